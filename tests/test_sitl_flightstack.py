"""sitl.flightstack: the pure state machine driven by a fake vehicle clock."""

from __future__ import annotations


import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore.codec import PositionTarget
from sitl.flightstack import (
    IDLE_MOTOR_CMD, PARAM_SPECS, RESULT_ACCEPTED, RESULT_DENIED, RESULT_TEMPORARILY_REJECTED,
    FlightMode, FlightStack, NavState, Parameters,
)

S = 1_000_000   # us per second
NAN3 = np.full(3, np.nan)


def ground(x=0.0, y=0.0, z=0.0, yaw=0.0):
    return NavState(np.array([x, y, z]), np.zeros(3), yaw, 0.0, True)


def air(x=0.0, y=0.0, z=2.0, yaw=0.0):
    return NavState(np.array([x, y, z]), np.zeros(3), yaw, 0.0, False)


def pos_target(p=(0.0, 0.0, 2.0)):
    return PositionTarget(np.array(p, float), NAN3.copy(), NAN3.copy(), None, None, 0xDF8)


def texts(stack):
    return [e.text for e in stack.pop_events()]


@pytest.fixture()
def stack():
    return FlightStack(Parameters(), home_enu_m=(0.0, 0.0, 0.0))


def test_boots_disarmed_in_hold(stack):
    assert not stack.armed and stack.mode is FlightMode.LOITER
    assert stack.custom_mode == (4 << 16) | (3 << 24)
    assert stack.system_status == mavlink.MAV_STATE_STANDBY
    out = stack.update(0, ground())
    assert not out.armed and out.setpoint is None and out.motor_override is None


def test_arming_checks(stack):
    assert stack.arm(0, air()).result == RESULT_DENIED                      # not landed
    assert "Arming denied: not landed" in texts(stack)
    tilted = NavState(np.zeros(3), np.zeros(3), 0.0, math.radians(40), True)
    assert stack.arm(0, tilted).result == RESULT_DENIED
    assert stack.arm(0, air(), force=True).result == RESULT_ACCEPTED          # 21196 bypasses
    assert stack.armed and stack.system_status == mavlink.MAV_STATE_ACTIVE
    assert stack.disarm(0, air()).result == RESULT_DENIED                   # in the air
    assert stack.disarm(0, air(), force=True).result == RESULT_ACCEPTED
    assert not stack.armed


def test_armed_on_ground_in_hold_idles_then_preflight_disarm(stack):
    assert stack.arm(0, ground()).accepted
    out = stack.update(0, ground())
    assert out.armed and out.idle
    t = stack.params["COM_DISARM_PRFLT"]
    assert stack.update(int((t - 0.01) * S), ground()).armed
    out = stack.update(int(t * S), ground())
    assert not out.armed and not stack.armed
    assert any("Disarmed" in x for x in texts(stack))


def test_offboard_needs_a_fresh_stream(stack):
    st = ground()
    r = stack.set_mode(0, st, FlightMode.OFFBOARD)
    assert r.result == RESULT_TEMPORARILY_REJECTED and stack.mode is FlightMode.LOITER
    stack.offboard_setpoint(0, pos_target())
    loss = stack.params["COM_OF_LOSS_T"]
    assert stack.set_mode(int(loss * S) + 1, st, FlightMode.OFFBOARD).result == RESULT_TEMPORARILY_REJECTED
    assert stack.set_mode(int(loss * S), st, FlightMode.OFFBOARD).accepted
    assert stack.mode is FlightMode.OFFBOARD and stack.custom_mode == 6 << 16


def test_offboard_loss_holds_then_lands(stack):
    st = ground()
    stack.offboard_setpoint(0, pos_target((1.0, 2.0, 3.0)))
    assert stack.set_mode(0, st, FlightMode.OFFBOARD).accepted
    assert stack.arm(0, st).accepted
    out = stack.update(0, st)
    assert not out.idle and out.setpoint.pos_enu_m == pytest.approx((1.0, 2.0, 3.0))
    texts(stack)
    loss, hold = stack.params["COM_OF_LOSS_T"], stack.params["COM_FAIL_ACT_T"]
    here = air(5.0, 6.0, 2.5)
    stack.update(int(loss * S), here)
    assert stack.mode is FlightMode.OFFBOARD                    # exactly at the timeout: still fresh
    t_fail = int(loss * S) + 1
    out = stack.update(t_fail, here)
    assert stack.mode is FlightMode.LOITER and stack.failsafe == "offboard"
    assert stack.system_status == mavlink.MAV_STATE_CRITICAL
    assert out.setpoint.pos_enu_m == pytest.approx((5.0, 6.0, 2.5))   # holds where it is
    assert "Failsafe: offboard setpoints lost, holding" in texts(stack)
    stack.update(t_fail + int(hold * S) - 1, here)
    assert stack.mode is FlightMode.LOITER
    out = stack.update(t_fail + int(hold * S), here)
    assert stack.mode is FlightMode.LAND
    assert out.setpoint.vel_enu_m_s[2] == pytest.approx(-stack.params["MPC_LAND_SPEED"])
    assert "Failsafe: landing" in texts(stack)


