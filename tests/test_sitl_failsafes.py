"""The SITL flight stack's failsafes at their thresholds (issue 19: every failsafe test must
fail when its rule is broken; ``benchmarks/mutation.py`` checks it).

Thresholds come from the documentation (docs/mavlink.md, the module docstring,
PX4's parameter defaults); each is probed just inside and just outside.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore.codec import PositionTarget
from sitl.collision import CrashEvent
from sitl.flightstack import (
    RESULT_ACCEPTED, RESULT_DENIED, RESULT_TEMPORARILY_REJECTED, FlightMode, FlightStack, NavState, Parameters,
)

S = 1_000_000   # us per second
NAN3 = np.full(3, np.nan)
HOME = (3.0, -2.0, 1.0)   # not the origin: a sign error in "home - position" shows


def ground(x=HOME[0], y=HOME[1], z=HOME[2], tilt_deg=0.0):
    return NavState(np.array([x, y, z]), np.zeros(3), 0.0, math.radians(tilt_deg), True)


def air(x=HOME[0], y=HOME[1], z=HOME[2] + 2.0):
    return NavState(np.array([x, y, z]), np.zeros(3), 0.0, 0.0, False)


def pos_target(p=(0.0, 0.0, 2.0)):
    return PositionTarget(np.array(p, float), NAN3.copy(), NAN3.copy(), None, None, 0xDF8)


def texts(stack):
    return [e.text for e in stack.pop_events()]


@pytest.fixture()
def stack():
    return FlightStack(Parameters(), home_enu_m=HOME)


def test_failsafe_parameters_have_their_documented_defaults():
    """docs/mavlink.md: COM_HIL_TMO 0.2 s, COM_OF_LOSS_T 1 s, COM_FAIL_ACT_T 5 s, COM_OBL_ACT 0
    (land), COM_DISARM_LAND 2 s; PX4's COM_DISARM_PRFLT 10 s."""
    p = Parameters()
    assert (p["COM_HIL_TMO"], p["COM_OF_LOSS_T"], p["COM_FAIL_ACT_T"], p["COM_OBL_ACT"],
            p["COM_DISARM_LAND"], p["COM_DISARM_PRFLT"]) == (0.2, 1.0, 5.0, 0, 2.0, 10.0)


