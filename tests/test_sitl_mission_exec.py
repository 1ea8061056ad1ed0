"""The SITL's AUTO.MISSION state machine (sitl.mission_exec) on hand-worked
missions, flown by an ideal vehicle that is wherever the last setpoint put
it: the order of the items (DO_JUMP repeat counts), when a way-point counts
as reached (its acceptance radius), the speed and the yaw it asks for."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitl.flightstack import NavState, Parameters
from sitl.mission_exec import (DO_CHANGE_SPEED, DO_JUMP, DO_SET_ROI_LOCATION, NAV_LAND, NAV_RETURN_TO_LAUNCH,
                               NAV_TAKEOFF, NAV_WAYPOINT, MissionExecutor, NavItem, carrot_step,
                               heading_deg_to_yaw_enu, mission_problem)

DT = 0.01


def nav(seq, command, pos=None, p1=0.0, p2=0.0, p3=0.0, p4=math.nan):
    return NavItem(seq, command, (p1, p2, p3, p4), pos)


def state(p, landed=False, yaw=0.0):
    return NavState(np.array(p, dtype=float), np.zeros(3), yaw, 0.0, landed)


class IdealVehicle:
    """Flies the executor: the vehicle is where the previous setpoint was
    (on the ground until the setpoint climbs; the landing ends at z = 0)."""

    def __init__(self, ex: MissionExecutor, start=(0.0, 0.0, 0.0)):
        self.ex, self.p, self.landed = ex, np.array(start, float), True
        self.reached: list[tuple[int, np.ndarray]] = []
        self.setpoints = []

    def run(self, max_s: float):
        for _ in range(int(max_s / DT)):
            step = self.ex.update(state(self.p, self.landed), DT)
            for seq in self.ex.pop_events():
                self.reached.append((seq, self.p.copy()))
            if step.action is not None or (self.ex.finished and self.landed):
                return step
            sp = step.setpoint
            self.setpoints.append(sp)
            if sp is None:
                continue
            q = np.array(sp.pos_enu_m, float)
            if math.isnan(q[2]):   # landing: descend at the asked speed
                q[2] = max(0.0, self.p[2] + sp.vel_enu_m_s[2] * DT)
            self.p = q
            self.landed = self.p[2] <= 0.0
        return None


def params(**kw):
    return Parameters(initial={"MPC_TKO_SPEED": 2.0, "MPC_XY_CRUISE": 5.0, "NAV_ACC_RAD": 0.5,
                               "NAV_MC_ALT_RAD": 0.2, **kw})


def test_do_jump_repeats_the_loop_its_count_then_goes_on():
    items = [nav(0, NAV_TAKEOFF, (0, 0, 5)), nav(1, NAV_WAYPOINT, (4, 0, 5)), nav(2, NAV_WAYPOINT, (4, 4, 5)),
             nav(3, DO_JUMP, p1=1, p2=2), nav(4, NAV_WAYPOINT, (0, 4, 5)), nav(5, NAV_LAND, (0, 0, 5))]
    ex = MissionExecutor(items, params(), (0, 0, 0))
    assert ex.start(state((0, 0, 0), landed=True)) is None
    v = IdealVehicle(ex)
    v.run(120.0)
    # two jumps back to item 1: the loop 1, 2 is flown three times; DO_JUMP is never "reached"
    assert [s for s, _ in v.reached] == [0, 1, 2, 1, 2, 1, 2, 4, 5]
    assert ex.finished and v.landed
    # an infinite jump (-1) keeps looping: after 60 s of 16 m loops at 5 m/s it is still in it
    items[3] = nav(3, DO_JUMP, p1=1, p2=-1)
    ex = MissionExecutor(items, params(), (0, 0, 0))
    ex.start(state((0, 0, 0), landed=True))
    v = IdealVehicle(ex)
    v.run(60.0)
    assert 4 not in [s for s, _ in v.reached] and not ex.finished


def test_waypoint_reached_at_its_acceptance_radius_else_nav_acc_rad():
    for p2, radius in ((3.0, 3.0), (0.0, 0.5)):
        items = [nav(0, NAV_TAKEOFF, (0, 0, 5)), nav(1, NAV_WAYPOINT, (20, 0, 5), p2=p2),
                 nav(2, NAV_WAYPOINT, (20, 10, 5))]
        ex = MissionExecutor(items, params(), (0, 0, 0))
        ex.start(state((0, 0, 0), landed=True))
        v = IdealVehicle(ex)
        v.run(30.0)
        seq, p = v.reached[1]
        assert seq == 1
        # first frame within the radius: at most one frame's travel (5 m/s * DT) inside it
        d = math.hypot(20 - p[0], p[1])
        assert radius - 5.0 * DT - 1e-9 <= d <= radius + 1e-9


def test_takeoff_climbs_at_mpc_tko_speed_to_the_item_altitude():
    ex = MissionExecutor([nav(0, NAV_TAKEOFF, (0, 0, 4)), nav(1, NAV_WAYPOINT, (0, 5, 4))], params(), (0, 0, 0))
    ex.start(state((0, 0, 0), landed=True))
    v = IdealVehicle(ex)
    v.run(10.0)
    seq, p = v.reached[0]
    assert seq == 0 and p[2] >= 4.0 - 0.2 - 1e-9
    # 4 m at 2 m/s: about 2 s (the first setpoint climbs from the ground)
    climb = [sp for sp in v.setpoints[:400] if sp.vel_enu_m_s[2] > 0]
    assert len(climb) * DT == pytest.approx(4.0 / 2.0, abs=2 * DT)


def test_do_change_speed_sets_the_leg_speed_capped_by_mpc_xy_vel_max():
    for asked, flown in ((2.0, 2.0), (30.0, 5.0)):
        items = [nav(0, NAV_TAKEOFF, (0, 0, 5)), nav(1, DO_CHANGE_SPEED, p1=1, p2=asked),
                 nav(2, NAV_WAYPOINT, (100, 0, 5))]
        ex = MissionExecutor(items, params(MPC_XY_VEL_MAX=5.0), (0, 0, 0))
        ex.start(state((0, 0, 0), landed=True))
        v = IdealVehicle(ex)
        v.run(8.0)
        speeds = [math.hypot(*sp.vel_enu_m_s[:2]) for sp in v.setpoints[-100:]]
        assert speeds == pytest.approx([flown] * 100)


def test_the_target_slows_to_the_corner_speed_of_the_turn():
    """A right-angle turn: the target arrives at the corner at rest (cos 90 = 0);
    a straight continuation keeps the speed."""
    for nxt, v_end in (((20, 10, 5), 0.0), ((40, 0, 5), 5.0)):
        items = [nav(0, NAV_TAKEOFF, (0, 0, 5)), nav(1, NAV_WAYPOINT, (20, 0, 5), p2=0.01),
                 nav(2, NAV_WAYPOINT, nxt)]
        ex = MissionExecutor(items, params(), (0, 0, 0))
        ex.start(state((0, 0, 0), landed=True))
        v = IdealVehicle(ex)
        v.run(10.0)
        at = next(i for i, sp in enumerate(v.setpoints) if sp.pos_enu_m[0] >= 20 - 0.01)
        prev = v.setpoints[at - 1]
        assert math.hypot(*prev.vel_enu_m_s[:2]) == pytest.approx(v_end, abs=math.sqrt(2 * 2.0 * 5.0 * DT) + 1e-6)


def test_roi_yaw_points_the_nose_at_the_location_and_param4_is_a_compass_heading():
    items = [nav(0, NAV_TAKEOFF, (0, 0, 5), p4=90.0), nav(1, DO_SET_ROI_LOCATION, (0, 10, 0)),
             nav(2, NAV_WAYPOINT, (5, 0, 5), p4=0.0), nav(3, NAV_WAYPOINT, (5, 20, 5))]
    ex = MissionExecutor(items, params(), (0, 0, 0))
    ex.start(state((0, 0, 0), landed=True))
    v = IdealVehicle(ex)
    v.run(1.0)
    # take-off param4 = 90 deg (east): ENU yaw 0
    assert v.setpoints[-1].yaw_enu_rad == pytest.approx(0.0, abs=1e-12)
    v.run(20.0)
    # at (5, 0) the ROI (0, 10) is at atan2(10, -5) = 116.565 deg from east (param4 = north is overridden)
    # (the vehicle is where the previous setpoint put it)
    i = min(range(len(v.setpoints) - 1), key=lambda i: math.dist(v.setpoints[i].pos_enu_m[:2], (5.0, 0.0)))
    x, y = v.setpoints[i].pos_enu_m[:2]
    assert math.dist((x, y), (5.0, 0.0)) < 0.5
    assert v.setpoints[i + 1].yaw_enu_rad == pytest.approx(math.atan2(10.0 - y, 0.0 - x), abs=1e-9)
    assert math.degrees(v.setpoints[i + 1].yaw_enu_rad) == pytest.approx(116.565, abs=3.0)
    assert heading_deg_to_yaw_enu(0.0) == pytest.approx(math.pi / 2)      # north
    assert abs(heading_deg_to_yaw_enu(270.0)) == pytest.approx(math.pi)   # west
    assert heading_deg_to_yaw_enu(135.0) == pytest.approx(-math.pi / 4)  # south-east


def test_return_to_launch_item_hands_over_and_landed_start_inserts_a_takeoff():
    items = [nav(0, NAV_WAYPOINT, (3, 0, 5)), nav(1, NAV_RETURN_TO_LAUNCH)]
    ex = MissionExecutor(items, params(MIS_TAKEOFF_ALT=2.5), (0, 0, 0))
    ex.start(state((0, 0, 0), landed=True))
    v = IdealVehicle(ex)
    # no NAV_TAKEOFF: PX4 climbs to MIS_TAKEOFF_ALT first, vertically
    v.run(1.0)
    assert all(sp.pos_enu_m[0] == 0.0 for sp in v.setpoints) and v.setpoints[-1].pos_enu_m[2] == pytest.approx(2.0)
    step = v.run(20.0)
    assert step.action == "rtl" and [s for s, _ in v.reached] == [0, 1]


def test_mission_problems_are_named():
    assert mission_problem([]) == "no mission stored"
    assert "command 31" in mission_problem([nav(0, 31, (0, 0, 1))])
    assert "DO_JUMP" in mission_problem([nav(0, DO_JUMP, p1=0, p2=1)])        # to itself
    assert "no position" in mission_problem([nav(0, NAV_WAYPOINT, None)])


def test_carrot_step_moves_at_speed_and_stops_on_the_target():
    c, vel, arrived = carrot_step((0, 0, 0), (10, 0, 0), 2.0, 2.0, 0.5)
    assert c == [1.0, 0.0, 0.0] and vel == (2.0, 0.0, 0.0) and not arrived
    c, vel, arrived = carrot_step((9.9, 0, 0), (10, 0, 0), 2.0, 0.0, 0.5)
    assert c == [10.0, 0.0, 0.0] and arrived
