"""Returns on still surfaces that must not read as movers (``companion.replan.closing``), and
the governor's last pass that must not lengthen a command past the corridor's walls
(``Replanner._govern(scale_only=True)``). Obstacles-wide seed 20261166, flight 20.

Geometry is worked by hand: a beam's return is where its axis meets a surface, so the
returns are computed here from the beam and the surface, not by the code under test.
"""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

from companion.replan import closing
from companion.replan.closing import ClosingSpeed
from companion.replan.replanner import GOVERNOR_LAG_S, GOVERNOR_MARGIN_M, Replanner


def _fly_away_over_a_jump(c: ClosingSpeed) -> None:
    """A level beam looking back (+x) from a vehicle flying west (-x) at 0.5 m/s at 1.5 m: its
    returns lie on a still face at x = 7.2 for 0.5 s, then on a still face 0.7 m nearer
    (x = 6.5) that the first one hid (20 Hz, one beam). Neither face moves."""
    for k in range(24):
        t = 0.05 * k
        o = (5.0 - 0.5 * t, 0.0, 1.5)
        x = 7.2 if t < 0.5 else 6.5
        c.on_hit(t, 7, (x, 0.0, 1.5), (1.0, 0.0, 0.0), origin_enu_m=o)


def test_a_return_that_jumps_to_a_nearer_surface_is_no_mover(monkeypatch):
    c = ClosingSpeed()
    _fly_away_over_a_jump(c)
    assert all(c.approach_m_s(0.05 * k) == 0.0 for k in range(24))
    # the rule is what decides: without it the jump reads as a mover coming 0.7 m in
    # 0.3-0.6 s, 1.17-2.33 m/s (the pair's age), and it is kept for HOLD_S
    monkeypatch.setattr(closing, "continuous", lambda *a: True)
    c = ClosingSpeed()
    _fly_away_over_a_jump(c)
    w = c.approach_m_s(1.15)
    assert 0.7 / 0.6 - 1e-9 <= w <= 0.7 / 0.3 + 1e-9


def test_a_walker_coming_down_a_level_beam_is_read_at_its_speed_along_its_track():
    """The continuity rule keeps a real mover: a walker at 1.5 m/s toward a vehicle hovering
    at 1.5 m, 20 Hz returns 0.075 m apart (under 6 m/s x 0.05 s + 0.1 m)."""
    c = ClosingSpeed()
    for k in range(20):
        t = 0.05 * k
        c.on_hit(t, 3, (6.0 - 1.5 * t, 0.0, 1.5), (1.0, 0.0, 0.0), origin_enu_m=(0.0, 0.0, 1.5))
    assert c.approach_m_s(0.95) == pytest.approx(1.5, abs=1e-9)


def _top_slide(c: ClosingSpeed, tilt_deg: float, field: bool = True) -> float:
    """A beam ``tilt_deg`` down looking back (+x) from a vehicle flying west at 1.0 m/s and
    descending at 0.3 m/s from 2.3 m, over a still level top at z = 1.5 (x 0..20): the
    return is where the axis meets the plane, x = o_x + (o_z - 1.5) / tan(tilt), sliding
    toward the vehicle faster than it flies. Returns the return's level speed toward the
    sensor in the world, d/dt of -x: 1.0 + 0.3 / tan(tilt). Relative to the sensor it moves
    at 0.3 / tan(tilt), above the riding rule's 0.3 m/s for a tilt under 45 deg. ``field``:
    the beam's (sensor height, range, lowest and highest sine of elevation), a narrow beam's
    (both -sin(tilt)), as the replanner gives it."""
    e = math.radians(tilt_deg)
    axis = (math.cos(e), 0.0, -math.sin(e))
    for k in range(20):
        t = 0.05 * k
        o = (10.0 - 1.0 * t, 0.0, 2.3 - 0.3 * t)
        x = o[0] + (o[2] - 1.5) / math.tan(e)
        f = (o[2], (o[2] - 1.5) / math.sin(e), -math.sin(e), -math.sin(e)) if field else None
        c.on_hit(t, 30, (x, 0.0, 1.5), axis, origin_enu_m=o, field=f)
    return 1.0 + 0.3 / math.tan(e)


@pytest.mark.parametrize("tilt_deg", [20.0, 40.0])
def test_a_tilted_beam_sliding_over_a_still_top_is_no_mover(monkeypatch, tilt_deg):
    c = ClosingSpeed()
    world_speed = _top_slide(c, tilt_deg)
    assert world_speed > closing.MIN_M_S + 1.0          # fast enough to be read, and not riding
    assert c.approach_m_s(0.95) == 0.0
    c = ClosingSpeed()
    _top_slide(c, tilt_deg, field=False)                # a field it cannot judge: not read at all
    assert c.approach_m_s(0.95) == 0.0
    # the plane rule is what decides: without it the slide reads as a mover at the return's
    # world speed along the beam's level axis
    monkeypatch.setattr(closing, "still_plane", lambda *a: False)
    c = ClosingSpeed()
    _top_slide(c, tilt_deg)
    assert c.approach_m_s(0.95) == pytest.approx(world_speed, rel=1e-9)


