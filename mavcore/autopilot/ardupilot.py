"""ArduCopter (4.5) personality.

Modes: ``custom_mode`` is the ArduCopter mode number
(``ArduCopter/mode.h``, ``enum class Number``; the same table as pymavlink's
``mavutil.mode_mapping_acm``), set with MAV_CMD_DO_SET_MODE(1, number) or
SET_MODE. Parameters: https://ardupilot.org/copter/docs/parameters.html
(units as ArduPilot has them: cm, cm/s, centidegrees; the alias table maps
them to the SI values the SITL works in). Integer parameters go on the wire
as a C cast to float (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST), not
byte-wise as PX4 does.

Rules that differ from PX4 (docs/flying-a-real-vehicle.md):
- GUIDED needs no setpoint stream to be entered;
- armed on the ground in GUIDED the motors idle: the take-off is
  MAV_CMD_NAV_TAKEOFF (param7: metres above home), armed, in GUIDED, after
  which the vehicle stays in GUIDED holding the take-off point;
- setpoints older than GUID_TIMEOUT: the vehicle stops and holds in GUIDED;
  FS_GCS_ENABLE (off by default) names the action after FS_GCS_TIMEOUT;
- AUTO (``MissionRules``, docs/mission.md "Missions on each personality"):
  item 0 is home and never flown; way-points are reached within WPNAV_RADIUS
  (param2 is not read by Copter); a mission started armed on the ground
  needs a NAV_TAKEOFF first and waits for the take-off to be released
  (MAV_CMD_MISSION_START, a GUIDED take-off before, or AUTO_OPTIONS bit 1);
  NAV_RETURN_TO_LAUNCH is flown inside AUTO and the vehicle disarms when the
  mission ends on the ground.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

from .base import MODE_FLAG_CUSTOM_MODE_ENABLED, Autopilot, MissionRules, ModeDef, OffboardLoss, ParamAlias, ParamCheck, ParamSpec
from .sim_params import SIM_PARAM_SPECS

#: MAV_AUTOPILOT_ARDUPILOTMEGA
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
#: FIRMWARE_VERSION_TYPE_OFFICIAL
_OFFICIAL = 255

#: ArduCopter mode numbers (ArduCopter/mode.h) and the SITL behaviour of each;
#: None: a mode the SITL refuses (DENIED).
COPTER_MODES = {
    0: ("STABILIZE", "MANUAL"), 1: ("ACRO", None), 2: ("ALT_HOLD", None), 3: ("AUTO", "MISSION"),
    4: ("GUIDED", "OFFBOARD"), 5: ("LOITER", "LOITER"), 6: ("RTL", "RTL"), 7: ("CIRCLE", None),
    9: ("LAND", "LAND"), 16: ("POSHOLD", "POSCTL"), 17: ("BRAKE", None), 20: ("GUIDED_NOGPS", None),
    21: ("SMART_RTL", None),
}

_R, _I = mavlink.MAV_PARAM_TYPE_REAL32, mavlink.MAV_PARAM_TYPE_INT32

#: FS_GCS_ENABLE -> action (ArduCopter's GCS failsafe; no SmartRTL here: its
#: fallback is taken). 0: disabled (hold in GUIDED).
_FS_GCS_ACTION = {1: "rtl", 2: "rtl", 3: "rtl", 4: "land", 5: "land", 6: "rtl", 7: "land"}


class ArduCopter(Autopilot):
    key = "ardupilot"
    mav_autopilot = MAV_AUTOPILOT_ARDUPILOTMEGA
    mav_type = mavlink.MAV_TYPE_QUADROTOR
    flight_sw_version = (4 << 24) | (5 << 16) | (7 << 8) | _OFFICIAL
    modes = tuple(ModeDef(n, c, b) for c, (n, b) in COPTER_MODES.items())
    boot_mode = "STABILIZE"
    offboard_mode = "GUIDED"
    attitude_mode = "GUIDED"
    after_takeoff = "GUIDED"
    #: The take-off climbs inside GUIDED: HEARTBEAT says GUIDED throughout.
    report_as = {"TAKEOFF": "GUIDED"}
    offboard_needs_stream = False
    takeoff_by_command = True
    takeoff_alt_relative = True
    param_bytewise = False
    #: ArduCopter sends no HIGHRES_IMU by default: RAW_IMU (int16: milli-g,
    #: mrad/s, milligauss) and SCALED_IMU2 in its RAW_SENS stream group.
    imu_message = "RAW_IMU"
    #: docs/flying-a-real-vehicle.md "Parameters to set" (ArduCopter).
    param_checks = (
        ParamCheck("FS_GCS_ENABLE", "GCS failsafe: RTL or land", allowed=(1, 5)),
    )
    param_specs = (
        ParamSpec("GUID_TIMEOUT", _R, 3.0, 0.1, 5.0, "guided setpoint timeout: older setpoints stop the vehicle (s)"),
        ParamSpec("FS_GCS_ENABLE", _I, 0, 0, 7, "GCS failsafe: 0 off, 1 RTL, 3 SmartRTL/RTL, 4 SmartRTL/land, 5 land"),
        ParamSpec("FS_GCS_TIMEOUT", _R, 5.0, 2.0, 120.0, "GCS failsafe timeout (s)"),
        ParamSpec("DISARM_DELAY", _I, 10, 0, 127, "auto-disarm on the ground (s; 0 off)"),
        ParamSpec("PILOT_TKOFF_ALT", _R, 250.0, 10.0, 1000.0,
                  "take-off height when MAV_CMD_NAV_TAKEOFF asks for none (cm)"),
        ParamSpec("WPNAV_SPEED", _R, 500.0, 20.0, 2000.0, "horizontal speed limit and return speed (cm/s)"),
        ParamSpec("WPNAV_SPEED_UP", _R, 250.0, 10.0, 1000.0, "climb speed limit and take-off speed (cm/s)"),
        ParamSpec("WPNAV_SPEED_DN", _R, 150.0, 10.0, 500.0, "descent speed limit (cm/s)"),
        ParamSpec("LAND_SPEED", _R, 50.0, 30.0, 200.0, "final landing descent speed (cm/s)"),
        ParamSpec("ANGLE_MAX", _I, 3000, 1000, 8000, "tilt limit (centidegrees)"),
        ParamSpec("RTL_ALT", _R, 500.0, 0.0, 15000.0, "return altitude above home (cm; ArduCopter's default is 1500)"),
        ParamSpec("WPNAV_RADIUS", _R, 200.0, 5.0, 1000.0, "way-point acceptance radius (cm)"),
        ParamSpec("AUTO_OPTIONS", _I, 0, 0, 255,
                  "AUTO options bitmask: bit 0 allows arming in AUTO, bit 1 allows the take-off without raising "
                  "the throttle (the SITL has no RC: MAV_CMD_MISSION_START or a GUIDED take-off release it)"),
        ParamSpec("MOT_THST_HOVER", _R, 0.35, 0.05, 1.0,
                  "hover thrust, normalised (the vehicle's m g / (4 f_max) at start; ArduCopter learns it in flight)"),
        ParamSpec("MOT_THST_EXPO", _R, 0.0, 0.0, 1.0,
                  "motor thrust curve expo: thrust = (1 - e) u + e u^2 (ArduCopter's default 0.65; the simulated "
                  "motors are linear: 0)"),
    ) + SIM_PARAM_SPECS
    param_aliases = (
        ParamAlias("COM_OF_LOSS_T", "GUID_TIMEOUT"),
        ParamAlias("COM_DISARM_LAND", "DISARM_DELAY"),
        ParamAlias("COM_DISARM_PRFLT", "DISARM_DELAY"),
        ParamAlias("MIS_TAKEOFF_ALT", "PILOT_TKOFF_ALT", 100.0),
        ParamAlias("MPC_TKO_SPEED", "WPNAV_SPEED_UP", 100.0),
        ParamAlias("MPC_Z_VEL_MAX_UP", "WPNAV_SPEED_UP", 100.0),
        ParamAlias("MPC_Z_VEL_MAX_DN", "WPNAV_SPEED_DN", 100.0),
        ParamAlias("MPC_LAND_SPEED", "LAND_SPEED", 100.0),
        ParamAlias("MPC_XY_CRUISE", "WPNAV_SPEED", 100.0),
        ParamAlias("MPC_XY_VEL_MAX", "WPNAV_SPEED", 100.0),
        ParamAlias("MPC_TILTMAX_AIR", "ANGLE_MAX", 100.0),
        ParamAlias("RTL_RETURN_ALT", "RTL_ALT", 100.0),
        ParamAlias("NAV_ACC_RAD", "WPNAV_RADIUS", 100.0),
        ParamAlias("MPC_THR_HOVER", "MOT_THST_HOVER"),
        ParamAlias("THR_MDL_FAC", "MOT_THST_EXPO"),
    )
    #: Internal values with no ArduCopter parameter (not on the wire).
    fixed_params = {
        "COM_HIL_TMO": 0.2, "NAV_MC_ALT_RAD": 0.8,
        # PX4's collision prevention is off (ArduCopter's AVOID_* is not simulated);
        # a geofence breach returns (ArduCopter's FENCE_ACTION default 1: RTL, else land).
        "CP_DIST": -1.0, "CP_DELAY": 0.4, "CP_GO_NO_DATA": 0, "GF_ACTION": 3, "MPC_ACC_HOR": 3.0,
        # PX4's offboard-loss parameters, unused by ArduCopter's rules (FS_GCS_* below)
        "COM_OBL_ACT": 1, "COM_FAIL_ACT_T": 5.0,
    }
    #: Guided timeout: hold in GUIDED; FS_GCS_ENABLE's action FS_GCS_TIMEOUT
    #: after the last setpoint (the SITL counts the controlling link's
    #: setpoints; the companion sends its HEARTBEAT on the same link).
    offboard_loss = OffboardLoss("COM_OF_LOSS_T", None, "FS_GCS_TIMEOUT", "FS_GCS_ENABLE")
    #: ArduCopter's AUTO: ArduCopter/mode_auto.cpp (init, takeoff_run, verify_nav_wp,
    #: exit_mission), libraries/AP_Mission (AP_MISSION_FIRST_REAL_COMMAND 1; NAV_WAYPOINT
    #: keeps param1 only on Copter) and GCS_Mavlink.cpp (MAV_CMD_MISSION_START).
    mission_rules = MissionRules(first_seq=1, item_acceptance=False, item_yaw=False, implicit_takeoff=False,
                                 rtl_in_mission=True, auto_armed=True, reached_text=True)

    def action_of(self, value: float) -> str:
        return _FS_GCS_ACTION.get(int(value), "hold")

    def custom_mode_from_params(self, param2: float, param3: float) -> int:
        return int(param2)

    def set_mode_params(self, name: str) -> tuple[float, float, float]:
        return float(MODE_FLAG_CUSTOM_MODE_ENABLED), float(self.custom_mode(name)), 0.0


ARDUCOPTER = ArduCopter()
