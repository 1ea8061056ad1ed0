"""ArduCopter's AUTO on the SITL's ardupilot personality (``MissionRules``):
item 0 is home and never flown, way-points are reached within WPNAV_RADIUS
whatever their param2, the RETURN_TO_LAUNCH item is flown inside AUTO and
reached on touchdown, the take-off waits for its release (``auto_armed``),
a mission without a take-off is refused armed on the ground, arming in AUTO
needs AUTO_OPTIONS bit 0, and the vehicle disarms when the mission ends on
the ground. Sources: ArduCopter/mode_auto.cpp, GCS_Mavlink.cpp
(MAV_CMD_MISSION_START), libraries/AP_Mission (docs/mission.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavcore.autopilot import ARDUCOPTER, PX4_AUTOPILOT
from sitl.flightstack import RESULT_ACCEPTED, RESULT_DENIED, FlightMode, FlightStack, Parameters
from sitl.mission_exec import (NAV_RETURN_TO_LAUNCH, NAV_TAKEOFF, NAV_WAYPOINT, MissionExecutor,
                               mission_problem)
from test_sitl_flightstack import S, air, ground, texts
from test_sitl_mission_exec import IdealVehicle, nav, params, state

RULES = ARDUCOPTER.mission_rules
#: Item 0 is home, far from where the mission flies: flying it would show.
HOME_ITEM = nav(0, NAV_WAYPOINT, (50.0, 50.0, 0.0))


def copter_mission(first_nav=NAV_TAKEOFF):
    return [HOME_ITEM, nav(1, first_nav, (0.0, 0.0, 3.0)), nav(2, NAV_WAYPOINT, (4.0, 0.0, 3.0), p2=0.1),
            nav(3, NAV_WAYPOINT, (4.0, 4.0, 3.0), p2=0.1), nav(4, NAV_RETURN_TO_LAUNCH)]


def test_item_0_is_home_and_never_flown_and_rtl_lands_inside_auto():
    ex = MissionExecutor(copter_mission(), params(NAV_ACC_RAD=0.5, RTL_RETURN_ALT=5.0), (0, 0, 0), RULES)
    assert ex.current == 1 and ex.start(state((0, 0, 0), landed=True)) is None and ex.current == 1
    v = IdealVehicle(ex)
    step = v.run(120.0)
    assert step is None or step.action is None          # never handed to the stack's RTL mode
    assert [s for s, _ in v.reached] == [1, 2, 3, 4]      # home (0) never reached
    assert ex.finished and v.landed
    # way-points: reached on WPNAV_RADIUS (0.5 m), param2 (0.1 m) unread: the ideal vehicle is on
    # the target, which moves 5 m/s * 10 ms per frame, so it is reached between 0.45 and 0.5 m away
    for seq, p in v.reached[1:3]:
        d = math.dist(p[:2], ex.items[seq].pos_enu_m[:2])
        assert 0.5 - 5.0 * 0.01 - 1e-9 <= d <= 0.5 + 1e-9
    # the return: up to RTL_ALT above home (5 m, higher than the 3 m flown), home, down to the ground
    zs = [sp.pos_enu_m[2] for sp in v.setpoints if sp is not None and not math.isnan(sp.pos_enu_m[2])]
    assert max(zs) == pytest.approx(5.0)
    assert v.p == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    assert max(abs(sp.pos_enu_m[0]) for sp in v.setpoints if sp is not None) <= 4.0 + 1e-9


def test_px4_rules_read_param2_and_fly_item_0():
    items = [nav(0, NAV_TAKEOFF, (0, 0, 3)), nav(1, NAV_WAYPOINT, (4, 0, 3), p2=0.1)]
    ex = MissionExecutor(items, params(NAV_ACC_RAD=0.5), (0, 0, 0), PX4_AUTOPILOT.mission_rules)
    ex.start(state((0, 0, 0), landed=True))
    v = IdealVehicle(ex)
    v.run(30.0)
    assert [s for s, _ in v.reached] == [0, 1]
    assert math.dist(v.reached[1][1][:2], (4, 0)) <= 0.1 + 1e-9


def test_mission_problem_skips_home_and_needs_an_item_after_it():
    assert mission_problem([nav(0, 999)] + copter_mission()[1:], first_seq=1) is None
    assert mission_problem([HOME_ITEM], first_seq=1) == "no mission stored"
    assert "DO_JUMP to 0" in mission_problem(copter_mission()[:4] + [nav(4, 177, p1=0, p2=1)], first_seq=1)


@pytest.fixture()
def copter():
    return FlightStack(Parameters.for_autopilot(ARDUCOPTER), (0.0, 0.0, 0.0), ARDUCOPTER)


def fly_mission(stack, items):
    stack.set_mission(MissionExecutor(items, stack.params, stack.home_enu_m, RULES), None)


def test_armed_on_the_ground_auto_needs_a_takeoff_first(copter):
    fly_mission(copter, copter_mission(first_nav=NAV_WAYPOINT))
    assert copter.set_mode(0, ground(), FlightMode.OFFBOARD).accepted          # GUIDED
    assert copter.arm(0, ground()).accepted
    r = copter.set_mode(0, ground(), FlightMode.MISSION)
    assert r.result == RESULT_DENIED and copter.mode is FlightMode.OFFBOARD
    assert "Auto: Missing Takeoff Cmd" in texts(copter)
    fly_mission(copter, copter_mission())
    assert copter.set_mode(0, ground(), FlightMode.MISSION).accepted
    assert copter.custom_mode == 3                                               # AUTO


def test_the_takeoff_waits_for_mission_start(copter):
    fly_mission(copter, copter_mission())
    copter.set_mode(0, ground(), FlightMode.OFFBOARD)
    copter.arm(0, ground())
    assert copter.set_mode(0, ground(), FlightMode.MISSION).accepted
    for k in range(1, 50):                                # 5 s: no throttle raised, motors idle
        out = copter.update(k * S // 10, ground())
        assert out.armed and out.idle and out.setpoint is None
    assert copter.mission.current == 1
    assert copter.mission_start_command(5 * S, ground(), 2.0, 0.0).result == RESULT_DENIED   # first item: unsupported
    assert copter.mission_start_command(5 * S, ground(), 0.0, 0.0).result == RESULT_ACCEPTED
    out = copter.update(5 * S + S // 10, ground())
    assert not out.idle and out.setpoint.vel_enu_m_s[2] == pytest.approx(copter.params["MPC_TKO_SPEED"])


def test_auto_options_bit_1_takes_off_without_release_and_bit_0_arms_in_auto(copter):
    fly_mission(copter, copter_mission())
    assert copter.set_mode(0, ground(), FlightMode.MISSION).accepted             # disarmed: allowed
    r = copter.arm(0, ground())
    assert r.result == RESULT_DENIED and r.reason == "Mode not armable"
    assert copter.params.set("AUTO_OPTIONS", 3).ok
    assert copter.arm(0, ground()).accepted
    out = copter.update(S // 10, ground())
    assert not out.idle and out.setpoint.vel_enu_m_s[2] > 0


def test_disarms_when_the_mission_ends_on_the_ground(copter):
    items = [HOME_ITEM, nav(1, NAV_TAKEOFF, (0.0, 0.0, 1.0)), nav(2, 21, (0.0, 0.0, 1.0))]   # take off, land
    fly_mission(copter, items)
    copter.set_mode(0, ground(), FlightMode.OFFBOARD)
    copter.arm(0, ground())
    copter.set_mode(0, ground(), FlightMode.MISSION)
    copter.mission_start_command(0, ground(), 0.0, 0.0)
    copter.update(S, air(z=1.0))                          # take-off reached
    copter.update(2 * S, air(z=0.5))                      # landing
    assert copter.armed
    out = copter.update(3 * S, ground())                  # touchdown: the mission's last item reached
    assert not out.armed and "Disarmed (mission complete)" in texts(copter)
    assert copter.mission.finished and np.all(np.isfinite(copter.home_enu_m))
