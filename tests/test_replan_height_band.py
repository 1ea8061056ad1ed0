"""The field of view's extreme elevations (``perception.field_sine_range``, what
``closing.still_plane`` reads), the height band kept over sloping ground by the avoiding
command (``Replanner._band_over_slope``), and the campaign's figure of it.

A climb held level over remembered points it may not descend onto crept on down a slope to
3.30 m above the ground under a 3 m ceiling (mix 20261210 flight 6), and from above the
ceiling no re-route can start.
"""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

from companion.campaign.results import make_row
from companion.replan.perception import BeamEvidence, field_sine_range
from companion.replan.replanner import WALL_MARGIN_M, Replanner
from mavcore.mission.replan import ReplanConfig

import test_replan_closedloop as C


def _level_beam(z: float, d: float, hfov_deg: float, vfov_deg: float, yaw_deg: float = 30.0) -> BeamEvidence:
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    a, h, v = (c, s, 0.0), (-s, c, 0.0), (0.0, 0.0, 1.0)
    o = (1.0, 2.0, z)
    return BeamEvidence(o, a, h, v, math.radians(hfov_deg) / 2, math.radians(vfov_deg) / 2, d,
                        (o[0] + d * a[0], o[1] + d * a[1], z), d, ())


# --- the field's extreme elevations ---------------------------------------------------------


def _lowest(ev):
    return field_sine_range(ev)[0]


def test_a_level_beams_lowest_ray_is_its_lower_edge_straight_ahead():
    # the ray (1, s, -T) / sqrt(1 + s^2 + T^2) is lowest at s = 0 (a wider field only
    # shortens its drop): sin(-vfov / 2), whatever the horizontal field; highest +sin
    for hfov in (0.0, 24.0, 60.0):
        lo, hi = field_sine_range(_level_beam(1.5, 2.0, hfov, 10.0))
        assert lo == pytest.approx(-math.sin(math.radians(5.0)), abs=1e-12)
        assert hi == pytest.approx(math.sin(math.radians(5.0)), abs=1e-12)
    # no field: the axis itself
    assert field_sine_range(_level_beam(1.5, 2.0, 0.0, 0.0)) == pytest.approx((0.0, 0.0), abs=1e-12)


def test_a_downward_beam_with_the_nadir_in_view_reaches_straight_down():
    o = (0.0, 0.0, 3.0)
    ev = BeamEvidence(o, (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0), math.radians(18.0),
                      math.radians(18.0), 1.2, (0.0, 0.0, 1.8), 1.2, ())
    assert _lowest(ev) == pytest.approx(-1.0, abs=1e-12)
    # tilted 30 deg forward, the nadir is outside an 18 deg half-field: the lowest ray is the
    # edge nearest the nadir, 12 deg from it; the highest, the far edge 48 deg from it
    t = math.radians(30.0)
    a = (math.sin(t), 0.0, -math.cos(t))
    v = (math.cos(t), 0.0, math.sin(t))
    ev = BeamEvidence(o, a, (0.0, 1.0, 0.0), v, math.radians(18.0), math.radians(18.0), 1.2,
                      tuple(o[i] + 1.2 * a[i] for i in range(3)), 1.2, ())
    lo, hi = field_sine_range(ev)
    assert lo == pytest.approx(-math.cos(math.radians(12.0)), abs=1e-12)
    # the far edge's corners are higher than its midpoint: checked by sampling below
    assert hi >= -math.cos(math.radians(48.0)) - 1e-12


def test_the_extremes_bound_a_dense_sampling_of_the_field_and_meet_it():
    rng = np.random.default_rng(20261128)
    for i in range(400):
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        a, h, v = Q[:, 0], Q[:, 1], Q[:, 2]
        hh, hv = rng.uniform(0.0, 1.2, size=2)
        o = rng.normal(size=3)
        ev = BeamEvidence(tuple(o), tuple(a), tuple(h), tuple(v), hh, hv, 1.0, tuple(o + a), 1.0, ())
        lo, hi = field_sine_range(ev)
        S, T = np.meshgrid(np.linspace(-math.tan(hh), math.tan(hh), 201),
                           np.linspace(-math.tan(hv), math.tan(hv), 201))
        rays = a[:, None, None] + S * h[:, None, None] + T * v[:, None, None]
        z = rays[2] / np.linalg.norm(rays, axis=0)
        # a grid step of the field turns a ray by at most ~2 tan(half) / 200 rad
        step = 2.0 * max(math.tan(hh), math.tan(hv)) / 200.0 + 1e-9
        assert lo <= z.min() + 1e-9 and z.min() - lo <= step
        assert hi >= z.max() - 1e-9 and hi - z.max() <= step


# --- the height band over sloping ground -------------------------------------------------------


def _sloped(field, slope: float) -> Replanner:
    rp = Replanner(ReplanConfig(), field.known, field.plan)
    rp.known = types.SimpleNamespace(ground_z=lambda x, y: slope * x)    # rises toward +x
    return rp


