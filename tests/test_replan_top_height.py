"""How high an obstacle is (docs/replan.md "How high an obstacle is"): the lowest height a
return's surface can have, the map's per-voxel lower bound, the climb decided on it, and the
height band kept over sloping ground.

A level beam 10 deg tall returns from a box's top edge through the lower edge of its field
until the vehicle is range x tan 5 deg above the top; its return, placed on the axis at the
vehicle's own height, rose with the vehicle past the climb limit, and climbable boxes were
re-routed round or held (obstacles-wide 20261166 flight 11: a 1.627 m box read 1.86 m).
"""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

from companion.campaign.results import make_row
from companion.replan.perception import BeamEvidence, lowest_return_z
from companion.replan.replanner import GOVERNOR_MARGIN_M, WALL_MARGIN_M, Replanner
from companion.replan.voxmap import L_CANDIDATE, ObstacleMap
from mavcore import codec
from mavcore.mission.replan import ReplanConfig

import test_replan_closedloop as C


def _level_beam(z: float, d: float, hfov_deg: float, vfov_deg: float, yaw_deg: float = 30.0) -> BeamEvidence:
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    a, h, v = (c, s, 0.0), (-s, c, 0.0), (0.0, 0.0, 1.0)
    o = (1.0, 2.0, z)
    return BeamEvidence(o, a, h, v, math.radians(hfov_deg) / 2, math.radians(vfov_deg) / 2, d,
                        (o[0] + d * a[0], o[1] + d * a[1], z), d, ())


# --- the lowest height of a return -------------------------------------------------------------


def test_a_level_beams_lowest_return_is_its_lower_edge_straight_ahead():
    # the ray (1, s, -T) / sqrt(1 + s^2 + T^2) is lowest at s = 0 (a wider field only
    # shortens its drop): z - d sin(vfov / 2), whatever the horizontal field
    for hfov in (0.0, 24.0, 60.0):
        ev = _level_beam(1.5, 2.0, hfov, 10.0)
        assert lowest_return_z(ev) == pytest.approx(1.5 - 2.0 * math.sin(math.radians(5.0)), abs=1e-12)
    # an attitude 2 deg off lowers every ray by at most 2 deg
    ev = _level_beam(1.5, 2.0, 24.0, 10.0)
    assert lowest_return_z(ev, math.radians(2.0)) == pytest.approx(1.5 - 2.0 * math.sin(math.radians(7.0)),
                                                                   abs=1e-12)
    # no field: the axis point itself
    assert lowest_return_z(_level_beam(1.5, 2.0, 0.0, 0.0)) == pytest.approx(1.5, abs=1e-12)


def test_a_downward_beam_with_the_nadir_in_view_reaches_straight_down():
    o = (0.0, 0.0, 3.0)
    ev = BeamEvidence(o, (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0), math.radians(18.0),
                      math.radians(18.0), 1.2, (0.0, 0.0, 1.8), 1.2, ())
    assert lowest_return_z(ev) == pytest.approx(3.0 - 1.2, abs=1e-12)
    # tilted 30 deg forward, the nadir is outside an 18 deg half-field: the lowest ray is the
    # edge nearest the nadir, 12 deg from it
    t = math.radians(30.0)
    a = (math.sin(t), 0.0, -math.cos(t))
    v = (math.cos(t), 0.0, math.sin(t))
    ev = BeamEvidence(o, a, (0.0, 1.0, 0.0), v, math.radians(18.0), math.radians(18.0), 1.2,
                      tuple(o[i] + 1.2 * a[i] for i in range(3)), 1.2, ())
    assert lowest_return_z(ev) == pytest.approx(3.0 - 1.2 * math.cos(math.radians(12.0)), abs=1e-12)


def test_the_lowest_return_bounds_a_dense_sampling_of_the_field_and_meets_it():
    rng = np.random.default_rng(20261128)
    for i in range(400):
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        a, h, v = Q[:, 0], Q[:, 1], Q[:, 2]
        hh, hv = rng.uniform(0.0, 1.2, size=2)
        d = rng.uniform(0.3, 8.0)
        o = rng.normal(size=3)
        ev = BeamEvidence(tuple(o), tuple(a), tuple(h), tuple(v), hh, hv, d, tuple(o + d * a), d, ())
        z = lowest_return_z(ev)
        S, T = np.meshgrid(np.linspace(-math.tan(hh), math.tan(hh), 201),
                           np.linspace(-math.tan(hv), math.tan(hv), 201))
        rays = a[:, None, None] + S * h[:, None, None] + T * v[:, None, None]
        sampled = o[2] + d * (rays[2] / np.linalg.norm(rays, axis=0)).min()
        assert z <= sampled + 1e-9
        # a grid step of the field turns a ray by at most ~2 tan(half) / 200 rad
        assert sampled - z <= d * 2.0 * max(math.tan(hh), math.tan(hv)) / 200.0 + 1e-9