@pytest.mark.parametrize("tilt_deg", [20.0, 45.0])
def test_a_walker_coming_down_a_tilted_beam_is_read_at_its_speed(tilt_deg):
    """Fresh seed 20261221 (walkers along the corridors), flight 8 (obstacle-tall): climbing at
    2.13 m, the vehicle flew at 0.8 m/s toward a worker walking down the corridor at 1.33 m/s.
    The suite's level ring (2 deg high) passes over a 1.8 m head there; only its 20 deg and
    45 deg rings saw the worker, and beams over 15 deg read no movers: 0.124 m of true
    clearance. Here the worker's face is at x = 6 - 1.3 t, the vehicle at x = 0.8 t, 2.13 m
    up; the beam's return is where its axis meets the face. The plane rule does not explain
    the pair (the range shrinks 2.1 m/s where a level surface keeps it), the return does not
    ride with the sensor, so the approach reads 1.3 m/s."""
    e = math.radians(tilt_deg)
    axis = (math.cos(e), 0.0, -math.sin(e))
    lo, hi = -math.sin(e + math.radians(1.0)), -math.sin(e - math.radians(1.0))
    c = ClosingSpeed()
    for k in range(20):
        t = 0.05 * k
        o = (0.8 * t, 0.0, 2.13)
        d = (6.0 - 1.3 * t - o[0]) / math.cos(e)
        hit = (o[0] + d * axis[0], 0.0, o[2] + d * axis[2])
        c.on_hit(t, 20, hit, axis, origin_enu_m=o, field=(o[2], d, lo, hi))
    assert c.approach_m_s(0.95) == pytest.approx(1.3, abs=1e-9)
    # the place a give-way backs away from (``mover_at``) is the newest return
    assert c.mover_at(0.95)[:2] == pytest.approx((6.0 - 1.3 * 0.95, 0.0))


def test_a_beam_looking_down_reads_no_mover():
    """Beyond ``MOVER_TILT_MAX_DEG`` (60 deg) a beam's level part is too small to read an
    approach: the down rangefinder's return jumps as the vehicle passes over a crate."""
    e = math.radians(70.0)
    axis = (math.cos(e), 0.0, -math.sin(e))
    c = ClosingSpeed()
    for k in range(20):
        t = 0.05 * k
        d = 2.0 - 1.0 * t
        c.on_hit(t, 40, (d * axis[0], 0.0, 2.0 + d * axis[2]), axis, origin_enu_m=(0.0, 0.0, 2.0),
                 field=(2.0, d, axis[2], axis[2]))
    assert c.approach_m_s(0.95) == 0.0


def test_the_default_low_ring_still_reads_a_walker():
    """The default suite's low ring looks 9 deg down (mavcore.mission.sim): within the
    15 deg bound. A walker's face coming at 1.2 m/s toward a hovering vehicle at 1.5 m."""
    from mavcore.mission.sim import DEFAULT_LOW_PITCH_DEG

    assert DEFAULT_LOW_PITCH_DEG < closing.MOVER_TILT_MAX_DEG
    e = math.radians(DEFAULT_LOW_PITCH_DEG)
    axis = (math.cos(e), 0.0, -math.sin(e))
    c = ClosingSpeed()
    for k in range(20):
        t = 0.05 * k
        xf = 5.0 - 1.2 * t                                 # the face
        c.on_hit(t, 20, (xf, 0.0, 1.5 - xf * math.tan(e)), axis, origin_enu_m=(0.0, 0.0, 1.5))
    assert c.approach_m_s(0.95) == pytest.approx(1.2, abs=1e-9)


# --- the governor's last pass ----------------------------------------------------------------


def _governor(w_m_s: float):
    """The members ``_govern`` reads, on a bare object: keep 0.942 m (0.5 m + 0.442 m), brake
    1 m/s^2, a mover's speed ``w_m_s``."""
    rp = types.SimpleNamespace(_keep_m=0.942, _brake=1.0, _t_s=0.0,
                               closing=types.SimpleNamespace(approach_m_s=lambda t: w_m_s))
    rp._allowed_speed = types.MethodType(Replanner._allowed_speed, rp)
    rp._govern = types.MethodType(Replanner._govern, rp)
    return rp