@pytest.mark.parametrize("slope", [0.1, 0.3])
def test_the_height_above_ground_leaves_the_band_no_faster_than_its_walls_allow(slope):
    field = C.build_field()
    rp = _sloped(field, slope)
    cfg = rp.cfg
    rng = np.random.default_rng(7)
    scaled = 0
    for _ in range(400):
        x = float(rng.uniform(0.0, 10.0))
        g = slope * x
        # near one of the walls (where the rule acts), inside and a little beyond
        wall = cfg.ceiling_agl_m - WALL_MARGIN_M if rng.random() < 0.5 else cfg.floor_agl_m + WALL_MARGIN_M
        z = g + wall + float(rng.uniform(-0.3, 0.3))
        v = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.3, 0.3)])
        out = rp._band_over_slope(np.array([x, 1.0, z]), v, g)
        assert out[2] == v[2] and np.allclose(out[:2], v[:2] * (out[0] / v[0]))      # only the level part, scaled
        k = out[0] / v[0]
        assert 0.0 <= k <= 1.0
        scaled += k < 1.0
        # the rate of the height above ground, from the ground itself (a plane: exact)
        rate = out[2] - slope * out[0]
        top = z - g - (cfg.ceiling_agl_m - WALL_MARGIN_M)
        bottom = z - g - (cfg.floor_agl_m + WALL_MARGIN_M)
        if v[2] - slope * v[0] <= rp._wall_speed(-top) and v[2] - slope * v[0] >= -rp._wall_speed(bottom):
            assert k == 1.0                           # nothing to keep: untouched
        if v[2] <= rp._wall_speed(-top):
            assert rate <= rp._wall_speed(-top) + 1e-12
        if v[2] >= -rp._wall_speed(bottom):
            assert rate >= -rp._wall_speed(bottom) - 1e-12
    assert scaled > 50


def test_held_level_at_the_ceiling_a_climb_does_not_creep_down_a_slope():
    # at the ceiling's wall, the vertical speed held at 0 (over remembered points), the
    # ground falling 0.15 m a metre ahead: no level motion downhill, all of it uphill
    rp = _sloped(C.build_field(), 0.15)
    cfg = rp.cfg
    x = 5.0
    P = np.array([x, 1.0, 0.15 * x + cfg.ceiling_agl_m - WALL_MARGIN_M])
    assert np.allclose(rp._band_over_slope(P, np.array([-0.8, 0.3, 0.0]), 0.15 * x), [0.0, 0.0, 0.0])
    assert np.allclose(rp._band_over_slope(P, np.array([0.8, 0.3, 0.0]), 0.15 * x), [0.8, 0.3, 0.0])
    # and 1 m under it the same command goes on
    P[2] -= 1.0
    assert np.allclose(rp._band_over_slope(P, np.array([-0.8, 0.3, 0.0]), 0.15 * x), [-0.8, 0.3, 0.0])


# --- the figure in the campaign's table --------------------------------------------------------


def test_the_campaign_row_says_how_far_under_the_ceiling_the_avoidance_stayed():
    scen = {"campaign": "c", "scenario": 1, "mission": "m", "seed": 1, "cut_s": None, "control": "companion",
            "overrides": {}}
    rep = {"completed": True, "crashed": False,
           "replanning": {"max_height_agl_m": 3.22, "ceiling_agl_m": 3.0, "event_list": []}}
    assert make_row(scen, rep, None, 1.0)["ceiling_margin_m"] == pytest.approx(-0.22, abs=1e-12)
    rep["replanning"] = {"max_height_agl_m": None, "ceiling_agl_m": 3.0}
    assert make_row(scen, rep, None, 1.0)["ceiling_margin_m"] is None


def test_the_avoiding_velocity_command_keeps_the_band_over_a_slope():
    # the APF's command itself (no governor: nothing else in it could hold the level part):
    # a goal downhill at the vehicle's height, the vehicle at the ceiling's wall
    from dataclasses import replace
    field = C.build_field()
    rp = Replanner(replace(ReplanConfig(), clearance_governor=False), field.known, field.plan)
    rp.known = types.SimpleNamespace(ground_z=lambda x, y: 0.15 * x)
    cfg = rp.cfg
    P = np.array([5.0, 1.0, 0.75 + cfg.ceiling_agl_m - WALL_MARGIN_M])
    A, u, n = np.array([6.0, 1.0, 0.0]), np.array([-1.0, 0.0]), np.array([0.0, 1.0])
    v = np.asarray(rp._apf_velocity(P, np.zeros((0, 3)), np.zeros(0), np.array([0.0, 1.0, P[2]]), A, u, n, 0.75))
    assert v[2] - 0.15 * v[0] <= 1e-12            # the height above ground does not grow
    # uphill the same goal distance away, it flies
    v = np.asarray(rp._apf_velocity(P, np.zeros((0, 3)), np.zeros(0), np.array([10.0, 1.0, P[2]]), A, -u, n, 0.75))
    assert v[0] > 0.5
