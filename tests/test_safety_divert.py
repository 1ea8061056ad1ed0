"""A refused landing is moved to the nearest spot the guard accepts (companion.safety.divert,
issue 15), hand-worked on the guard tests' scene: flat ground at z = 0, one row at x 5.0-5.2,
y 0-5.0 extruded to 2 m, airframe R = 0.4 m, clearances 0.5 m: every column point keeps
0.9 m from the rows and obstacles (test_safety_guard's module doc).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.safety.divert import MAX_RING_M, N_ANGLES, RING_STEP_M, candidates, find_landing
from test_safety_guard import REQ, R, _box, _commands, _core_beside, _guard

CRATE = ((7.0, 7.0, 0.0), (8.0, 8.0, 0.8))      # the crate, 0.8 m high
BESIDE = (8.2, 7.5, 1.5)                          # stopped 0.2 m east of it


def _column_clear(dist, spot) -> bool:
    """Independently: every point of the column under ``spot`` down to R above the flat
    ground (5 mm apart) keeps REQ from the obstacle ``dist``."""
    zs = np.arange(spot[2], R - 1e-9, -0.005)
    pts = np.column_stack([np.full_like(zs, spot[0]), np.full_like(zs, spot[1]), zs])
    return bool(dist(pts).min() >= REQ - 1e-9)


def test_candidates_are_tried_shortest_path_first():
    c = candidates(BESIDE, (0.0, 0.0, 0.0), 3.0, 0.5, 1.0)
    n_rings = int(round(MAX_RING_M / RING_STEP_M))
    assert len(c) == n_rings * N_ANGLES + 1
    lengths = [x[0] for x in c]
    assert lengths == sorted(lengths)
    # home: up 1.5 m to the transit height, then hypot(8.2, 7.5) across: longer than any ring
    assert c[-1][1] == "home" and c[-1][0] == pytest.approx(1.5 + math.hypot(8.2, 7.5))
    # a ring spot is level with the hover, r from it
    r, kind, segs = c[N_ANGLES + 3]
    assert kind == "ring" and r == pytest.approx(2 * RING_STEP_M)
    assert math.dist(segs[0][1], BESIDE) == pytest.approx(r) and segs[0][1][2] == BESIDE[2]


def test_moves_to_the_nearest_clear_column_beside_the_crate():
    # refused where it is (0.2 m from the crate's side); a column keeps 0.9 m from the crate's
    # footprint x <= 8.0 only at x >= 8.9: rings 0.25 and 0.5 reach x 8.7 at most, the ring
    # 0.75 at angle 0 reaches x 8.95 (0.95 m), its neighbours at +-22.5 deg only
    # 8.2 + 0.75 cos 22.5 = 8.893 (< 8.9): the move is 0.75 m east, the 33rd candidate
    crate = _box(*CRATE)
    g = _guard(crate)
    assert not g.check_landing(BESIDE, (0.0, 0.0, 0.0)).ok
    d = find_landing(g, BESIDE, None, None)
    assert d.kind == "ring" and d.spot == pytest.approx((8.95, 7.5, 1.5), abs=1e-12)
    assert d.path_m == pytest.approx(0.75) and d.tried == 2 * N_ANGLES + 1
    assert _column_clear(crate, d.spot)
    assert not _column_clear(crate, (8.2 + 0.75 * math.cos(math.pi / 8), 7.5 + 0.75 * math.sin(math.pi / 8), 1.5))
    # the move itself: 0.75 m with the climb speed (0.5 m/s here) its peak, 35/16 of the mean
    assert d.segments[0][2] == pytest.approx(35.0 / 16.0 * 0.75 / 0.5)


def test_goes_home_over_the_transit_height_when_no_ring_is_clear():
    # hovering 1.5 m over a wide 0.8 m slab (x 6-12, y 4-11): 0.7 m above it, every ring spot
    # within 3 m is over the slab too. Home (2, 7.5): up to the 3 m transit height (1.5 m at
    # 0.5 m/s: 35/16 * 3 s), 7 m across at 1 m/s, and its column is 4 m from the slab
    slab = _box((6.0, 4.0, 0.0), (12.0, 11.0, 0.8))
    g = _guard(slab)
    d = find_landing(g, (9.0, 7.5, 1.5), (2.0, 7.5, 0.0), 3.0, 0.5, 1.0)
    assert d.kind == "home" and d.spot == pytest.approx((2.0, 7.5, 3.0))
    assert d.path_m == pytest.approx(8.5) and d.tried == (MAX_RING_M / RING_STEP_M) * N_ANGLES + 1
    (a, b, t1), (c, e, t2) = d.segments
    assert b == pytest.approx((9.0, 7.5, 3.0)) and e == pytest.approx((2.0, 7.5, 3.0))
    assert t1 == pytest.approx(35.0 / 16.0 * 1.5 / 0.5) and t2 == pytest.approx(35.0 / 16.0 * 7.0)
    assert _column_clear(slab, d.spot)
    # home under the slab too: nowhere to go
    assert find_landing(g, (9.0, 7.5, 1.5), (10.0, 7.5, 0.0), 3.0) is None


def test_a_clear_column_behind_a_wall_is_not_reached_through_it():
    # a 3 m wall x 8.75-8.8 along y, 0.55 m east of the hover (inside the clearance, outside
    # the airframe). East of it the first clear column is on ring 1.75 at angle 0: (9.95, 7.5),
    # 1.15 m from the wall; but the straight move there crosses the wall (distance 0)
    crate, wall = _box(*CRATE), _box((8.75, 0.0, 0.0), (8.8, 20.0, 3.0))

    def both(p):
        return np.minimum(crate(p), wall(p))
    g = _guard(both)
    east = (9.95, 7.5, 1.5)
    assert _column_clear(both, east) and g.check_landing(east, (0.0, 0.0, 0.0)).ok
    assert not g.check_segments([(BESIDE, east, 3.0)]).ok
    d = find_landing(g, BESIDE, None, None)
    assert d is not None and d.spot[0] < 8.75            # the side of the wall it hovers on
    assert _column_clear(both, d.spot)
    # the move, sampled 1 cm apart, never touches either (centre at least R away)
    a, b = np.asarray(d.segments[0][0]), np.asarray(d.segments[0][1])
    s = np.linspace(0.0, 1.0, int(math.dist(a, b) / 0.01) + 2)[:, None]
    assert both(a + s * (b - a)).min() >= R


def _fly(core, t0: float, t_end: float, dt: float = 0.004, body_rates=(0.0, 0.0, 0.0)):
    """Frames of a perfect tracker: the vehicle is where the reference is, turning at
    ``body_rates`` (its ATTITUDE); returns the positions flown, the COMMAND_LONG ids in
    order and the time of the last frame (``_fly.times``: each position's frame time)."""
    t, flown, cmds = t0, [], []
    _fly.times = []
    core.view.att_w = body_rates
    core._drive()
    cmds += _commands(core)
    while t < t_end and core.phase != "landing" and not core.finished:
        t += dt
        core.view.t_s = t
        ref = core._guarded(t)
        if ref is not None:
            core.view.pos, core.view.vel = tuple(ref.p), tuple(ref.v)
            flown.append(ref.p)
            _fly.times.append(t)
        core._drive()
        cmds += _commands(core)
    return np.array(flown), cmds, t


def test_core_moves_a_refused_landing_then_lands():
    from pymavlink.dialects.v20 import common as mavlink

    crate = _box(*CRATE)
    core, gate = _core_beside(crate, BESIDE)
    core._steering, core._launch = True, (0.0, 8.0, 0.0)
    core._react(core.monitor.fail(100.0, "no_route", "no route", "land"))
    flown, cmds, t_land = _fly(core, 100.0, 130.0)
    assert cmds == [mavlink.MAV_CMD_NAV_LAND] and core.phase == "landing"
    # the search is spread over the frames: 32 candidates refused, 2 a frame (CANDIDATES_PER_FRAME),
    # so the move starts 16 frames (4 ms) or more after the stop
    moved = np.linalg.norm(flown - np.asarray(BESIDE), axis=1) > 0.0
    t_start = _fly.times[int(np.argmax(moved))] - 0.004
    assert t_start >= 100.0 + 16 * 0.004 - 1e-9
    # the move (0.75 m, 35/16 * 0.75 s at the 1 m/s climb speed), then the plan end's 1 s hover,
    # settled: the landing is handed over then, not before
    t_move_end = t_start + 35.0 / 16.0 * 0.75
    assert t_move_end + 1.0 <= t_land <= t_move_end + 1.0 + 0.02
    # landed from the hand-worked spot, 0.75 m east, and its column is clear
    assert core.view.pos == pytest.approx((8.95, 7.5, 1.5), abs=1e-9)
    assert gate.n_landings == 2 and gate.n_landings_refused == 1
    move = gate.to_dict()["landing_moves"][0]
    assert move["kind"] == "ring" and move["path_m"] == pytest.approx(0.75)
    # every frame flown: away from the crate, never closer (the margin rule, measured directly)
    d = crate(flown)
    assert np.all(np.diff(d) >= -1e-9) and d[-1] >= REQ


def test_core_hands_the_landing_over_only_once_the_vehicle_stops_turning():
    # still turning at 0.5 rad/s (> 0.1): the landing waits the 3 s settle bound after the hover
    from pymavlink.dialects.v20 import common as mavlink

    core, gate = _core_beside(_box(*CRATE), BESIDE)
    core._steering, core._launch = True, (0.0, 8.0, 0.0)
    core._react(core.monitor.fail(100.0, "no_route", "no route", "land"))
    flown, cmds, t_land = _fly(core, 100.0, 130.0, body_rates=(0.0, 0.0, 0.5))
    assert cmds == [mavlink.MAV_CMD_NAV_LAND]
    moved = np.linalg.norm(flown - np.asarray(BESIDE), axis=1) > 0.0
    t_move_end = _fly.times[int(np.argmax(moved))] - 0.004 + 35.0 / 16.0 * 0.75
    assert t_move_end + 1.0 + 3.0 <= t_land <= t_move_end + 1.0 + 3.0 + 0.02


def test_the_report_of_a_move_and_of_none_found_follows_the_schema():
    import json
    from pathlib import Path

    from jsonschema import Draft202012Validator

    schema = json.loads((Path(__file__).parent.parent / "docs/schemas/report.schema.json").read_text())
    guard = Draft202012Validator(schema["properties"]["guard"])
    core, gate = _core_beside(_box(*CRATE), BESIDE)
    core._steering, core._launch = True, (0.0, 8.0, 0.0)
    core._react(core.monitor.fail(100.0, "no_route", "no route", "land"))
    _fly(core, 100.0, 130.0)
    slab = _box((6.0, 4.0, 0.0), (12.0, 11.0, 0.8))
    core2, gate2 = _core_beside(slab, (9.0, 7.5, 1.5))
    core2._steering, core2._launch = True, (10.0, 7.5, 0.0)
    core2._react(core2.monitor.fail(100.0, "no_route", "no route", "land"))
    _fly(core2, 100.0, 110.0)
    for g in (gate, gate2):
        doc = json.loads(json.dumps(g.to_dict()))
        assert list(guard.iter_errors(doc)) == [] and len(doc["landing_moves"]) == 1
    assert gate2.to_dict()["landing_moves"][0]["candidates_tried"] == 12 * 16 + 1


def test_core_not_steering_still_hovers():
    # attached to a vehicle it did not put in OFFBOARD: it cannot move it; it hovers (AUTO.LOITER)
    from pymavlink.dialects.v20 import common as mavlink

    core, gate = _core_beside(_box(*CRATE), BESIDE)
    core._launch = (0.0, 8.0, 0.0)
    core._react(core.monitor.fail(100.0, "no_route", "no route", "land"))
    assert _commands(core) == [mavlink.MAV_CMD_DO_SET_MODE] and core.phase == "holding"
    assert gate.landing_moves == []


def test_core_holds_when_no_spot_is_found():
    from pymavlink.dialects.v20 import common as mavlink

    slab = _box((6.0, 4.0, 0.0), (12.0, 11.0, 0.8))
    core, gate = _core_beside(slab, (9.0, 7.5, 1.5))
    core._steering, core._launch = True, (10.0, 7.5, 0.0)
    core._react(core.monitor.fail(100.0, "no_route", "no route", "land"))
    flown, cmds, _ = _fly(core, 100.0, 110.0)
    assert mavlink.MAV_CMD_NAV_LAND not in cmds and cmds[-1] == mavlink.MAV_CMD_DO_SET_MODE
    assert core.phase == "holding" and gate.landing_moves[0]["spot_enu_m"] is None
    assert np.allclose(flown, (9.0, 7.5, 1.5))                 # it stayed where it hovered
