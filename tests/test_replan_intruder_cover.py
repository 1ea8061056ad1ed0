"""Low obstacles seen in time (companion.replan.intruder_cover): hand-worked cases.

One beam facing the direction of travel (body x), 24 deg wide; the vehicle's
centre 1.5 m over flat ground; clearance sphere keep = 0.5 + 0.442 m; braking
1 m/s^2; delay 0.05 s (20 Hz) + 0.1 s. The speed a range R allows for a stop
c short of it: v^2 / 2 + 0.15 v = R - c.
"""

import math

import numpy as np
import pytest

from companion.replan.coverage_check import Beam, CONTROL_DELAY_S
from companion.replan.intruder_cover import depression_interval, ground_tangent, low_allowed_speed
from mavcore import frames

KEEP = 0.942
TAU = 0.05 + CONTROL_DELAY_S


def _beam(pitch_down_deg: float, vfov_deg: float, max_m: float = 6.0) -> Beam:
    R = frames.euler_zyx2rotmat(0.0, math.radians(pitch_down_deg), 0.0)
    return Beam(0, np.asarray(R, dtype=float), math.tan(math.radians(12.0)),
                math.tan(math.radians(0.5 * vfov_deg)), max_m, 0.05)


def _v(range_m: float, c: float) -> float:
    return -TAU + math.sqrt(TAU * TAU + 2.0 * (range_m - c))


FORWARD = np.array([[1.0, 0.0, 0.0]])


def test_trace_of_a_pitched_beam_on_the_plane_of_travel():
    # pitched 6 deg down, 16 deg tall: depressions -2 .. 14 deg along its axis
    b = _beam(6.0, 16.0)
    lo, hi = depression_interval(FORWARD @ b.rotation_flu, b.rotation_flu[2, :], b.tan_half_h, b.tan_half_v)
    assert lo[0] == pytest.approx(math.tan(math.radians(-2.0)), abs=1e-12)
    assert hi[0] == pytest.approx(math.tan(math.radians(14.0)), abs=1e-12)
    # its steepest ray: 14 deg down, sin 14 of it downward
    assert ground_tangent(b.rotation_flu[2, :], b.tan_half_h, b.tan_half_v) == pytest.approx(
        math.sin(math.radians(14.0)), abs=1e-9)


def test_a_level_beam_never_sees_the_lowest_top_in_range():
    # +-5 deg: a top 0.942 m down is in view only beyond 0.942 / tan 5 = 10.8 m > 6 m
    v = low_allowed_speed(FORWARD, np.array([1.5]), (_beam(0.0, 10.0),), 1.0, KEEP, CONTROL_DELAY_S)
    assert v[0] == 0.0


def test_a_beam_pitched_down_sees_them_all_at_the_range():
    # +2 .. -14 deg: the lowest top is in view from 3.78 m, the ground 1.5 / sin 14 = 6.2 m
    # away is out of range: the range binds. A top level with the centre needs 6 - 0.942;
    # the check's depth grid takes the first step's far end sqrt(36 - (0.942/8)^2) with it
    v = low_allowed_speed(FORWARD, np.array([1.5]), (_beam(6.0, 16.0),), 1.0, KEEP, CONTROL_DELAY_S)
    assert _v(math.sqrt(36.0 - (KEEP / 8) ** 2), KEEP) - 1e-12 <= v[0] <= _v(6.0, KEEP)


def test_the_ground_hides_what_is_beyond_it():
    # -20 .. -30 deg: the ground is 1.5 / sin 30 = 3 m away; a top just below the centre is
    # in view from its upper edge, at depth D tan 20 and slant D / cos 20 < 3: D < 3 cos 20
    v = low_allowed_speed(FORWARD, np.array([1.5]), (_beam(25.0, 10.0),), 1.0, KEEP, CONTROL_DELAY_S)
    assert v[0] == pytest.approx(_v(3.0 * math.cos(math.radians(20.0)), KEEP), rel=1e-9)


