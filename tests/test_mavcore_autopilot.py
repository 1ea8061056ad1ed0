"""The autopilot personalities (``mavcore.autopilot``) and the SITL flight
stack's ArduCopter rules.

Mode numbers are checked against pymavlink's own tables (``mavutil.mode_mapping_acm``,
``mavutil.px4_map``: what MAVProxy and pymavlink-based tools use) and against
hand-worked PX4 words; the ArduCopter rules against their thresholds
(GUID_TIMEOUT, FS_GCS_TIMEOUT), each probed just inside and just outside.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pymavlink import mavutil

from mavcore import autopilot as autopilots
from mavcore.autopilot import ARDUCOPTER, PX4_AUTOPILOT
from mavcore.codec import PositionTarget
from sitl.flightstack import (
    RESULT_ACCEPTED, RESULT_FAILED, RESULT_TEMPORARILY_REJECTED, FlightMode, FlightStack, NavState, Parameters,
)

S = 1_000_000
HOME = (3.0, -2.0, 1.0)
NAN3 = np.full(3, np.nan)


def ground(z=HOME[2]):
    return NavState(np.array([HOME[0], HOME[1], z]), np.zeros(3), 0.0, 0.0, True)


def air(z=HOME[2] + 2.0):
    return NavState(np.array([HOME[0], HOME[1], z]), np.zeros(3), 0.0, 0.0, False)


def pos_target(p):
    return PositionTarget(np.array(p, float), NAN3.copy(), NAN3.copy(), None, None, 0xDF8)


def ap_stack(**params):
    p = Parameters.for_autopilot(ARDUCOPTER)
    for k, v in params.items():
        assert p.set(k, v).ok
    return FlightStack(p, HOME, ARDUCOPTER)


# --------------------------------------------------------------------------- tables
def test_arducopter_mode_numbers_are_pymavlinks():
    for m in ARDUCOPTER.modes:
        assert mavutil.mode_mapping_acm[m.custom_mode] == m.name
    assert ARDUCOPTER.custom_mode("GUIDED") == 4 and ARDUCOPTER.custom_mode("GUIDED_NOGPS") == 20
    names = {m.name for m in ARDUCOPTER.modes}
    assert {"GUIDED", "AUTO", "LAND", "RTL", "LOITER", "STABILIZE", "GUIDED_NOGPS"} <= names


def test_px4_mode_words_by_hand_and_pymavlink():
    # main << 16 | sub << 24: OFFBOARD 6 -> 393216; AUTO.LOITER 4/3 -> 262144 + 50331648
    assert PX4_AUTOPILOT.custom_mode("OFFBOARD") == 393216
    assert PX4_AUTOPILOT.custom_mode("AUTO.LOITER") == 50593792
    for name in ("MANUAL", "POSCTL", "OFFBOARD", "TAKEOFF", "LOITER", "MISSION", "RTL", "LAND"):
        _, main, sub = mavutil.px4_map[name]
        ours = PX4_AUTOPILOT.decode_mode(main << 16 | sub << 24)
        assert ours.name.split(".")[-1] == name and ours.behaviour is not None
    # DO_SET_MODE parameters: (custom mode flag, main, sub) for PX4, (flag, number, 0) for ArduCopter
    assert PX4_AUTOPILOT.set_mode_params("AUTO.LAND") == (1.0, 4.0, 6.0)
    assert ARDUCOPTER.set_mode_params("LAND") == (1.0, 9.0, 0.0)


def test_registry():
    assert autopilots.get("ardupilot") is ARDUCOPTER and autopilots.get("px4") is PX4_AUTOPILOT
    with pytest.raises(ValueError, match="known: px4, ardupilot"):
        autopilots.get("betaflight")
    assert autopilots.from_heartbeat(mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA) is ARDUCOPTER
    assert autopilots.from_heartbeat(mavutil.mavlink.MAV_AUTOPILOT_PX4) is PX4_AUTOPILOT
    assert autopilots.from_heartbeat(mavutil.mavlink.MAV_AUTOPILOT_GENERIC) is None


def test_arducopter_parameters_in_its_units():
    """ArduPilot's names and units on the wire, SI inside: LAND_SPEED 50 cm/s is 0.5 m/s,
    ANGLE_MAX 3000 cdeg is 30 deg; a set through either name lands on the same value."""
    p = Parameters.for_autopilot(ARDUCOPTER)
    assert "LAND_SPEED" in p and "MPC_LAND_SPEED" not in p and "COM_OF_LOSS_T" not in p
    assert p["MPC_LAND_SPEED"] == pytest.approx(0.5) and p["MPC_TILTMAX_AIR"] == pytest.approx(30.0)
    assert p["COM_OF_LOSS_T"] == 3.0 and p["COM_DISARM_LAND"] == p["COM_DISARM_PRFLT"] == 10
    assert p.set("LAND_SPEED", 150).ok and p["MPC_LAND_SPEED"] == pytest.approx(1.5)
    assert p.set("MPC_TILTMAX_AIR", 35.0).ok and p["ANGLE_MAX"] == 3500
    assert not p.set("LAND_SPEED", 10).ok            # ArduPilot's range 30..200 cm/s
    assert len({s.name for s in p.specs}) == len(p.specs)


# --------------------------------------------------------------------------- ArduCopter rules
def test_arducopter_boots_in_stabilize_and_guided_needs_no_stream():
    s = ap_stack()
    assert s.custom_mode == 0 and s.label(s.mode) == "STABILIZE"
    assert s.set_mode(0, ground(), FlightMode.OFFBOARD).result == RESULT_ACCEPTED
    assert s.custom_mode == 4
    px4 = FlightStack(Parameters(), HOME)
    assert px4.set_mode(0, ground(), FlightMode.OFFBOARD).result == RESULT_TEMPORARILY_REJECTED


def test_arducopter_takes_off_only_by_command_armed_in_guided():
    s = ap_stack()
    st = ground()
    assert s.takeoff(0, st, HOME[2] + 2.0).result == RESULT_FAILED          # disarmed
    s.set_mode(0, st, FlightMode.OFFBOARD)
    assert s.arm(0, st).accepted
    s.offboard_setpoint(0, pos_target((HOME[0], HOME[1], HOME[2] + 5.0)))
    out = s.update(S // 10, st)
    assert out.idle and out.setpoint is None          # setpoints do not lift it on the ground
    assert s.takeoff(S // 10, st, HOME[2] + 2.0).accepted
    assert s.custom_mode == 4                          # the climb is reported as GUIDED
    out = s.update(S // 10 + S, st)
    v = s.params["MPC_TKO_SPEED"]                       # WPNAV_SPEED_UP 250 cm/s
    assert v == pytest.approx(2.5)
    assert out.setpoint.pos_enu_m[2] == pytest.approx(HOME[2] + min(v * 1.0, 2.0))


def _guided_flying(s, t_us):
    """Armed in GUIDED, in the air, a setpoint received at ``t_us``."""
    s.set_mode(0, ground(), FlightMode.OFFBOARD)
    assert s.arm(0, ground()).accepted
    assert s.takeoff(0, ground(), HOME[2] + 2.0).accepted
    s.update(0, ground())
    s.update(S, air())            # climbed
    s.mode = FlightMode.OFFBOARD  # take-off done (its own completion is timed by the climb)
    s.offboard_setpoint(t_us, pos_target((HOME[0] + 1.0, HOME[1], HOME[2] + 2.0)))
    s.update(t_us, air())


def test_guided_timeout_holds_in_guided():
    s = ap_stack()
    t0 = 2 * S
    _guided_flying(s, t0)
    timeout = s.params["COM_OF_LOSS_T"]        # GUID_TIMEOUT, 3 s
    out = s.update(t0 + int(timeout * S) - 1000, air())
    assert s.failsafe is None and out.setpoint.pos_enu_m[0] == pytest.approx(HOME[0] + 1.0)
    out = s.update(t0 + int(timeout * S) + 1000, air())
    assert s.failsafe == "offboard" and s.mode is FlightMode.OFFBOARD and s.custom_mode == 4
    assert out.setpoint.pos_enu_m[0] == pytest.approx(HOME[0])      # stopped where it is
    s.offboard_setpoint(t0 + 4 * S, pos_target((HOME[0] + 2.0, HOME[1], HOME[2] + 2.0)))
    out = s.update(t0 + 4 * S, air())
    assert s.failsafe is None and out.setpoint.pos_enu_m[0] == pytest.approx(HOME[0] + 2.0)


@pytest.mark.parametrize("enable, mode", [(5, FlightMode.LAND), (1, FlightMode.RTL), (0, FlightMode.OFFBOARD)])
def test_gcs_failsafe_acts_fs_gcs_timeout_after_the_last_setpoint(enable, mode):
    s = ap_stack(FS_GCS_ENABLE=enable)
    t0 = 2 * S
    _guided_flying(s, t0)
    t_fs = t0 + int(s.params["FS_GCS_TIMEOUT"] * S)      # 5 s after the last setpoint
    s.update(t0 + 3 * S + 1000, air())                   # guided timeout: holding
    s.update(t_fs - 1000, air())
    assert s.mode is FlightMode.OFFBOARD
    s.update(t_fs + 1000, air())
    assert s.mode is mode


# --------------------------------------------------------------------------- RAW_IMU
def test_raw_imu_units_by_hand_and_back():
    """ArduPilot's RAW_IMU: milli-g (1 g = 9.80665 m/s^2), mrad/s, milligauss, body FRD
    (FLU y, z negated), int16 saturating; the companion reads it back within a count."""
    from types import SimpleNamespace

    from companion.flight.inbox import SiImu as _SiImu
    from mavcore.codec import raw_imu_args

    a = raw_imu_args(123, (0.0, 0.0, 9.80665), (0.1, 0.2, -0.3), (0.2, 0.0, -0.4))
    assert a == (123, 0, 0, -1000, 100, -200, 300, 200, 0, 400, 0, 0)
    assert raw_imu_args(0, (40 * 9.80665, 0.0, 0.0), (0, 0, 0), (0, 0, 0))[1] == 32767
    names = ("time_usec", "xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro", "xmag", "ymag", "zmag")
    back = _SiImu(SimpleNamespace(**dict(zip(names, a[:10]))))
    assert (back.zacc, back.ygyro, back.zmag) == pytest.approx((-9.80665, -0.2, 0.4))


def test_guided_nogps_is_known_and_refused_for_now():
    s = ap_stack()
    assert ARDUCOPTER.mode_name(20) == "GUIDED_NOGPS"
    assert s.mode_of(20) is None and s.mode_of(4) is FlightMode.OFFBOARD and s.mode_of(99) is None
    assert not s.set_mode(0, ground(), s.mode_of(20)).accepted


def test_mavcore_imports_neither_side():
    """The shared core is imported by companion and sitl and imports neither."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "mavcore"
    for path in root.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            assert not any(n.split(".")[0] in ("companion", "sitl") for n in names), (path, names)


def test_bad_sim_autopilot_names_the_key(tmp_path):
    from mavcore.errors import InputError
    from mavcore.mission import load_mission

    src = Path(__file__).resolve().parents[1] / "missions" / "flat-rectangle" / "mission.yaml"
    text = src.read_text().replace("\nsim:\n", "\nsim:\n  autopilot: betaflight\n", 1)
    assert "betaflight" in text
    bad = tmp_path / "m.yaml"
    bad.write_text(text.replace("../", str(src.parent.parent) + "/"))
    with pytest.raises(InputError, match="sim.autopilot"):
        load_mission(bad)


def test_every_internal_parameter_has_an_arducopter_value():
    """The stack reads its parameters by PX4's names: each one must resolve under
    the ArduCopter personality (a listed name, an alias or a fixed value)."""
    p = Parameters.for_autopilot(ARDUCOPTER)
    for spec in PX4_AUTOPILOT.param_specs:
        assert math.isfinite(float(p[spec.name])), spec.name
    assert p["NAV_ACC_RAD"] == pytest.approx(2.0)          # WPNAV_RADIUS 200 cm
