"""The guard (companion.safety, issue 15): hand-worked geometry and the stopping law.

Every number here is worked by hand from the geometry of the test scene, not
read from the guard's output: a flat field at z = 0, one vine row over the
cells x in [5.0, 5.2], y in [0, 5.0] (0.1 m cells) extruded to a 2 m canopy,
the airframe sphere R = 0.4 m and clearances 0.5 m (required centre distance
0.9 m from rows, obstacles and the ground).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from companion.trajectory.reference import smooth_segment
from mavcore.maps.grid import ElevationModel, OccupancyGrid
from companion.replan.memory import ObstacleMemory
from companion.safety import (Guard, GuardConfig, SafetyScene, known_obstacle_distance, stopping_distance_m,
                              stopping_speed_m_s)

R, C = 0.4, 0.5
REQ = R + C          # 0.9 m from the vehicle's centre
CANOPY = 2.0


def _scene() -> SafetyScene:
    occ = np.zeros((100, 100), bool)
    occ[0:50, 50:52] = True            # rows 0..49 (y 0..5.0), cols 50..51 (x 5.0..5.2)
    grid = OccupancyGrid(occ, ~occ, 0.1)
    dem = ElevationModel(np.zeros((11, 11)), 0.0, 0.0, 1.0)
    return SafetyScene.from_maps(grid, dem, CANOPY)


def _guard(obstacle_distance=None) -> Guard:
    cfg = GuardConfig(airframe_radius_m=R, terrain_clearance_m=C, row_clearance_m=C, obstacle_clearance_m=C,
                      accel_m_s2=1.0, delay_s=0.2)
    return Guard(cfg, _scene(), obstacle_distance)


def _box(lo, hi):
    """Exact distance (m) to the axis-aligned box [lo, hi] (0 inside)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)

    def dist(points):
        p = np.asarray(points, float).reshape(-1, 3)
        e = np.maximum(np.maximum(lo - p, p - hi), 0.0)
        return np.sqrt((e * e).sum(axis=1))
    return dist


@dataclass
class _Samples:
    p: np.ndarray
    v: np.ndarray


class _Line:
    """Constant velocity from p0 for duration_s (a candidate trajectory)."""

    def __init__(self, p0, v, duration_s):
        self.p0, self.vel = np.asarray(p0, float), np.asarray(v, float)
        self.t0, self.tf = 0.0, float(duration_s)

    def sample(self, t):
        t = np.atleast_1d(np.asarray(t, float))
        return _Samples(self.p0 + t[:, None] * self.vel, np.broadcast_to(self.vel, (len(t), 3)))


class _Segment:
    """Rest-to-rest smooth segment p0 -> p1 (the take-off's shape)."""

    def __init__(self, p0, p1, T):
        self.a, self.b, self.t0, self.tf = p0, p1, 0.0, float(T)

    def sample(self, t):
        s = [smooth_segment(self.a, self.b, self.tf, float(x)) for x in np.atleast_1d(t)]
        return _Samples(np.array([x[0] for x in s]), np.array([x[1] for x in s]))


# --- the stopping law -------------------------------------------------------------------

def test_stopping_speed_hand_values():
    # a = 2, tau = 0.5, room = 3: v = sqrt(2*2*3 + (2*0.5)^2) - 2*0.5 = sqrt(13) - 1
    assert stopping_speed_m_s(3.0, 2.0, 0.5) == pytest.approx(math.sqrt(13.0) - 1.0, abs=1e-12)
    # and that speed stops in exactly the room: v tau + v^2 / (2 a) = 3
    v = math.sqrt(13.0) - 1.0
    assert stopping_distance_m(v, 2.0, 0.5) == pytest.approx(0.5 * v + v * v / 4.0, abs=1e-12)
    assert 0.5 * v + v * v / 4.0 == pytest.approx(3.0, abs=1e-12)
    # no delay: the kinematic sqrt(2 a d); no room: no approach
    assert stopping_speed_m_s(2.0, 1.0, 0.0) == pytest.approx(2.0, abs=1e-12)
    assert stopping_speed_m_s(-0.3, 1.0, 0.2) == 0.0