def test_returns_near_the_ground_are_the_ground():
    # the replanner takes a return within 0.2 m of the nearest ground in view for the
    # ground: the view ends 0.2 m short of the 3 m, D / cos 20 < 2.8
    v = low_allowed_speed(FORWARD, np.array([1.5]), (_beam(25.0, 10.0),), 1.0, KEEP, CONTROL_DELAY_S,
                          ground_band_m=0.2)
    assert v[0] == pytest.approx(_v(2.8 * math.cos(math.radians(20.0)), KEEP), rel=1e-9)


def test_terrain_rising_ahead_closes_the_view():
    # the slope rises 0.25 m per m ahead: the steepest ray (14 deg down) meets it at
    # s = 1.5 / (tan 14 + 0.25) = 3.0 m, nearer than where the lowest top comes into view (3.78 m)
    s = np.arange(0.25, 6.01, 0.25)
    drop = (1.5 - 0.25 * s)[None, :]
    b = (_beam(6.0, 16.0),)
    assert low_allowed_speed(FORWARD, np.array([1.5]), b, 1.0, KEEP, CONTROL_DELAY_S, (s, drop))[0] == 0.0
    flat = (s, np.full((1, s.size), 1.5))
    assert low_allowed_speed(FORWARD, np.array([1.5]), b, 1.0, KEEP, CONTROL_DELAY_S, flat)[0] > 3.0


def test_nothing_lower_fits_on_the_ground():
    v = low_allowed_speed(FORWARD, np.array([0.0]), (_beam(0.0, 10.0),), 1.0, KEEP, CONTROL_DELAY_S)
    assert v[0] == math.inf


def _reference_low_allowed_speed(d_body, h, beams, accel, keep, delay, profile, band):
    """The module's rule computed on every sample and every beam, whole arrays, no
    filtering (the formulas of the module doc, as the first version computed them)."""
    from companion.replan.coverage_check import allowed_speed
    from companion.replan.intruder_cover import DEPTH_STEPS, far_distance

    n = h.shape[0]
    top = np.minimum(keep, np.maximum(h, 0.0))
    out = np.full(n, np.inf)
    per_beam = []
    for beam in beams:
        R = beam.rotation_flu
        t_lo, t_hi = depression_interval(d_body @ R, R[2, :], beam.tan_half_h, beam.tan_half_v)
        g = ground_tangent(R[2, :], beam.tan_half_h, beam.tan_half_v)
        with np.errstate(divide="ignore"):
            ground = np.where(g > 0.0, np.maximum(np.maximum(h, 0.0) / max(g, 1e-300) - band, 0.0), np.inf)
        reach = np.minimum(beam.max_m, ground)
        if profile is not None:
            s_m, drop_m = profile                            # the nearest terrain point in the trace
            tg = drop_m / s_m[None, :]
            inside = (tg >= t_lo[:, None]) & (tg <= t_hi[:, None])
            reach = np.minimum(reach, np.where(inside, np.hypot(s_m[None, :], drop_m), np.inf).min(axis=1))
        per_beam.append((t_lo, t_hi, reach, beam.period_s + delay))
    for k in range(DEPTH_STEPS):
        d0, d1 = top * k / DEPTH_STEPS, top * (k + 1) / DEPTH_STEPS
        need_c = np.sqrt(np.maximum(keep * keep - d0 * d0, 0.0))
        best = np.zeros(n)
        for t_lo, t_hi, reach, tau in per_beam:
            best = np.maximum(best, allowed_speed(far_distance(d1, t_lo, t_hi, h, reach), accel, tau, need_c))
        out = np.where(top > 0.0, np.minimum(out, best), out)
    return out