@pytest.mark.parametrize("action, mode", [(1, FlightMode.LOITER), (2, FlightMode.RTL)])
def test_offboard_loss_action_param(stack, action, mode):
    assert stack.params.set("COM_OBL_ACT", action).ok
    assert stack.params.set("COM_FAIL_ACT_T", 0.0).ok
    stack.offboard_setpoint(0, pos_target())
    stack.set_mode(0, ground(), FlightMode.OFFBOARD)
    stack.arm(0, ground())
    stack.update(2 * S, air(3.0, 0.0, 2.0))
    stack.update(2 * S + 1, air(3.0, 0.0, 2.0))
    assert stack.mode is mode


def test_user_mode_change_ends_failsafe(stack):
    stack.offboard_setpoint(0, pos_target())
    stack.set_mode(0, ground(), FlightMode.OFFBOARD)
    stack.arm(0, ground())
    stack.update(2 * S, air())
    assert stack.failsafe == "offboard"
    assert stack.set_mode(2 * S, air(), FlightMode.POSCTL).accepted
    assert stack.failsafe is None
    stack.update(20 * S, air())
    assert stack.mode is FlightMode.POSCTL                      # no land after the hold time


def test_actuator_override_and_loss(stack):
    stack.arm(0, ground(), force=True)
    cmd = (0.5, 0.5, 0.5, 0.5)
    stack.actuator_controls(0, cmd)
    out = stack.update(0, ground())
    assert out.motor_override == cmd and "Actuator override active" in texts(stack)
    tmo = stack.params["COM_HIL_TMO"]
    stack.actuator_controls(int(0.1 * S), None)                 # an all-NaN tick refreshes nothing
    assert stack.update(int(tmo * S), air(1.0, 2.0, 3.0)).motor_override == cmd
    out = stack.update(int(tmo * S) + 1, air(1.0, 2.0, 3.0))
    assert out.motor_override is None and out.reset_controller
    assert out.setpoint.pos_enu_m == pytest.approx((1.0, 2.0, 3.0))    # hold where it is
    assert "Actuator stream lost: onboard controller holds" in texts(stack)
    out = stack.update(int(tmo * S) + 2, air(1.0, 2.0, 3.0))
    assert not out.reset_controller                             # only once


def test_override_timeout_follows_a_parameter_change(stack):
    # the freshness limits are cached per parameter version: a PARAM_SET between
    # frames must take effect at the next frame
    stack.arm(0, ground(), force=True)
    cmd = (0.5, 0.5, 0.5, 0.5)
    stack.actuator_controls(0, cmd)
    assert stack.update(0, ground()).motor_override == cmd
    assert stack.params.set("COM_HIL_TMO", 1.0).ok
    assert stack.update(int(0.9 * S), air()).motor_override == cmd     # fresh under the new 1 s
    assert stack.params.set("COM_HIL_TMO", 0.5).ok
    assert stack.update(int(0.9 * S) + 1, air()).motor_override is None  # stale under 0.5 s


def test_override_needs_armed(stack):
    stack.actuator_controls(0, (1.0, 1.0, 1.0, 1.0))
    out = stack.update(0, ground())
    assert not out.armed and out.motor_override is None


def test_takeoff_ramp_then_hold_at_target(stack):
    home_z = 0.0
    assert stack.takeoff(0, ground(), None).accepted            # disarmed: mode only (PX4)
    assert stack.mode is FlightMode.TAKEOFF
    stack.arm(0, ground())
    v = stack.params["MPC_TKO_SPEED"]
    target = home_z + stack.params["MIS_TAKEOFF_ALT"]
    stack.update(0, ground())
    out = stack.update(1 * S, air(z=1.0))
    assert out.setpoint.pos_enu_m[2] == pytest.approx(v * 1.0)  # the reference climbs at MPC_TKO_SPEED
    assert out.setpoint.vel_enu_m_s[2] == pytest.approx(v)
    assert stack.landed_state == mavlink.MAV_LANDED_STATE_TAKEOFF
    out = stack.update(10 * S, air(z=target - 0.1))
    assert stack.mode is FlightMode.LOITER
    assert out.setpoint.pos_enu_m == pytest.approx((0.0, 0.0, target))    # holds the takeoff point
    assert "Takeoff complete: Mode AUTO.LOITER" in texts(stack)