def test_speed_governance_refuses_a_speed_that_cannot_stop_before_the_clearance():
    # an obstacle face 1.9 m ahead: room 1.0 m; v_max = sqrt(2 + 0.04) - 0.2 = 1.2283 m/s.
    # At 1.17 m/s the vehicle stops in 1.17*0.2 + 1.17^2/2 = 0.918 m (< 1 m): flown.
    # At 1.29 m/s it needs 0.258 + 0.832 = 1.090 m (> 1 m): refused.
    g = _guard(_box((1.9, 6.0, 0.0), (3.0, 10.0, 3.0)))
    p = (0.0, 8.0, 1.5)
    assert g.check_sample(p, (1.17, 0, 0)).ok
    v = g.check_sample(p, (1.29, 0, 0))
    assert not v.ok and v.rule == "speed" and v.surface == "obstacle"
    assert v.allowed_m_s == pytest.approx(math.sqrt(2.04) - 0.2, abs=1e-9)
    # moving away from it, inside the clearance: allowed (it may get out)
    assert g.check_sample((1.2, 8.0, 1.5), (-0.5, 0, 0)).ok


# --- whole candidates, 0.1 m too close / 0.1 m clear ---------------------------------------

@pytest.mark.parametrize("margin, ok", [(-0.1, False), (0.1, True)])
def test_candidate_past_a_box(margin, ok):
    # a box 1 m wide at x 4..5, y 6..7, z 0..3; the candidate flies along x at 0.5 m/s at
    # y = 7 + 0.9 + margin: its closest approach is 0.9 + margin from the face y = 7
    # (at 0.5 m/s the stopping law allows 0.46 m/s with 0.2 m of room: passing 0.1 m
    # clear, the approach is 0.21 m/s there)
    g = _guard(_box((4.0, 6.0, 0.0), (5.0, 7.0, 3.0)))
    traj = _Line((0.0, 7.0 + REQ + margin, 1.5), (0.5, 0.0, 0.0), 18.0)
    v = g.check_trajectory(traj)
    assert v.ok is ok
    if not ok:
        assert v.surface == "obstacle" and v.distance_m < REQ + 0.1


@pytest.mark.parametrize("margin, ok", [(-0.1, False), (0.1, True)])
def test_candidate_past_a_row_end(margin, ok):
    # the row ends at y = 5.0; below the canopy the candidate flies along x at y = 5 + 0.9 + margin
    traj = _Line((1.0, 5.0 + REQ + margin, 1.5), (1.0, 0.0, 0.0), 8.0)
    g = _guard()
    v = g.check_trajectory(traj)
    assert v.ok is ok
    closest = g.distances(traj.sample(np.arange(0.0, 8.0, 0.05)).p)["row"].min()
    assert closest == pytest.approx(REQ + margin, abs=1e-6)
    if not ok:
        assert v.surface == "row" and v.rule == "clearance" and v.distance_m < REQ


@pytest.mark.parametrize("margin, ok", [(-0.1, False), (0.1, True)])
def test_candidate_over_a_row_keeps_the_clearance_above_the_canopy(margin, ok):
    # across the row at z = 2 + 0.9 + margin: the distance over it is z - canopy
    traj = _Line((1.0, 2.0, CANOPY + REQ + margin), (1.0, 0.0, 0.0), 8.0)
    g = _guard()
    v = g.check_trajectory(traj)
    assert v.ok is ok
    closest = g.distances(traj.sample(np.arange(0.0, 8.0, 0.05)).p)["row"].min()
    assert closest == pytest.approx(REQ + margin, abs=1e-6)
    if not ok:
        assert v.surface == "row" and v.distance_m < REQ


@pytest.mark.parametrize("margin, ok", [(-0.1, False), (0.1, True)])
def test_candidate_down_to_the_terrain(margin, ok):
    # a slow descent (1 m in 20 s, peak 0.11 m/s) to 0.9 + margin above the flat ground at x = 8
    traj = _Segment((8.0, 8.0, 1.0 + REQ + margin), (8.0, 8.0, REQ + margin), 20.0)
    v = _guard().check_trajectory(traj)
    assert v.ok is ok
    if not ok:
        assert v.surface == "terrain"


def test_candidate_checked_whole_not_its_first_seconds():
    # the box is met 60 s into the candidate
    g = _guard(_box((60.0, 7.0, 0.0), (61.0, 8.0, 3.0)))
    v = g.check_trajectory(_Line((0.0, 8.0 + REQ - 0.1, 1.5), (1.0, 0.0, 0.0), 80.0))
    assert not v.ok and v.t_s == pytest.approx(59.0, abs=1.5)


