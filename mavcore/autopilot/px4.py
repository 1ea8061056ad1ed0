"""PX4 (v1.14) personality.

Modes: ``custom_mode = main_mode << 16 | sub_mode << 24`` (PX4
``src/modules/commander/px4_custom_mode.h``); the names are the ones PX4's
own tools print ("AUTO.LOITER" is QGroundControl's Hold). Parameters are
PX4's names in PX4's units (SI): https://docs.px4.io/main/en/advanced_config/parameter_reference.html
"""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

from .base import MODE_FLAG_CUSTOM_MODE_ENABLED, Autopilot, ModeDef, OffboardLoss, ParamCheck, ParamSpec
from .sim_params import SIM_PARAM_SPECS

MAIN_MODE_MANUAL = 1
MAIN_MODE_ALTCTL = 2
MAIN_MODE_POSCTL = 3
MAIN_MODE_AUTO = 4
MAIN_MODE_ACRO = 5
MAIN_MODE_OFFBOARD = 6
MAIN_MODE_STABILIZED = 7
MAIN_MODE_RATTITUDE = 8
SUB_MODE_AUTO_READY = 1
SUB_MODE_AUTO_TAKEOFF = 2
SUB_MODE_AUTO_LOITER = 3
SUB_MODE_AUTO_MISSION = 4
SUB_MODE_AUTO_RTL = 5
SUB_MODE_AUTO_LAND = 6

#: PX4 main modes (custom_mode >> 16 & 0xFF), for readable reports.
MAIN_MODES = {1: "MANUAL", 2: "ALTCTL", 3: "POSCTL", 4: "AUTO", 5: "ACRO", 6: "OFFBOARD",
              7: "STABILIZED", 8: "RATTITUDE"}
#: PX4 AUTO sub modes (custom_mode >> 24).
AUTO_SUB_MODES = {1: "READY", 2: "TAKEOFF", 3: "LOITER", 4: "MISSION", 5: "RTL", 6: "LAND",
                  8: "FOLLOW_TARGET", 9: "PRECLAND"}


def custom_mode(main_mode: int, sub_mode: int = 0) -> int:
    """PX4 ``custom_mode`` word of a main/sub mode pair."""
    return (int(main_mode) & 0xFF) << 16 | (int(sub_mode) & 0xFF) << 24


def modes_from_custom(custom: int) -> tuple[int, int]:
    """(main_mode, sub_mode) of a PX4 ``custom_mode`` word."""
    c = int(custom)
    return (c >> 16) & 0xFF, (c >> 24) & 0xFF


def mode_name(custom: int) -> str:
    """'OFFBOARD', 'AUTO.LAND', ... from a PX4 HEARTBEAT custom_mode."""
    main, sub = modes_from_custom(custom)
    name = MAIN_MODES.get(main, f"MODE{main}")
    if main == MAIN_MODE_AUTO:
        name += "." + AUTO_SUB_MODES.get(sub, str(sub))
    return name


_BEHAVIOUR = {"MANUAL": "MANUAL", "POSCTL": "POSCTL", "OFFBOARD": "OFFBOARD", "AUTO.TAKEOFF": "TAKEOFF",
              "AUTO.LOITER": "LOITER", "AUTO.MISSION": "MISSION", "AUTO.RTL": "RTL", "AUTO.LAND": "LAND"}

_R, _I = mavlink.MAV_PARAM_TYPE_REAL32, mavlink.MAV_PARAM_TYPE_INT32