def test_takeoff_altitude_bounds(stack):
    assert stack.takeoff(0, ground(), 151.0).result == RESULT_DENIED        # > 150 m above home
    assert stack.takeoff(0, ground(), float("inf")).result == RESULT_DENIED
    assert stack.takeoff(0, ground(), 2.0).accepted
    assert stack._anchor.target_z == pytest.approx(2.0)                      # honoured as asked
    # At or below home (param7 = 0 AMSL, or an ArduPilot-style relative value):
    # PX4 takes off to home + MIS_TAKEOFF_ALT with a warning instead of refusing.
    assert stack.takeoff(0, ground(), -1.0).accepted
    assert stack._anchor.target_z == pytest.approx(0.0 + stack.params["MIS_TAKEOFF_ALT"])
    assert any(t.startswith("Using minimum takeoff altitude") for t in texts(stack))


def test_land_idles_then_disarms(stack):
    stack.arm(0, ground(), force=True)
    stack.update(0, air())
    assert stack.land(0, air(1.0, 1.0, 2.0)).accepted
    out = stack.update(S, air(1.0, 1.0, 1.5))
    assert out.setpoint.vel_enu_m_s[2] == pytest.approx(-stack.params["MPC_LAND_SPEED"])
    assert out.setpoint.pos_enu_m[:2] == pytest.approx((1.0, 1.0)) and math.isnan(out.setpoint.pos_enu_m[2])
    assert stack.landed_state == mavlink.MAV_LANDED_STATE_LANDING
    out = stack.update(3 * S, ground(1.0, 1.0))
    assert out.idle and "Landing detected" in texts(stack)
    t = stack.params["COM_DISARM_LAND"]
    assert stack.update(3 * S + int(t * S) - 1, ground(1.0, 1.0)).armed
    assert not stack.update(3 * S + int(t * S), ground(1.0, 1.0)).armed


def test_mission_mode_refused(stack):
    r = stack.set_mode(0, ground(), FlightMode.MISSION)
    assert r.result == RESULT_DENIED and stack.mode is FlightMode.LOITER
    assert stack.set_mode(0, ground(), None).result == RESULT_DENIED


def test_return_climbs_then_flies_home_at_cruise(stack):
    stack.arm(0, ground(), force=True)
    stack.update(0, air(10.0, 0.0, 2.0))
    assert stack.set_mode(0, air(10.0, 0.0, 2.0), FlightMode.RTL).accepted
    rtl_z = stack.params["RTL_RETURN_ALT"]
    out = stack.update(1 * S, air(10.0, 0.0, 2.0))
    assert out.setpoint.pos_enu_m[2] == pytest.approx(min(2.0 + stack.params["MPC_Z_VEL_MAX_UP"], rtl_z))
    stack.update(2 * S, air(10.0, 0.0, rtl_z))
    out = stack.update(3 * S, air(10.0, 0.0, rtl_z))
    cruise = stack.params["MPC_XY_CRUISE"]
    assert out.setpoint.pos_enu_m[0] == pytest.approx(10.0 - cruise)
    assert out.setpoint.vel_enu_m_s[0] == pytest.approx(-cruise)
    stack.update(5 * S, air(0.1, 0.0, rtl_z))
    assert stack.mode is FlightMode.LAND


def test_parameters_typed_and_bounded():
    p = Parameters()
    assert len(p) == len(PARAM_SPECS)
    assert p.set("COM_OF_LOSS_T", 2.5).ok and p["COM_OF_LOSS_T"] == 2.5
    r = p.set("COM_OF_LOSS_T", 1e6)
    assert not r.ok and r.value == 2.5 and "outside" in r.reason
    assert not p.set("COM_OBL_ACT", 1.5).ok
    assert p.set("COM_OBL_ACT", 2.0).ok and p["COM_OBL_ACT"] == 2 and isinstance(p["COM_OBL_ACT"], int)
    assert not p.set("NO_SUCH_PARAM", 1).ok
    assert not p.set("COM_HIL_TMO", float("nan")).ok
    spec, value = p.by_index(p.index("COM_HIL_TMO"))
    assert spec.name == "COM_HIL_TMO" and value == 0.2
    assert all(len(s.name) <= 16 for s in PARAM_SPECS)
    with pytest.raises(ValueError):
        Parameters(initial={"SIM_VEC_VAR": -1.0})


def test_idle_constant_is_below_hover():
    # Idle spin must not lift the paper's vehicle: 4 * cmd * f_max < m g.
    from mavcore.vehicle import VehicleConfig
    v = VehicleConfig()
    assert 4 * IDLE_MOTOR_CMD * v.max_thrust_per_rotor_n < v.mass_kg * 9.81