def test_candidate_starting_inside_may_leave_and_never_close():
    # the box's face y = 7; the candidate starts 0.6 m from it (inside the 0.9 m clearance)
    g = _guard(_box((4.0, 6.0, 0.0), (8.0, 7.0, 3.0)))
    # straight away: out of the clearance after 0.3 m (1 s at 0.3 m/s), then stays out
    assert g.check_trajectory(_Line((4.5, 7.6, 1.5), (0.0, 0.3, 0.0), 5.0)).ok
    # along the face for 5 s: never closer, never out; no time limit on that
    assert g.check_trajectory(_Line((4.5, 7.6, 1.5), (0.3, 0.0, 0.0), 5.0)).ok
    # closing at 0.02 m/s (under the old per-sample tolerance of 0.05 m/s): 0.1 m closer in
    # 5 s; the rule allows 5 mm of closing, so the sample 0.25 s after 5 mm fails
    v = g.check_trajectory(_Line((4.5, 7.6, 1.5), (0.0, -0.02, 0.0), 5.0))
    assert not v.ok and v.rule == "clearance" and v.surface == "obstacle"
    assert v.t_s == pytest.approx(0.3, abs=0.051) and v.distance_m < 0.6 - 0.005


def test_candidate_out_of_a_clearance_may_not_go_back_in():
    g = _guard(_box((4.0, 6.0, 0.0), (8.0, 7.0, 3.0)))
    # from 0.6 m out to 1.2 m (2 s at 0.3 m/s), then back toward the face at 0.04 m/s
    # (under both per-sample rules' tolerance): 0.9 m from it at t = 2 + 0.3 / 0.04 = 9.5 s
    # (rounding puts that sample on either side), the next (0.898 m) fails
    line = _Line((4.5, 7.6, 1.5), (0.0, 0.3, 0.0), 2.0)
    back = _Line((4.5, 8.2, 1.5), (0.0, -0.04, 0.0), 10.0)

    class _Out:
        t0, tf = 0.0, 12.0

        def sample(self, t):
            t = np.atleast_1d(np.asarray(t, float))
            a, b = line.sample(np.minimum(t, 2.0)), back.sample(np.maximum(t - 2.0, 0.0))
            first = (t <= 2.0)[:, None]
            return _Samples(np.where(first, a.p, b.p), np.where(first, a.v, b.v))
    v = g.check_trajectory(_Out())
    assert not v.ok and v.rule == "clearance" and v.t_s == pytest.approx(9.525, abs=0.03)


def test_contact_is_a_hard_floor_even_when_leaving():
    # starts 0.35 m from the face, inside the airframe radius (0.4 m): refused although it
    # moves straight away; from 0.45 m the same leg passes
    g = _guard(_box((4.0, 6.0, 0.0), (8.0, 7.0, 3.0)))
    v = g.check_trajectory(_Line((4.5, 7.35, 1.5), (0.0, 0.3, 0.0), 4.0))
    assert not v.ok and v.t_s == pytest.approx(0.0) and "contact" in v.detail
    assert g.check_trajectory(_Line((4.5, 7.45, 1.5), (0.0, 0.3, 0.0), 4.0)).ok


def test_the_rule_carries_across_chunks(monkeypatch):
    # the same closing candidate, judged in chunks of 7 samples: the same verdict
    import companion.safety.guard as guard_mod
    g = _guard(_box((4.0, 6.0, 0.0), (8.0, 7.0, 3.0)))
    line = _Line((4.5, 7.6, 1.5), (0.0, -0.02, 0.0), 5.0)
    whole = g.check_trajectory(line)
    monkeypatch.setattr(guard_mod, "CHUNK", 7)
    assert g.check_trajectory(line).t_s == pytest.approx(whole.t_s)


def test_check_path_is_the_margin_rule_with_a_margin():
    g = _guard(_box((4.0, 6.0, 0.0), (8.0, 7.0, 3.0)))
    toward = np.column_stack([np.full(11, 4.5), np.linspace(8.2, 7.9, 11), np.full(11, 1.5)])
    # the path ends 0.9 m from the face: keeps the clearance, not 0.05 m more
    assert g.check_path(toward).ok
    v = g.check_path(toward, 0.05)
    assert not v.ok and v.surface == "obstacle" and v.point_enu_m[1] == pytest.approx(7.93, abs=1e-9)
    # leaving from inside: passes however deep it starts (above the airframe radius)
    assert g.check_path(toward[::-1] - [0.0, 0.4, 0.0], 0.05).ok


# --- landing: never down onto what is below -----------------------------------------------