@pytest.mark.parametrize("seed", range(6))
def test_filtered_and_chunked_rule_gives_the_whole_arrays_numbers(seed):
    # low_allowed_speed skips the samples a beam's trace misses, and check_coverage feeds it
    # the terrain a chunk of samples at a time: the numbers must be the whole computation's,
    # bit for bit (a speed-up of the pre-flight gate, not a change of its verdicts)
    from mavcore.mission.sim import default_rangefinders
    from companion.replan.coverage_check import beam_from_config

    rng = np.random.default_rng([2026_11_28, seed])
    beams = tuple(beam_from_config(c) for c in default_rangefinders())
    beams += (_beam(6.0, 16.0), _beam(0.0, 10.0, 12.0), _beam(-20.0, 8.0))
    n = 700
    yaw = rng.uniform(-math.pi, math.pi, n)
    d = np.stack([np.cos(yaw), np.sin(yaw), np.zeros(n)], axis=1)
    d[: n // 7] = [1.0, 0.0, 0.0]                        # straight ahead, the usual case
    h = rng.choice([1.5, 0.3, 0.0, -0.2, 2.5], n) + rng.uniform(-0.05, 0.05, n)
    s = np.arange(0.25, 20.0 + 0.125, 0.25)
    slope = rng.uniform(-0.4, 0.4, n)[:, None]
    drop = h[:, None] - slope * s[None, :] + rng.normal(0.0, 0.05, (n, len(s)))
    drop[rng.random((n, len(s))) < 0.01] = -np.inf       # beyond the DEM
    for profile in (None, (s, drop)):
        want = _reference_low_allowed_speed(d, h, beams, 1.0, KEEP, CONTROL_DELAY_S, profile, 0.05)
        got = low_allowed_speed(d, h, beams, 1.0, KEEP, CONTROL_DELAY_S, profile, 0.05)
        np.testing.assert_array_equal(got, want)
        assert np.isfinite(want).any() and (want < 3.0).any()     # the rule limits some samples


def test_check_coverage_takes_the_terrain_in_chunks_with_the_same_numbers(monkeypatch):
    # a callable terrain, fed TERRAIN_CHUNK samples at a time, against the whole profile
    from companion.replan import coverage_check as cc
    from mavcore.maps.grid import ElevationModel

    xs = np.arange(0.0, 60.0, 0.5)
    Z = np.broadcast_to(0.05 * xs[None, :], (len(xs), len(xs))).copy()     # rising 5 % to the east
    dem = ElevationModel(Z, 0.0, 0.0, 0.5)
    t = np.linspace(0.0, 30.0, 301)
    p = np.stack([5.0 + 1.5 * t, 10.0 + 0.3 * np.sin(t), 1.5 + 0.05 * (5.0 + 1.5 * t)], axis=1)
    v = np.gradient(p, t, axis=0)
    from mavcore.mission.sim import default_rangefinders

    beams = tuple(cc.beam_from_config(c) for c in default_rangefinders())
    reach = max(b.max_m for b in beams)
    whole = cc.terrain_profile(p, v, dem, reach)
    parts = [cc.terrain_profile(p[k:k + 7], v[k:k + 7], dem, reach) for k in range(0, len(p), 7)]
    assert np.array_equal(np.vstack([q[1][1] for q in parts]), whole[1][1])
    assert np.array_equal(np.concatenate([q[0] for q in parts]), whole[0])
    target = np.array([30.0, 1000.0, 1.5])
    ref = cc.check_coverage(t, p, v, target, beams, 1.0, KEEP, None, whole, 0.05)
    flat = cc.check_coverage(t, p, v, target, beams, 1.0, KEEP)
    assert (ref.allowed_speed_m_s < flat.allowed_speed_m_s).any()       # the low rule limits some samples
    monkeypatch.setattr(cc, "TERRAIN_CHUNK", 37)
    got = cc.check_coverage(t, p, v, target, beams, 1.0, KEEP, None,
                            lambda i0, i1: cc.terrain_profile(p[i0:i1], v[i0:i1], dem, reach), 0.05)
    np.testing.assert_array_equal(got.allowed_speed_m_s, ref.allowed_speed_m_s)
    np.testing.assert_array_equal(got.sensor_id, ref.sensor_id)
    assert got.gaps == ref.gaps and got.time_scale == ref.time_scale