class PX4(Autopilot):
    key = "px4"
    mav_autopilot = mavlink.MAV_AUTOPILOT_PX4
    mav_type = mavlink.MAV_TYPE_QUADROTOR
    #: v1.14.0 release, as PX4 encodes it (major, minor, patch, type 0xFF).
    flight_sw_version = (1 << 24) | (14 << 16) | (0 << 8) | 0xFF
    modes = tuple(
        [ModeDef(n, custom_mode(m), _BEHAVIOUR.get(n)) for m, n in MAIN_MODES.items() if m != MAIN_MODE_AUTO]
        + [ModeDef("AUTO." + n, custom_mode(MAIN_MODE_AUTO, s), _BEHAVIOUR.get("AUTO." + n))
           for s, n in AUTO_SUB_MODES.items()])
    boot_mode = "AUTO.LOITER"
    offboard_mode = "OFFBOARD"
    attitude_mode = "OFFBOARD"
    after_takeoff = "AUTO.LOITER"
    offboard_needs_stream = True
    takeoff_by_command = False
    takeoff_alt_relative = False
    param_bytewise = True
    imu_message = "HIGHRES_IMU"
    #: docs/flying-a-real-vehicle.md "Parameters to set" (PX4).
    param_checks = (
        ParamCheck("COM_OF_LOSS_T", "offboard loss timeout (s)", min=0.5, max=1.0),
        ParamCheck("COM_OBL_ACT", "offboard loss action: land or return", allowed=(0, 2)),
    )
    param_specs = (
        ParamSpec("COM_OF_LOSS_T", _R, 1.0, 0.0, 60.0, "offboard setpoint loss timeout (s)"),
        ParamSpec("COM_OBL_ACT", _I, 0, 0, 2, "offboard loss action after the hold: 0 land, 1 hold, 2 return"),
        ParamSpec("COM_FAIL_ACT_T", _R, 5.0, 0.0, 60.0, "hold time before a failsafe action (s)"),
        ParamSpec("COM_HIL_TMO", _R, 0.2, 0.01, 10.0, "HIL_ACTUATOR_CONTROLS freshness timeout (s)"),
        ParamSpec("COM_DISARM_LAND", _R, 2.0, -1.0, 20.0, "auto-disarm after landing (s, <= 0 off)"),
        ParamSpec("COM_DISARM_PRFLT", _R, 10.0, -1.0, 60.0, "auto-disarm without takeoff (s, <= 0 off)"),
        ParamSpec("MIS_TAKEOFF_ALT", _R, 2.5, 0.1, 100.0, "default takeoff height above home (m)"),
        ParamSpec("MPC_TKO_SPEED", _R, 1.5, 0.1, 5.0, "takeoff climb speed (m/s)"),
        ParamSpec("MPC_LAND_SPEED", _R, 0.7, 0.1, 3.0, "landing descent speed (m/s)"),
        ParamSpec("MPC_XY_CRUISE", _R, 5.0, 0.1, 20.0, "horizontal speed of the return leg (m/s)"),
        ParamSpec("MPC_XY_VEL_MAX", _R, 5.0, 0.1, 20.0, "onboard controller horizontal speed limit (m/s)"),
        ParamSpec("MPC_Z_VEL_MAX_UP", _R, 3.0, 0.1, 8.0, "onboard controller climb speed limit (m/s)"),
        ParamSpec("MPC_Z_VEL_MAX_DN", _R, 1.5, 0.1, 4.0, "onboard controller descent speed limit (m/s)"),
        ParamSpec("MPC_TILTMAX_AIR", _R, 35.0, 10.0, 85.0, "onboard controller tilt limit (deg)"),
        # collision prevention, mission acceptance, geofence action (the mission-flying modules)
        ParamSpec("MPC_ACC_HOR", _R, 3.0, 0.5, 15.0, "horizontal braking of collision prevention (m/s^2)"),
        ParamSpec("CP_DIST", _R, -1.0, -1.0, 15.0, "collision prevention: distance kept from "
                  "OBSTACLE_DISTANCE's obstacles (m; < 0 off, PX4's default)"),
        ParamSpec("CP_DELAY", _R, 0.4, 0.0, 1.0, "collision prevention: sensing and control delay (s)"),
        ParamSpec("CP_GO_NO_DATA", _I, 0, 0, 1, "collision prevention: 1 allows moving where no sensor data is"),
        ParamSpec("NAV_MC_ALT_RAD", _R, 0.8, 0.05, 10.0, "takeoff and mission altitude acceptance (m)"),
        ParamSpec("NAV_ACC_RAD", _R, 2.0, 0.05, 200.0,
                  "mission way-point acceptance radius where the item's param2 is 0 (m; PX4's default is 10)"),
        ParamSpec("GF_ACTION", _I, 2, 0, 5,
                  "geofence breach action: 0 none, 1 warning, 2 hold, 3 return, 4 (termination) and 5 land"),
        ParamSpec("RTL_RETURN_ALT", _R, 5.0, 0.0, 150.0, "return altitude above home (m; PX4's default is 60)"),
        # the rate-setpoint path (--control rates): hover thrust and the motors' thrust curve
        ParamSpec("MPC_THR_HOVER", _R, 0.5, 0.05, 1.0,
                  "hover thrust, normalised (the vehicle's m g / (4 f_max) at start; read by a companion that "
                  "sends attitude-rate setpoints)"),
        ParamSpec("THR_MDL_FAC", _R, 0.0, 0.0, 1.0,
                  "motor thrust curve factor k of the rate-setpoint path: thrust = (1 - k) u + k u^2 (0: the "
                  "simulated motors are linear)"),
    ) + SIM_PARAM_SPECS
    param_aliases = ()
    #: Offboard loss: Hold (AUTO.LOITER) after COM_OF_LOSS_T, then after
    #: COM_FAIL_ACT_T the action COM_OBL_ACT (docs.px4.io "Offboard Loss Failsafe").
    offboard_loss = OffboardLoss("COM_OF_LOSS_T", "LOITER", "COM_FAIL_ACT_T", "COM_OBL_ACT")

    def action_of(self, value: float) -> str:
        """COM_OBL_ACT -> 'land' | 'hold' | 'rtl' (0 land, 1 hold, 2 return)."""
        return {0: "land", 2: "rtl"}.get(int(value), "hold")

    def decode_mode(self, custom: int):
        main, sub = modes_from_custom(custom)
        if main != MAIN_MODE_AUTO:
            sub = 0                       # PX4 ignores the sub mode outside AUTO
        return super().decode_mode(custom_mode(main, sub))

    def mode_name(self, custom: int) -> str:
        return mode_name(custom)

    def custom_mode_from_params(self, param2: float, param3: float) -> int:
        return custom_mode(int(param2), int(param3))

    def set_mode_params(self, name: str) -> tuple[float, float, float]:
        main, sub = modes_from_custom(self.custom_mode(name))
        return float(MODE_FLAG_CUSTOM_MODE_ENABLED), float(main), float(sub)


PX4_AUTOPILOT = PX4()