def test_landing_refused_beside_a_low_obstacle_below():
    # stopped at 1.5 m, 0.2 m beside a box whose top is 0.8 m: the descent passes its edge
    # at 0.2 m (< 0.9 m); 2 m away (1.1 m > 0.9 m from every point of the column) it lands
    g = _guard(_box((7.0, 7.0, 0.0), (8.0, 8.0, 0.8)))
    v = g.check_landing((8.2, 7.5, 1.5), (0.0, 0.0, 0.0))
    assert not v.ok and v.rule == "landing" and v.surface == "obstacle"
    assert v.distance_m == pytest.approx(0.2, abs=1e-9)
    assert g.check_landing((10.0, 7.5, 1.5), (0.0, 0.0, 0.0)).ok


def test_landing_checks_where_braking_ends():
    # at rest 1.9 m before the box the column is clear; moving at 1 m/s toward it the
    # vehicle stops 1*0.2 + 1/2 = 0.7 m on, 1.2 m from the box (>= 0.9 m): clear; at
    # 1.5 m/s it stops 0.3 + 1.125 = 1.425 m on, 0.475 m from it: refused
    g = _guard(_box((5.0, 7.0, 0.0), (6.0, 8.0, 0.5)))
    assert g.check_landing((3.1, 7.5, 1.5), (0.0, 0.0, 0.0)).ok
    assert g.check_landing((3.1, 7.5, 1.5), (1.0, 0.0, 0.0)).ok
    assert not g.check_landing((3.1, 7.5, 1.5), (1.5, 0.0, 0.0)).ok


def test_known_obstacles_adapter_memory_and_added_cells():
    mem = ObstacleMemory(0.1, 10.0, 15.0, 0.15)
    mem.add(0.0, (3.0, 4.0, 1.0))
    occ = np.zeros((100, 100), bool)
    grid = OccupancyGrid(occ, ~occ, 0.1)
    added = np.zeros((100, 100), bool)
    added[20, 30] = True               # the square x 3.0..3.1, y 2.0..2.1

    class _Known:
        pass
    known = _Known()
    known.grid, known.added = grid, added
    od = known_obstacle_distance(mem, lambda: known)
    d = od(np.array([[0.0, 0.0, 1.0], [3.05, 2.05, 7.0], [3.0, 2.5, 1.0]]))
    # inside the added column: 0 (any height); (3, 2.5): 0.4 m north of the added square
    # (0, 0, 1): 5 m from the point, hypot(3.0, 2.0) from the added square's corner (3, 2)
    assert d == pytest.approx([math.hypot(3.0, 2.0), 0.0, 0.4])


def test_hold_with_an_empty_memory_still_sees_the_added_obstacle():
    # the case: a re-route moved the obstacle into the map and emptied the
    # memory; the vehicle stopped 0.2 m beside it: the landing is refused
    mem = ObstacleMemory(0.1, 10.0, 15.0, 0.15)
    occ = np.zeros((100, 100), bool)
    added = np.zeros((100, 100), bool)
    added[70:80, 20:30] = True         # x 2.0..3.0, y 7.0..8.0

    class _Known:
        pass
    known = _Known()
    known.grid, known.added = OccupancyGrid(occ, ~occ, 0.1), added
    g = _guard(known_obstacle_distance(mem, lambda: known))
    v = g.check_landing((3.2, 7.5, 1.5), (0.0, 0.0, 0.0))
    assert not v.ok and v.surface == "obstacle" and v.distance_m == pytest.approx(0.2, abs=1e-9)
    assert g.check_landing((4.0, 7.5, 1.5), (0.0, 0.0, 0.0)).ok      # 1.0 m > 0.9 m


# --- the fallback: a braked hover that stops within the stopping law ----------------------

def test_default_law_hand_value():
    # defaults a = 1 m/s^2, tau = 0.5 s, room 1 m: v = sqrt(2 + 0.25) - 0.5 = 1.0 m/s,
    # stopping in 1.0 * 0.5 + 1.0^2 / 2 = 1.0 m
    from companion.safety.guard import DELAY_S

    assert stopping_speed_m_s(1.0, 1.0, DELAY_S) == pytest.approx(1.0, abs=1e-12)
    assert stopping_distance_m(1.0, 1.0, DELAY_S) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("speed", [0.5, 1.0, 1.5])