# --------------------------------------------------------------------------- return to launch
def _returning(stack, x, y, z):
    """Armed in the air at (x, y, z), RTL entered, the climb phase done (z is the return altitude)."""
    assert stack.arm(0, air(x, y, z), force=True).accepted
    stack.update(0, air(x, y, z))
    assert stack.set_mode(0, air(x, y, z), FlightMode.RTL).accepted
    stack.update(S // 10, air(x, y, z))            # phase 0 -> 1: at the return altitude
    assert stack.mode is FlightMode.RTL
    texts(stack)


@pytest.mark.parametrize("dx,dy,lands", [(0.4, 0.0, True), (0.6, 0.0, False), (0.5, 0.0, False), (0.0, -0.45, True),
                                         (0.3, 0.3, True), (0.4, 0.4, False), (-0.6, 0.0, False)])
def test_return_lands_only_within_half_a_metre_of_home(stack, dx, dy, lands):
    """RTL_ACCEPT_RADIUS_M = 0.5 m horizontally: 0.4 m (and 0.3 x sqrt 2 = 0.42 m) lands,
    0.6 m (and 0.4 x sqrt 2 = 0.57 m) keeps returning, once the carrot is home."""
    z = HOME[2] + Parameters()["RTL_RETURN_ALT"]
    _returning(stack, HOME[0] + 3.0, HOME[1], z)
    stack.update(S // 10 + 2 * S, air(HOME[0] + dx, HOME[1] + dy, z))   # 2 s at 5 m/s: carrot home
    assert (stack.mode is FlightMode.LAND) is lands
    assert texts(stack) == (["Return: home reached, landing"] if lands else [])


def test_return_does_not_land_before_the_carrot_is_home(stack):
    """The vehicle near home while the carrot is still 3 m out: keep returning."""
    z = HOME[2] + Parameters()["RTL_RETURN_ALT"]
    _returning(stack, HOME[0] + 20.0, HOME[1], z)
    out = stack.update(S // 10 + 2 * S, air(HOME[0] + 0.1, HOME[1], z))   # carrot 10 m along: 10 m out
    assert stack.mode is FlightMode.RTL
    assert out.setpoint.pos_enu_m == pytest.approx((HOME[0] + 10.0, HOME[1], z))


def test_return_carrot_reaching_home_exactly_stops_there(stack):
    """10 m out, 2 s at MPC_XY_CRUISE 5 m/s: the step equals the distance; the carrot is home at rest."""
    z = HOME[2] + Parameters()["RTL_RETURN_ALT"]
    _returning(stack, HOME[0] + 10.0, HOME[1], z)
    out = stack.update(S // 10 + 2 * S, air(HOME[0] + 5.0, HOME[1], z))
    assert out.setpoint.pos_enu_m == pytest.approx((HOME[0], HOME[1], z))
    assert tuple(out.setpoint.vel_enu_m_s) == (0.0, 0.0, 0.0)
    assert stack.mode is FlightMode.RTL                          # the vehicle is 5 m out


def test_return_flies_towards_home_along_the_line_at_cruise(stack):
    """From (+3, +4) of home (5 m), 0.4 s at 5 m/s: the carrot moves 2 m along (-0.6, -0.8)."""
    z = HOME[2] + Parameters()["RTL_RETURN_ALT"]
    _returning(stack, HOME[0] + 3.0, HOME[1] + 4.0, z)
    out = stack.update(S // 10 + 4 * S // 10, air(HOME[0] + 3.0, HOME[1] + 4.0, z))
    assert out.setpoint.pos_enu_m == pytest.approx((HOME[0] + 3.0 - 1.2, HOME[1] + 4.0 - 1.6, z))
    assert out.setpoint.vel_enu_m_s == pytest.approx((-3.0, -4.0, 0.0))


@pytest.mark.parametrize("below,climbed", [(0.4, True), (0.5, False), (0.6, False)])
def test_return_leaves_the_climb_within_half_a_metre_of_the_return_altitude(stack, below, climbed):
    """Phase 0 ends once the climb reference is at the return altitude and the vehicle within
    0.5 m of it; until then the setpoint stays above the start point."""
    z = HOME[2] + Parameters()["RTL_RETURN_ALT"]
    x0 = HOME[0] + 10.0
    stack.arm(0, air(x0, HOME[1], z - 1.0), force=True)
    stack.update(0, air(x0, HOME[1], z - 1.0))
    stack.set_mode(0, air(x0, HOME[1], z - 1.0), FlightMode.RTL)
    out = stack.update(S, air(x0, HOME[1], z - below))          # 1 s at 3 m/s: the reference is up
    assert out.setpoint.pos_enu_m[2] == pytest.approx(z)
    out = stack.update(2 * S, air(x0, HOME[1], z - below))
    moved = bool(out.setpoint.pos_enu_m[0] < x0 - 1.0)
    assert moved is climbed


def test_return_climb_ramps_at_the_climb_speed(stack):
    """MPC_Z_VEL_MAX_UP = 3 m/s: 0.5 s after entering RTL 4 m below the return altitude the
    reference is 1.5 m up."""
    z = HOME[2] + Parameters()["RTL_RETURN_ALT"]
    st = air(HOME[0] + 10.0, HOME[1], z - 4.0)
    stack.arm(0, st, force=True)
    stack.update(0, st)
    stack.set_mode(0, st, FlightMode.RTL)
    out = stack.update(S // 2, st)
    assert out.setpoint.pos_enu_m == pytest.approx((HOME[0] + 10.0, HOME[1], z - 2.5))


# --------------------------------------------------------------------------- arming
@pytest.mark.parametrize("tilt_deg,ok", [(29.0, True), (31.0, False)])
def test_arming_needs_less_than_30_degrees_of_tilt(stack, tilt_deg, ok):
    r = stack.arm(0, ground(tilt_deg=tilt_deg))
    assert (r.result == RESULT_ACCEPTED) is ok and stack.armed is ok
    if not ok:
        assert r.reason == "vehicle not level" and "Arming denied: vehicle not level" in texts(stack)
    else:
        assert texts(stack) == ["Armed in AUTO.LOITER"]


@pytest.mark.parametrize("mode", [FlightMode.LAND, FlightMode.RTL])
def test_arming_refused_in_land_and_return(stack, mode):
    stack.mode = mode
    r = stack.arm(0, ground())
    assert r.result == RESULT_DENIED and r.reason == f"not armable in {mode.label}" and not stack.armed


def test_arming_in_offboard_needs_a_fresh_stream(stack):
    stack.offboard_setpoint(0, pos_target())
    assert stack.set_mode(0, ground(), FlightMode.OFFBOARD).accepted
    loss = stack.params["COM_OF_LOSS_T"]
    r = stack.arm(int(loss * S) + 1, ground())
    assert r.result == RESULT_DENIED and r.reason == "no offboard setpoint stream"
    assert stack.arm(int(loss * S), ground()).accepted


def test_force_arm_in_the_air_counts_as_airborne_and_arming_twice_is_accepted(stack):
    assert stack.arm(0, air(), force=True).accepted
    assert texts(stack) == ["Armed (forced) in AUTO.LOITER"]
    assert stack.arm(1, ground()).result == RESULT_ACCEPTED and texts(stack) == []
    # airborne since arming: landed for COM_DISARM_LAND (2 s) disarms, not the 10 s preflight rule
    stack.update(S, ground())
    assert stack.update(3 * S - 1, ground()).armed
    assert not stack.update(3 * S, ground()).armed
    assert "Disarmed (landed)" in texts(stack)


# --------------------------------------------------------------------------- auto-disarm
def test_preflight_disarm_after_exactly_com_disarm_prflt(stack):
    """Armed on the ground without taking off: disarmed after COM_DISARM_PRFLT = 10 s."""
    assert stack.arm(5 * S, ground()).accepted
    assert stack.update(5 * S, ground()).idle
    assert stack.update(15 * S - 1, ground()).armed
    out = stack.update(15 * S, ground())
    assert not out.armed and not stack.armed
    assert "Disarmed (no takeoff)" in texts(stack)


def test_preflight_disarm_waits_while_taking_off(stack):
    assert stack.takeoff(0, ground(), None).accepted
    assert stack.arm(0, ground()).accepted
    stack.update(0, ground())
    assert stack.update(30 * S, ground()).armed                  # AUTO.TAKEOFF: no preflight disarm


@pytest.mark.parametrize("name", ["COM_DISARM_LAND", "COM_DISARM_PRFLT"])
def test_auto_disarm_off_when_zero(stack, name):
    assert stack.params.set(name, 0.0).ok
    airborne = name == "COM_DISARM_LAND"
    stack.arm(0, air() if airborne else ground(), force=airborne)
    stack.update(0, air() if airborne else ground())
    stack.update(S, ground())
    assert stack.update(100 * S, ground()).armed


def test_landing_resets_the_landed_timer_when_airborne_again(stack):
    stack.arm(0, air(), force=True)
    stack.update(0, ground())                       # touched down
    stack.update(int(1.5 * S), air())               # and up again
    stack.update(2 * S, ground())
    assert stack.update(int(3.9 * S), ground()).armed     # 1.9 s since the second touchdown
    assert not stack.update(4 * S, ground()).armed


# --------------------------------------------------------------------------- offboard loss
def _offboard_flying(stack):
    stack.offboard_setpoint(0, pos_target())
    assert stack.set_mode(0, ground(), FlightMode.OFFBOARD).accepted
    assert stack.arm(0, ground()).accepted
    stack.update(0, air())
    texts(stack)


def test_offboard_loss_hold_time_counts_from_the_loss(stack):
    """Loss seen at t_fail = 1 s + 1 us (COM_OF_LOSS_T), land at t_fail + COM_FAIL_ACT_T (5 s)."""
    _offboard_flying(stack)
    t_fail = S + 1
    stack.update(t_fail, air())
    assert stack.failsafe == "offboard" and stack.mode is FlightMode.LOITER
    stack.update(t_fail + 5 * S - 1, air())
    assert stack.mode is FlightMode.LOITER and stack.failsafe == "offboard"
    stack.update(t_fail + 5 * S, air())
    assert stack.mode is FlightMode.LAND and stack.failsafe is None
    assert stack.system_status == mavlink.MAV_STATE_ACTIVE


def test_offboard_loss_return_on_the_ground_keeps_holding(stack):
    """COM_OBL_ACT = 2 (return) needs a flying vehicle: landed, it keeps holding."""
    assert stack.params.set("COM_OBL_ACT", 2).ok
    _offboard_flying(stack)
    stack.update(S + 1, air())
    stack.update(S + 1 + 5 * S, ground())
    assert stack.mode is FlightMode.LOITER and stack.failsafe == "offboard-hold"
    assert stack.system_status == mavlink.MAV_STATE_CRITICAL


def test_offboard_loss_hold_action_stays_a_failsafe(stack):
    assert stack.params.set("COM_OBL_ACT", 1).ok
    _offboard_flying(stack)
    stack.update(S + 1, air())
    assert "Failsafe: offboard setpoints lost, holding" in texts(stack)
    stack.update(S + 1 + 5 * S, air())
    assert stack.failsafe == "offboard-hold" and stack.mode is FlightMode.LOITER
    assert texts(stack) == []
    stack.update(S + 1 + 50 * S, air())
    assert stack.mode is FlightMode.LOITER


def test_offboard_return_action_announces_and_returns(stack):
    assert stack.params.set("COM_OBL_ACT", 2).ok
    _offboard_flying(stack)
    stack.update(S + 1, air())
    stack.update(S + 1 + 5 * S, air(HOME[0] + 4.0))
    assert stack.mode is FlightMode.RTL and stack.failsafe is None
    assert "Failsafe: returning" in texts(stack)


def test_offboard_loss_timeout_follows_a_parameter_change(stack):
    _offboard_flying(stack)
    assert stack.params.set("COM_OF_LOSS_T", 3.0).ok
    stack.update(3 * S, air())
    assert stack.mode is FlightMode.OFFBOARD
    stack.update(3 * S + 1, air())
    assert stack.mode is FlightMode.LOITER


def test_a_fresh_stream_keeps_offboard(stack):
    _offboard_flying(stack)
    for k in range(1, 40):
        stack.offboard_setpoint(k * S // 4, pos_target())
        stack.update(k * S // 4, air())
    assert stack.mode is FlightMode.OFFBOARD and stack.failsafe is None
    assert stack.system_status == mavlink.MAV_STATE_ACTIVE


def test_a_failsafe_ends_with_a_land_takeoff_or_disarm_command(stack):
    for end in ("land", "takeoff", "disarm", "same-mode"):
        s = FlightStack(Parameters(), home_enu_m=HOME)
        _offboard_flying(s)
        s.update(S + 1, air())
        assert s.failsafe == "offboard"
        if end == "land":
            assert s.land(S + 2, air()).accepted and s.mode is FlightMode.LAND
        elif end == "takeoff":
            assert s.takeoff(S + 2, air(), None).accepted and s.mode is FlightMode.TAKEOFF
        elif end == "disarm":
            assert s.disarm(S + 2, air(), force=True).accepted and not s.armed
        else:   # asking for the mode it is already in (AUTO.LOITER) ends the failsafe too
            assert s.set_mode(S + 2, air(), FlightMode.LOITER).accepted
        assert s.failsafe is None
        assert s.system_status != mavlink.MAV_STATE_CRITICAL


# --------------------------------------------------------------------------- actuator stream
def test_actuator_stream_freshness_at_com_hil_tmo(stack):
    """Fresh while now - t_cmd <= COM_HIL_TMO (0.2 s)."""
    stack.arm(0, ground(), force=True)
    cmd = (0.6, 0.6, 0.6, 0.6)
    stack.actuator_controls(S, cmd)
    assert stack.actuators_fresh(S + S // 5) and not stack.actuators_fresh(S + S // 5 + 1)
    assert stack.update(S + S // 5, air()).motor_override == cmd
    assert stack.override_active
    assert stack.update(S + S // 5 + 1, air()).motor_override is None
    assert not stack.override_active


def test_no_actuator_stream_is_not_fresh_and_disarm_drops_the_override(stack):
    assert not stack.actuators_fresh(0)
    stack.arm(0, ground(), force=True)
    stack.actuator_controls(0, [0.5, 0.5, 0.5, 0.5])             # a list is recorded as a tuple
    assert stack.update(0, air()).motor_override == (0.5, 0.5, 0.5, 0.5)
    assert stack.disarm(1, ground()).accepted
    assert not stack.override_active and stack.system_status == mavlink.MAV_STATE_STANDBY


# --------------------------------------------------------------------------- disarm and crash
def test_disarm_in_the_air_needs_force_unless_crashed(stack):
    stack.arm(0, air(), force=True)
    r = stack.disarm(0, air())
    assert r.result == RESULT_DENIED and r.reason == "not landed" and stack.armed
    assert "Disarming denied: not landed" in texts(stack)
    assert stack.disarm(0, ground()).accepted and not stack.armed
    assert texts(stack) == ["Disarmed"]
    assert stack.disarm(0, air()).accepted                      # already disarmed


def test_disarm_messages_say_why(stack):
    stack.arm(0, ground(), force=True)
    stack.disarm(0, ground(), why="landed")
    assert texts(stack)[-1] == "Disarmed (landed)"
    stack.arm(0, ground(), force=True)
    stack.disarm(0, air(), force=True)
    assert texts(stack)[-1] == "Disarmed (forced)"
    stack.arm(0, ground(), force=True)
    stack.disarm(0, ground())
    assert texts(stack)[-1] == "Disarmed"


def test_crash_cuts_the_motors_denies_commands_and_disarms_at_rest(stack):
    stack.arm(0, air(), force=True)
    stack.actuator_controls(0, (0.5, 0.5, 0.5, 0.5))
    stack.update(0, air())
    assert stack.override_active
    texts(stack)
    event = _crash_event()
    stack.crash(S, event)
    assert stack.crashed and stack.system_status == mavlink.MAV_STATE_EMERGENCY
    assert not stack.override_active and stack.failsafe is None
    assert texts(stack) == [event.text]
    stack.crash(S, event)                                       # once
    assert texts(stack) == []
    out = stack.update(S + 1, air())
    assert out.motor_override is None and out.setpoint is None and stack.armed   # falling, motors cut
    assert stack.disarm(S + 2, air()).accepted                  # a disarm is accepted at any time
    for r in (stack.arm(S + 3, ground(), force=True), stack.land(S + 3, ground()),
              stack.takeoff(S + 3, ground(), None), stack.set_mode(S + 3, ground(), FlightMode.POSCTL)):
        assert r.result == RESULT_DENIED and r.reason == "crashed"


def test_a_crashed_vehicle_is_disarmed_once_at_rest(stack):
    stack.arm(0, air(), force=True)
    stack.update(0, air())
    stack.crash(S, _crash_event())
    texts(stack)
    assert stack.update(2 * S, air()).armed is False and stack.armed        # in the air: still armed
    stack.update(3 * S, ground())
    assert not stack.armed and texts(stack) == ["Disarmed (crashed)"]


def _crash_event():
    return CrashEvent(S, "cylinder", 0, (1.0, 2.0, 0.5), (1.0, 0.0, 0.0))


def test_offboard_mode_needs_a_stream_and_rtl_a_flying_vehicle(stack):
    r = stack.set_mode(0, ground(), FlightMode.OFFBOARD)
    assert r.result == RESULT_TEMPORARILY_REJECTED
    r = stack.set_mode(0, ground(), FlightMode.RTL)
    assert r.result == RESULT_DENIED                            # disarmed
    stack.arm(0, ground())
    assert stack.set_mode(0, ground(), FlightMode.RTL).result == RESULT_DENIED   # landed
    assert stack.return_to_launch(0, air()).accepted


def test_a_plain_hold_is_no_failsafe_and_never_lands_by_itself(stack):
    """AUTO.LOITER entered by the user (no offboard loss): holds indefinitely."""
    stack.arm(0, air(), force=True)
    for k in range(1, 13):
        stack.update(k * 5 * S, air())
    assert stack.mode is FlightMode.LOITER and stack.failsafe is None
    assert "Failsafe: landing" not in texts(stack)


def test_a_crash_ends_an_active_failsafe(stack):
    _offboard_flying(stack)
    stack.update(S + 1, air())
    assert stack.failsafe == "offboard"
    stack.crash(S + 2, _crash_event())
    assert stack.failsafe is None and stack.system_status == mavlink.MAV_STATE_EMERGENCY


def test_the_preflight_timer_starts_at_arming(stack):
    """Armed at 5 s, first tick at 10 s: still disarmed at 5 + 10 s (COM_DISARM_PRFLT), not 20 s."""
    assert stack.arm(5 * S, ground()).accepted
    assert stack.update(10 * S, ground()).armed
    assert not stack.update(15 * S, ground()).armed


def test_re_arming_restarts_the_preflight_timer(stack):
    assert stack.arm(0, ground()).accepted
    stack.update(0, ground())
    assert not stack.update(10 * S, ground()).armed          # preflight auto-disarm
    assert stack.arm(20 * S, ground()).accepted
    assert stack.update(20 * S, ground()).armed               # a fresh 10 s
    assert stack.update(30 * S - 1, ground()).armed
    assert not stack.update(30 * S, ground()).armed


def test_landed_state_follows_the_arming_state_before_the_first_tick(stack):
    assert stack.landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND
    assert stack.arm(0, air(), force=True).accepted
    assert stack.landed_state == mavlink.MAV_LANDED_STATE_IN_AIR


def test_exactly_30_degrees_of_tilt_may_arm(stack):
    """ARM_MAX_TILT_RAD = 30 deg is the largest tilt that arms (refused only above it)."""
    assert stack.arm(0, ground(tilt_deg=30.0)).accepted


def test_disarmed_a_fresh_actuator_stream_is_no_override(stack):
    stack.actuator_controls(0, (0.9, 0.9, 0.9, 0.9))
    out = stack.update(0, ground())
    assert not stack.override_active and not out.armed and out.motor_override is None


@pytest.mark.parametrize("airborne", [True, False])
def test_the_auto_disarm_tick_outputs_nothing(stack, airborne):
    """The tick that auto-disarms (after landing, or without a take-off) drives nothing: not
    armed, no override, no idle, no setpoint, no controller reset."""
    stack.arm(0, air() if airborne else ground(), force=airborne)
    stack.update(0, air() if airborne else ground())
    stack.update(S, ground())
    t = S + 2 * S if airborne else 10 * S
    out = stack.update(t, ground())
    assert (out.armed, out.motor_override, out.idle, out.setpoint, out.reset_controller) == \
        (False, None, False, None, False)


@pytest.mark.parametrize("name", ["COM_DISARM_LAND", "COM_DISARM_PRFLT"])
def test_auto_disarm_times_under_a_second_work(stack, name):
    """Any time > 0 enables the auto-disarm: 0.5 s disarms 0.5 s after touchdown / arming."""
    assert stack.params.set(name, 0.5).ok
    airborne = name == "COM_DISARM_LAND"
    stack.arm(0, air() if airborne else ground(), force=airborne)
    stack.update(0, air() if airborne else ground())
    t0 = S if airborne else 0                      # touchdown, or arming on the ground
    stack.update(t0, ground())
    assert stack.update(t0 + S // 2 - 1, ground()).armed
    assert not stack.update(t0 + S // 2, ground()).armed


@pytest.mark.parametrize("action,text", [(0, "Failsafe: landing"), (2, "Failsafe: returning")])
def test_failsafe_mode_changes_are_announced_once_by_the_failsafe_text(stack, action, text):
    """The failsafe's own STATUSTEXT names each step; no separate "Mode ..." line."""
    assert stack.params.set("COM_OBL_ACT", action).ok
    _offboard_flying(stack)
    stack.update(S + 1, air())
    assert texts(stack) == ["Failsafe: offboard setpoints lost, holding"]
    stack.update(S + 1 + 5 * S, air(HOME[0] + 4.0))
    assert texts(stack) == [text]


def test_each_new_actuator_command_is_output_and_a_repeated_one_too(stack):
    stack.arm(0, air(), force=True)
    c1, c2 = (0.5, 0.5, 0.5, 0.5), (0.6, 0.4, 0.6, 0.4)
    stack.actuator_controls(0, c1)
    out = stack.update(0, air())
    assert (out.armed, out.motor_override, out.idle, out.reset_controller) == (True, c1, False, False)
    assert out.setpoint is not None                      # the onboard setpoint, kept for a hand-back
    again = stack.update(1000, air())
    assert again is not None and again.motor_override == c1 and again.armed
    stack.actuator_controls(2000, c2)
    out = stack.update(2000, air())
    assert out.motor_override == c2 and out.armed and not out.idle and not out.reset_controller


def test_under_override_the_output_carries_the_current_modes_setpoint(stack):
    """The override's output keeps the onboard setpoint for the hand-back: after LAND it is
    the landing descent, not the old hold."""
    stack.arm(0, air(), force=True)
    cmd = (0.5, 0.5, 0.5, 0.5)
    stack.actuator_controls(0, cmd)
    stack.update(0, air())
    assert stack.land(1000, air()).accepted
    stack.actuator_controls(1000, cmd)
    out = stack.update(1000, air())
    assert out.motor_override == cmd
    assert out.setpoint.vel_enu_m_s[2] == pytest.approx(-stack.params["MPC_LAND_SPEED"])


def test_return_lands_in_the_tick_the_carrot_reaches_home_exactly(stack):
    """10 m out, 2 s at 5 m/s: the step equals the distance; the vehicle within 0.5 m lands."""
    z = HOME[2] + Parameters()["RTL_RETURN_ALT"]
    _returning(stack, HOME[0] + 10.0, HOME[1], z)
    stack.update(S // 10 + 2 * S, air(HOME[0] + 0.1, HOME[1], z))
    assert stack.mode is FlightMode.LAND