def test_the_last_pass_never_lengthens_a_command():
    """A point 1.2 m behind the vehicle (+x), a mover's speed of 2 m/s: the stopping law
    allows sqrt(0.36 + 2 (1.2 - 0.942 - m)) - 0.6 toward it (m = GOVERNOR_MARGIN_M), so the
    rule asks to back away (-x) at 2 m/s less that. A command already backing away at
    0.6 m/s, bounded by a wall, is kept as it is, not stretched to that speed."""
    rp = _governor(2.0)
    P = np.array([5.0, 0.0, 1.5])
    obs = np.array([[6.2, 0.0, 1.5]])
    stop = math.sqrt(GOVERNOR_LAG_S ** 2 + 2.0 * max(0.0, 1.2 - 0.942 - GOVERNOR_MARGIN_M)) - GOVERNOR_LAG_S
    assert 2.0 - stop > 0.6                                   # the rule asks for more than the command
    v = np.array([-0.6, 0.0, 0.0])
    out = rp._govern(P, v, obs, np.array([1.2]), scale_only=True)
    assert out == pytest.approx(v)
    # the full pass still pushes away (it runs before the walls, which then bound it)
    full = rp._govern(P, v, obs, np.array([1.2]))
    assert full[0] == pytest.approx(-(2.0 - stop), abs=1e-9)
    # and a command too fast toward a point is still shortened: 1 m/s at a point 1.2 m ahead
    # with no mover is scaled to the stopping law's speed
    rp = _governor(0.0)
    out = rp._govern(P, np.array([1.0, 0.0, 0.0]), obs, np.array([1.2]), scale_only=True)
    assert out == pytest.approx([stop, 0.0, 0.0], abs=1e-9)


# --- a level beam whose field's lower edge grazes a still top (mix 20261210 flight 14) ------

VFOV_HALF = math.radians(5.0)


def _pitching_beam(c: ClosingSpeed, surface, n: int = 12) -> None:
    """A level-ish beam 10 deg tall (no horizontal field) at 1.5 m, hovering, pitching from
    +1 deg to -1.2 deg over ``n`` 20 Hz returns; ``surface(t, el)`` gives the measured range.
    The field's lowest and highest sines are those of el -+ 5 deg, worked by hand."""
    o = (0.0, 0.0, 1.5)
    for k in range(n):
        t = 0.05 * k
        el = math.radians(1.0 - 2.2 * k / (n - 1))
        d = surface(t, el)
        axis = (math.cos(el), 0.0, math.sin(el))
        hit = tuple(o[i] + d * axis[i] for i in range(3))
        c.on_hit(t, 4, hit, axis, origin_enu_m=o,
                 field=(o[2], d, math.sin(el - VFOV_HALF), math.sin(el + VFOV_HALF)))


def _grazed_top(t: float, el: float) -> float:
    # a still top at z = 1.3, 0.2 m under the sensor, met first by the field's lower edge
    return 0.2 / -math.sin(el - VFOV_HALF)


def test_a_top_grazed_by_a_pitching_beams_lower_edge_is_no_mover(monkeypatch):
    c = ClosingSpeed()
    _pitching_beam(c, _grazed_top)
    assert all(c.approach_m_s(0.05 * k) == 0.0 for k in range(12))
    # the rule decides: without it the return slides 2.87 -> 1.96 m toward the vehicle
    # in 0.55 s, read as a mover at over 1 m/s
    monkeypatch.setattr(closing, "still_plane", lambda *a: False)
    c = ClosingSpeed()
    _pitching_beam(c, _grazed_top)
    assert c.approach_m_s(0.55) > 1.0


def test_a_walker_coming_down_the_same_pitching_beam_is_still_read():
    # a vertical face walking in at 1.2 m/s from 4 m: the axis meets it at x / cos(el); no
    # still plane gives those ranges through the field's lower or upper edge
    c = ClosingSpeed()
    _pitching_beam(c, lambda t, el: (4.0 - 1.2 * t) / math.cos(el))
    assert c.approach_m_s(0.55) == pytest.approx(1.2, abs=0.05)


def test_still_plane_hand_worked():
    # lower edge at -4 deg meets z = 1.3 at 0.2 / sin 4 deg = 2.867 m; at -6 deg, 1.913 m
    f0 = (1.5, 0.2 / math.sin(math.radians(4.0)), -math.sin(math.radians(4.0)), math.sin(math.radians(6.0)))
    f1 = (1.5, 0.2 / math.sin(math.radians(6.0)), -math.sin(math.radians(6.0)), math.sin(math.radians(4.0)))
    assert closing.still_plane(f0, f1, 0.3)
    # 0.1 m off that range in 0.3 s is 0.33 m/s, over MIN_M_S: not the plane
    f2 = (1.5, f1[1] - 0.1, f1[2], f1[3])
    assert not closing.still_plane(f0, f2, 0.3)
    assert not closing.still_plane(None, f1, 0.3) and not closing.still_plane(f0, None, 0.3)