def test_gate_brakes_to_rest_within_the_stopping_distance(speed):
    from companion.trajectory.reference import RefSample
    from companion.safety.gate import GuardGate
    from companion.safety.guard import DELAY_S, GRACE_S

    cfg = GuardConfig(R, C, C, C, accel_m_s2=1.0, delay_s=DELAY_S)
    # an obstacle just beyond what the law allows at `speed` - 0.1: that sample passes,
    # one at `speed` + 0.2 that does not brake is flown for GRACE_S, then refused
    room = stopping_distance_m(speed - 0.1, 1.0, DELAY_S) + 0.02
    g = GuardGate(Guard(cfg, _scene(), _box((8.0 + REQ + room, 6.0, 0.0), (9.0 + REQ + room, 10.0, 3.0))), 2.0)
    z = (0.0, 0.0, 0.0)
    ok = RefSample((8.0, 8.0, 1.5), (speed - 0.1, 0.0, 0.0), z, z, z, (0.0, 1.0, 0.0))
    assert g.dispose(0.0, ok)[1] is None
    bad = RefSample((8.0, 8.0, 1.5), (speed + 0.2, 0.0, 0.0), z, z, z, (0.0, 1.0, 0.0))
    t = 0.0
    while True:
        t += 0.004
        ref, verdict = g.dispose(t, bad)
        if verdict is not None:
            break
        assert ref is bad and t <= GRACE_S + 0.004 + 1e-9
    assert verdict.rule == "speed" and g.engaged and t > GRACE_S
    x = []
    while not g.at_rest and t < 20.0:
        t += 0.004
        ref = g.dispose(t, bad)[0]          # the mode's proposals are no longer flown
        x.append(ref.p[0])
    assert g.at_rest
    # braked from the last state flown (speed + 0.2): within its stopping distance
    assert max(x) - 8.0 <= stopping_distance_m(speed + 0.2, 1.0, DELAY_S) + 1e-9
    assert g.dispose(t + 1.0, bad)[0].v == z


def test_gate_lets_a_braking_mode_brake():
    from companion.trajectory.reference import RefSample
    from companion.safety.gate import GuardGate

    g = GuardGate(_guard(_box((1.9, 6.0, 0.0), (3.0, 10.0, 3.0))), 2.0)
    z = (0.0, 0.0, 0.0)
    # 1.29 m/s with 1 m of room breaks the law (test above); decelerating at 0.5 m/s^2
    # (> 0.3 of the 1 m/s^2 limit) it is braking: flown, for as long as it brakes
    braking = RefSample((0.0, 8.0, 1.5), (1.29, 0.0, 0.0), (-0.5, 0.0, 0.0), z, z, (0.0, 1.0, 0.0))
    for k in range(200):
        assert g.dispose(0.004 * k, braking) == (braking, None)
    coasting = RefSample((0.0, 8.0, 1.5), (1.29, 0.0, 0.0), (-0.2, 0.0, 0.0), z, z, (0.0, 1.0, 0.0))
    verdicts = [g.dispose(0.8 + 0.004 * k, coasting)[1] for k in range(100)]
    assert any(v is not None for v in verdicts) and g.engaged


# --- the flight core: a hold never comes down onto a known obstacle -----------------------

def _core_beside(obstacle_distance, pos):
    """A FlightCore in the air at ``pos`` (at rest) in the trajectory phase, its guard on the
    test scene with ``obstacle_distance``."""
    from companion.flight.config import RunnerConfig
    from companion.flight.core import FlightCore, FlightInputs
    from companion.safety.gate import GuardGate
    from mavcore.vehicle import VehicleConfig

    gate = GuardGate(_guard(obstacle_distance), 2.0)
    inputs = FlightInputs(None, np.zeros((1, 3)), (44.8, -0.6, 30.0), (0.0, 0.0, 0.0), guard=gate)
    core = FlightCore(inputs, RunnerConfig(control="vehicle"), VehicleConfig())
    core.view.armed, core.phase, core.view.t_s = True, "trajectory", 100.0
    from mavcore import autopilot as autopilots

    core.view.autopilot = autopilots.PX4_AUTOPILOT          # as detected from a PX4 HEARTBEAT
    core.view.pos, core.view.vel, core._proc = pos, (0.0, 0.0, 0.0), None
    return core, gate


def _commands(core) -> list:
    """The COMMAND_LONG ids the core queued."""
    return [m.command for m in core.take_outbox() if getattr(m, "get_type", lambda: "")() == "COMMAND_LONG"]