def test_a_return_without_one_has_no_lowest_height():
    ev = _level_beam(1.5, 2.0, 24.0, 10.0)
    with pytest.raises(ValueError):
        lowest_return_z(BeamEvidence(ev.origin, ev.axis, ev.h_axis, ev.v_axis, ev.half_h_rad, ev.half_v_rad,
                                     5.0, None, math.nan, ()))


# --- the map's lower bound ---------------------------------------------------------------------


def test_a_voxel_keeps_the_highest_lower_bound_of_its_returns_never_above_its_point():
    m = ObstacleMap(0.1)
    m.add((1.05, 1.05, 1.55), z_low=1.30)
    m.add((1.06, 1.04, 1.56), z_low=1.40)           # same voxel, a higher bound
    m.add((1.04, 1.06, 1.57), z_low=1.35)           # a lower one changes nothing
    m.add((2.05, 1.05, 1.55), L_CANDIDATE, 0.0, z_low=1.90)   # a bound above the point: the point
    m.add((3.05, 1.05, 1.55))                       # no bound given: the point's own height
    lows = dict(zip(map(tuple, m.keys().tolist()), m.lows().tolist()))
    assert lows == {(10, 10, 15): 1.40, (20, 10, 15): 1.55, (30, 10, 15): 1.55}
    # a raised bound moves no point: the arrays (and the k-d tree) are not rebuilt for it
    v = m.version
    m.add((1.05, 1.05, 1.59), z_low=1.45)
    assert m.version == v and dict(zip(map(tuple, m.keys().tolist()), m.lows().tolist()))[(10, 10, 15)] == 1.45
    # cleared with its voxel
    m.expire_candidates(10.0)
    assert (20, 10, 15) not in set(map(tuple, m.keys().tolist())) and len(m.lows()) == len(m.points()) == 2


# --- the climb decided on it (the analytic world of test_replan_closedloop) ------------------


@pytest.fixture
def tall_ring(monkeypatch):
    """The ring's beams 10 deg tall (the SITL's default level ring), the down beam as there."""
    vf = math.radians(10.0)
    sens = tuple((k, codec.MAV_SENSOR_ROTATION_CUSTOM, C._yaw_quat(k * 360.0 / C.N_RING), C.RING_FOV, vf)
                 for k in range(C.N_RING)) + ((C.N_RING, 25, None, 0.0, 0.0),)
    geom = tuple((sid, o, codec.sensor_rotation_flu(o, q), h, v) for sid, o, q, h, v in sens)
    monkeypatch.setattr(C, "SENSOR_GEOMETRY", geom)
    monkeypatch.setattr(C, "SENSOR_FANS", tuple(C._fan_body(R, h, v) for _, _, R, h, v in geom))
    return C.build_field()


def _climb_limit_m(cfg: ReplanConfig) -> float:
    # the highest top the governor lets the vehicle pass over at the highest the avoiding
    # reference goes (flat ground at 0): top + clearance + body + margin <= ceiling - wall margin
    return cfg.ceiling_agl_m - WALL_MARGIN_M - GOVERNOR_MARGIN_M - cfg.clearance_m - (cfg.body_radius_m or 0.0)


def _wall(h: float) -> C.Box:
    return C.Box(8.8, 9.2, C.CORRIDOR_Y - 1.2, C.CORRIDOR_Y + 1.2, h)


def test_a_box_under_the_climb_limit_that_reads_over_it_is_climbed(tall_ring):
    cfg = ReplanConfig()
    limit = _climb_limit_m(cfg)
    box = _wall(limit - 0.1)                  # 2.2 m under the 2.3 m limit: its returns read 2.3-2.4 m
    f = C.fly(tall_ring, [box], cfg, t_end_s=80.0, stop_after=C._after_rejoin())
    assert C._actions(f) == ["avoid", "climb", "rejoin"], [(e.action, e.detail) for e in f.events]
    assert f.clearance([box]).min() >= cfg.clearance_m
    over = (f.ref[:, 0] >= box.x0) & (f.ref[:, 0] <= box.x1)
    assert over.any() and f.ref[over, 2].min() >= box.h + cfg.clearance_m
    assert f.ref[:, 2].max() <= cfg.ceiling_agl_m                    # flat ground at 0
    # the axis points did read over the limit: the decision came from the lower bounds
    rp = f.replanner
    assert rp.memory.points()[:, 2].max() > limit


def test_a_box_over_the_climb_limit_is_never_passed_over(tall_ring):
    cfg = ReplanConfig()
    box = _wall(_climb_limit_m(cfg) + 0.2)
    f = C.fly(tall_ring, [box], cfg, t_end_s=60.0)
    acts = C._actions(f)
    assert "reroute" in acts and acts.index("climb") < acts.index("reroute"), acts
    assert any("at least" in e.detail for e in f.events if e.action == "stop")
    over = (f.ref[:, 0] >= box.x0 - 0.5) & (f.ref[:, 0] <= box.x1 + 0.5) & \
        (np.abs(f.ref[:, 1] - C.CORRIDOR_Y) <= 1.2)
    assert not over.any()
    assert f.clearance([box]).min() >= cfg.clearance_m


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