def test_core_no_route_hold_beside_a_low_obstacle_hovers_instead_of_landing():
    # the flight: stopped 0.2 m beside a 0.8 m crate; no_route -> --on-failure land
    core, gate = _core_beside(_box((7.0, 7.0, 0.0), (8.0, 8.0, 0.8)), (8.2, 7.5, 1.5))
    from pymavlink.dialects.v20 import common as mavlink

    core._react(core.monitor.fail(100.0, "no_route", "no route", "land"))
    cmds = _commands(core)
    assert mavlink.MAV_CMD_NAV_LAND not in cmds
    assert cmds == [mavlink.MAV_CMD_DO_SET_MODE]              # AUTO.LOITER: hover where it is
    assert core.phase == "holding" and gate.n_landings_refused == 1
    assert gate.to_dict()["refusal_list"][0]["candidate"] == "landing"


def test_core_lands_where_the_column_is_clear():
    core, gate = _core_beside(_box((7.0, 7.0, 0.0), (8.0, 8.0, 0.8)), (10.0, 7.5, 1.5))
    from pymavlink.dialects.v20 import common as mavlink

    core._react(core.monitor.fail(100.0, "no_route", "no route", "land"))
    assert _commands(core) == [mavlink.MAV_CMD_NAV_LAND] and core.phase == "landing"
    assert gate.n_landings == 1 and gate.n_landings_refused == 0


def test_the_per_frame_path_judges_as_the_array_path():
    # the scalar per-frame check and the vectorised candidate check agree sample by sample
    rng = np.random.default_rng(7)
    g = _guard(_box((4.0, 6.0, 0.0), (5.0, 7.0, 3.0)))
    p = rng.uniform((0.0, 0.0, 0.0), (10.0, 10.0, 3.5), (400, 3))
    v = rng.uniform(-1.5, 1.5, (400, 3))
    for pk, vk in zip(p, v):
        a, b = g.check_sample(pk, vk), g._judge(pk, vk)
        assert (a.ok, a.rule, a.surface) == (b.ok, b.rule, b.surface)
        if not a.ok:
            assert a.distance_m == pytest.approx(b.distance_m, abs=1e-9)


def test_core_refuses_a_new_trajectory_into_the_ground_and_flies_the_braked_hover():
    # the rejoin into the ground: the mode's new trajectory dips to z = -0.11 m;
    # the core checks it whole when it appears, flies the brake instead, then lands checked
    from types import SimpleNamespace

    from pymavlink.dialects.v20 import common as mavlink

    from companion.trajectory.reference import RefSample

    z = (0.0, 0.0, 0.0)
    level = _Line((2.0, 8.0, 1.5), (0.5, 0.0, 0.0), 10.0)
    dive = _Segment((3.0, 8.0, 1.5), (5.0, 8.0, -0.11), 4.0)

    class _Mode:
        def __init__(self):
            self.plan = SimpleNamespace(trajectory=level)
            self.stepped = 0

        def step(self, t, pos, vel):
            self.stepped += 1
            tr = self.plan.trajectory
            s = tr.sample([t - 100.0])
            p, v = tuple(s.p[0]), tuple(s.v[0])
            return SimpleNamespace(ref=RefSample(p, v, z, z, z, (0.0, 1.0, 0.0)), mode="follow", events=(),
                                   finished=False, hold=False)

    core, gate = _core_beside(None, (2.0, 8.0, 1.5))
    mode = core.replanner = _Mode()
    core._t_traj, core._guard_tau0, core._guard_plan = 100.0, 0.0, mode.plan
    core._traj_deadline = 1e9
    for k in range(250):                                  # 1 s of the level plan: flown
        ref = core._guarded(100.0 + 0.004 * k)
        assert ref.p[0] == pytest.approx(2.0 + 0.5 * 0.004 * k)
    last = ref
    mode.plan = SimpleNamespace(trajectory=dive)          # the new candidate
    ref = core._guarded(101.0)
    assert gate.engaged and gate.refusals[0]["candidate"] == "trajectory"
    assert gate.refusals[0]["surface"] == "terrain"
    texts = [m.text for m in core.take_outbox() if getattr(m, "get_type", lambda: "")() == "STATUSTEXT"]
    assert any(t.startswith("companion: guard: terrain") for t in texts)
    n = mode.stepped
    t = 101.0
    while core.phase == "trajectory":
        t += 0.004
        ref = core._guarded(t)
        assert ref.p[2] == pytest.approx(1.5, abs=1e-9)   # braked level, never down the dive
        assert t < 105.0
    assert mode.stepped == n                             # the mode is no longer flown
    assert ref.p[0] - last.p[0] <= stopping_distance_m(0.5, 1.0, 0.5)
    assert core.monitor.first.kind == "guard" and core.phase == "landing"
    assert mavlink.MAV_CMD_NAV_LAND in _commands(core)    # the column below is clear
