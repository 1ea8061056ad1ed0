"""What a MAVLink command or setpoint may hold: one table for both ends.

The bundled SITL (``sitl.server``) denies a COMMAND_LONG / COMMAND_INT that
breaks these rules with ``MAV_RESULT_DENIED`` and ignores a setpoint,
actuator or mission message that breaks them with a STATUSTEXT, even from an
allowed controller; the companion (``companion.link.connection``) refuses
to send one (``UnsafeMessage``). The rules follow MAVLink's common.xml:

- NaN in a float parameter means "unused / keep current / default" only
  where common.xml gives it that meaning (yaw: "NaN to use the current
  system yaw heading mode"; latitude and longitude: the current position;
  the MAV_CMD rule "NaN and INT32_MAX may be used ... to indicate
  optional/default values") and in "Empty" parameters; in COMMAND_INT,
  x = y = INT32_MAX is the integer form of that NaN.
- ``NAV_TAKEOFF`` param7 (altitude): NaN (PX4: ``MIS_TAKEOFF_ALT`` above
  home, what MAVSDK's ``takeoff()`` sends) only while the vehicle is on the
  ground; in flight a take-off needs a finite altitude (a NaN one, ACCEPTED
  mid-flight, once took a vehicle out of its mission).
- Infinity has no meaning anywhere; enumerated parameters take only their
  listed values; integer parameters only integral values.
- ``SET_MESSAGE_INTERVAL`` param2: -1 (off), 0 (default) or 1..INT32_MAX us
  (MESSAGE_INTERVAL.interval_us is an int32).
- Setpoints: a field not masked out by ``type_mask`` is NaN ("not given",
  PX4's convention) or finite within ``MAX_SETPOINT_*``; only
  ``MAV_FRAME_LOCAL_NED`` and ``MAV_FRAME_BODY_NED``.
- SET_ATTITUDE_TARGET: body rates and thrust only (``type_mask`` has
  ATTITUDE_IGNORE and none of the rate or THROTTLE ignore bits), each rate
  finite within ``MAX_SETPOINT_BODY_RATE_RAD_S``, thrust finite in [0, 1]
  (MAVLink: "Collective thrust, normalized to 0 .. 1").
- HIL_ACTUATOR_CONTROLS ``controls[0..3]``: all NaN (a lockstep tick
  without override) or all finite in [-1, 1] (MAVLink's range; motors use
  [0, 1], below 0 is off).
- Mission items: params 1-4 finite or NaN; positional frames need a finite
  altitude within ``MAX_ALTITUDE_M`` and, in global frames, latitude and
  longitude within +-90 / +-180 degrees.

A command without a rule here is not validated by this module (the SITL
answers it ``MAV_RESULT_UNSUPPORTED``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

INT32_MAX = 2 ** 31 - 1
#: Largest MAVLink 2 message id (24 bits).
MAX_MESSAGE_ID = 2 ** 24 - 1
#: Sanity limits of a setpoint (ignored beyond them, as PX4 ignores implausible ones).
MAX_SETPOINT_POS_M = 1.0e5
MAX_SETPOINT_VEL_M_S = 100.0
MAX_SETPOINT_ACC_M_S2 = 100.0
MAX_SETPOINT_YAW_RAD = 2.0 * math.pi
MAX_SETPOINT_YAW_RATE_RAD_S = 100.0
MAX_SETPOINT_BODY_RATE_RAD_S = 100.0
#: SET_ATTITUDE_TARGET.type_mask of a body-rate setpoint: the attitude quaternion ignored.
ATTITUDE_TARGET_RATES_ONLY = mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE
_ATTITUDE_TARGET_NEEDED = (mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
                           | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
                           | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
                           | mavlink.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE)
#: Altitudes (m AMSL) a command or mission item may name (the mission's ``home.alt_m`` bound).
MAX_ALTITUDE_M = 1.0e5
ARM_FORCE_MAGIC = 21196.0

_INF = math.inf


@dataclass(frozen=True)
class Param:
    """The rule of one command parameter.

    A value is accepted when it is NaN and ``nan`` allows it ("yes"; "landed":
    only while the vehicle is on the ground), or it is finite and either one
    of ``values`` or within [``lo``, ``hi``] (and integral if ``integer``).
    ``geo``: "lat" or "lon" (degrees in COMMAND_LONG; 1e7 degrees in
    COMMAND_INT, where INT32_MAX stands for NaN).
    """

    label: str
    lo: float = -_INF
    hi: float = _INF
    nan: str = "no"
    values: tuple = ()
    integer: bool = False
    geo: str = ""

    def problem(self, x: float, landed: bool) -> str | None:
        if math.isnan(x):
            if self.nan == "yes" or (self.nan == "landed" and landed):
                return None
            return "NaN" + (" (only on the ground)" if self.nan == "landed" else "")
        if not math.isfinite(x):
            return f"{x}"
        if x in self.values:
            return None
        if self.integer and x != int(x):
            return f"{x:g} is not an integer"
        if not self.lo <= x <= self.hi:
            allowed = [f"{v:g}" for v in self.values]
            if self.lo <= self.hi:
                allowed.append(f"[{self.lo:g}, {self.hi:g}]")
            return f"{x:g} is not in {' or '.join(allowed)}"
        return None


def enum(label: str, *values: float, nan: str = "no") -> Param:
    """A parameter that takes only ``values``."""
    return Param(label, _INF, -_INF, nan, tuple(float(v) for v in values))


#: Empty / reserved: the vehicle does not read it; finite or NaN (common.xml's "unused").
EMPTY = Param("empty", nan="yes")
YAW = Param("yaw (deg)", -360.0, 360.0, nan="yes")
LAT = Param("latitude", -90.0, 90.0, nan="yes", geo="lat")
LON = Param("longitude", -180.0, 180.0, nan="yes", geo="lon")
MSG_ID = Param("message id", 0.0, MAX_MESSAGE_ID, integer=True)
RESPONSE_TARGET = enum("response target", 0, 1, 2, nan="yes")

#: MAV_CMD -> the rules of param1..param7 (COMMAND_INT: param5, param6 are x, y).
COMMAND_RULES: dict[int, tuple[Param, ...]] = {
    mavlink.MAV_CMD_COMPONENT_ARM_DISARM: (
        enum("arm", 0, 1), enum("force", 0, ARM_FORCE_MAGIC, nan="yes"), *(EMPTY,) * 5),
    mavlink.MAV_CMD_NAV_TAKEOFF: (
        Param("pitch (deg)", -90.0, 90.0, nan="yes"), EMPTY, EMPTY, YAW, LAT, LON,
        Param("altitude (m AMSL)", -MAX_ALTITUDE_M, MAX_ALTITUDE_M, nan="landed")),
    mavlink.MAV_CMD_NAV_LAND: (
        Param("abort altitude (m)", -MAX_ALTITUDE_M, MAX_ALTITUDE_M, nan="yes"),
        enum("land mode", 0, 1, 2, nan="yes"), EMPTY, YAW, LAT, LON,
        Param("altitude (m)", -MAX_ALTITUDE_M, MAX_ALTITUDE_M, nan="yes")),
    mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: (EMPTY,) * 7,
    mavlink.MAV_CMD_DO_SET_MODE: (
        Param("base mode", 0.0, 255.0, integer=True), Param("custom main mode", 0.0, 255.0, integer=True),
        Param("custom sub mode", 0.0, 255.0, integer=True), *(EMPTY,) * 4),
    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL: (
        MSG_ID, Param("interval (us)", 0.0, INT32_MAX, values=(-1.0,)), *(EMPTY,) * 4, RESPONSE_TARGET),
    mavlink.MAV_CMD_GET_MESSAGE_INTERVAL: (MSG_ID, *(EMPTY,) * 6),
    mavlink.MAV_CMD_REQUEST_MESSAGE: (MSG_ID, *(EMPTY,) * 5, RESPONSE_TARGET),
    mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: (EMPTY,) * 7,
    mavlink.MAV_CMD_GET_HOME_POSITION: (EMPTY,) * 7,
    mavlink.MAV_CMD_MISSION_START: (
        Param("first item", 0.0, 65535.0, nan="yes", integer=True),
        Param("last item", 0.0, 65535.0, nan="yes", integer=True), *(EMPTY,) * 5),
    # MAVSDK goto_location: param1 -1, param2 CHANGE_MODE, param4 yaw in rad (PX4's reading)
    mavlink.MAV_CMD_DO_REPOSITION: (
        Param("ground speed (m/s)", 0.0, MAX_SETPOINT_VEL_M_S, nan="yes", values=(-1.0,)),
        Param("reposition flags", 0.0, 1.0, nan="yes", integer=True), EMPTY,
        Param("yaw (rad)", -MAX_SETPOINT_YAW_RAD, MAX_SETPOINT_YAW_RAD, nan="yes"), LAT, LON,
        Param("altitude (m)", -MAX_ALTITUDE_M, MAX_ALTITUDE_M, nan="yes")),
}

#: COMMAND_INT frames in which a command's z is understood (others: DENIED).
#: The SITL reads NAV_TAKEOFF's altitude as AMSL, as PX4 does.
COMMAND_INT_FRAMES: dict[int, tuple[int, ...]] = {
    mavlink.MAV_CMD_NAV_TAKEOFF: (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT),
    mavlink.MAV_CMD_DO_REPOSITION: (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT,
                                    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                                    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT),
}

_NAMES = {v: k[len("MAV_CMD_"):] for k, v in vars(mavlink).items() if k.startswith("MAV_CMD_") and isinstance(v, int)}


def command_name(command: int) -> str:
    return _NAMES.get(int(command), str(int(command)))


def command_problem(command: int, params, *, int_frame: int | None = None, landed: bool = False) -> str | None:
    """Why COMMAND_LONG (``int_frame`` None) or COMMAND_INT (its ``frame``) ``command``
    with ``params`` (param1..7; for COMMAND_INT x and y as numbers) breaks the
    table, or None (also for a command without rules). ``landed``: the vehicle
    is on the ground (or disarmed)."""
    rules = COMMAND_RULES.get(int(command))
    if rules is None:
        return None
    name = command_name(command)
    if int_frame is not None and int(command) in COMMAND_INT_FRAMES and \
            int(int_frame) not in COMMAND_INT_FRAMES[int(command)]:
        return f"{name}: frame {int(int_frame)} is not supported"
    for i, (rule, x) in enumerate(zip(rules, params), start=1):
        try:
            x = float(x)
        except (TypeError, ValueError):
            return f"{name} param{i} ({rule.label}): not a number"
        if int_frame is not None and rule.geo and i in (5, 6):
            if x == INT32_MAX:
                x = math.nan          # COMMAND_INT's "unused"
            else:
                x *= 1e-7
        why = rule.problem(x, landed)
        if why is not None:
            return f"{name} param{i} ({rule.label}): {why}"
    return None


def position_target_problem(frame: int, type_mask: int, fields, yaw: float, yaw_rate: float,
                            nan_ok: bool = True) -> str | None:
    """Why a SET_POSITION_TARGET_LOCAL_NED breaks the rules, or None.

    ``fields``: (x, y, z, vx, vy, vz, afx, afy, afz) as sent. Bits of
    ``type_mask`` as POSITION_TARGET_TYPEMASK (bit i ignores field i; bit 9
    FORCE_SET makes afx..afz a force, not used; bit 10 yaw, bit 11 yaw rate).
    ``nan_ok``: a NaN field not masked out is "not given" (the vehicle's
    reading); the companion, which masks what it does not give, sends none.
    """
    if int(frame) not in (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_NED):
        return f"frame {int(frame)} is not supported"
    mask = int(type_mask)
    limits = (MAX_SETPOINT_POS_M,) * 3 + (MAX_SETPOINT_VEL_M_S,) * 3 + (MAX_SETPOINT_ACC_M_S2,) * 3
    names = ("x", "y", "z", "vx", "vy", "vz", "afx", "afy", "afz")
    force = mask & mavlink.POSITION_TARGET_TYPEMASK_FORCE_SET
    for i, (v, lim) in enumerate(zip(fields, limits)):
        if mask & (1 << i) or (i >= 6 and force):
            continue
        v = float(v)
        if not (math.isnan(v) and nan_ok) and not abs(v) <= lim:
            return f"{names[i]} = {v:g} is beyond {lim:g}"
    for bit, v, lim, label in ((mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE, yaw, MAX_SETPOINT_YAW_RAD, "yaw"),
                               (mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE, yaw_rate,
                                MAX_SETPOINT_YAW_RATE_RAD_S, "yaw_rate")):
        v = float(v)
        if not mask & bit and not (math.isnan(v) and nan_ok) and not abs(v) <= lim:
            return f"{label} = {v:g} is beyond {lim:g}"
    return None


def actuator_problem(c0: float, c1: float, c2: float, c3: float) -> str | None:
    """Why HIL_ACTUATOR_CONTROLS ``controls[0..3]`` are unusable, or None: all NaN
    (a tick) or all finite in [-1, 1]."""
    nans = math.isnan(c0) + math.isnan(c1) + math.isnan(c2) + math.isnan(c3)
    if nans == 4:
        return None
    if nans:
        return "controls[0..3] mix NaN and numbers"
    if -1.0 <= c0 <= 1.0 and -1.0 <= c1 <= 1.0 and -1.0 <= c2 <= 1.0 and -1.0 <= c3 <= 1.0:
        return None
    return "controls[0..3] outside [-1, 1]"


_GLOBAL_FRAMES = frozenset({mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                            mavlink.MAV_FRAME_GLOBAL_INT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                            mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT, mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT})
_LOCAL_FRAMES = frozenset({mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_ENU})
#: MAV_FRAME_MISSION: a non-positional item (speed change, ROI, ...).
_MISSION_FRAME = 2
_INVALID_PARAM = (mavlink.MAV_MISSION_INVALID_PARAM1, mavlink.MAV_MISSION_INVALID_PARAM2,
                  mavlink.MAV_MISSION_INVALID_PARAM3, mavlink.MAV_MISSION_INVALID_PARAM4)


def mission_item_problem(frame: int, params, x: int, y: int, z: float) -> tuple[int, str] | None:
    """(MAV_MISSION_RESULT, why) if a MISSION_ITEM_INT (``x``, ``y`` as on the wire:
    1e7 degrees in global frames, 1e4 m in local ones) breaks the rules, else None."""
    frame = int(frame)
    if frame not in _GLOBAL_FRAMES and frame not in _LOCAL_FRAMES and frame != _MISSION_FRAME:
        return mavlink.MAV_MISSION_UNSUPPORTED_FRAME, f"frame {frame} is not supported"
    for i, p in enumerate(params):
        p = float(p)
        if math.isinf(p):
            return _INVALID_PARAM[i], f"param{i + 1} = {p}"
    if frame == _MISSION_FRAME:
        return None
    if frame in _GLOBAL_FRAMES:
        if not -900_000_000 <= int(x) <= 900_000_000:
            return mavlink.MAV_MISSION_INVALID_PARAM5_X, f"latitude {int(x) * 1e-7:g} deg"
        if not -1_800_000_000 <= int(y) <= 1_800_000_000:
            return mavlink.MAV_MISSION_INVALID_PARAM6_Y, f"longitude {int(y) * 1e-7:g} deg"
    z = float(z)
    if not abs(z) <= MAX_ALTITUDE_M:
        return mavlink.MAV_MISSION_INVALID_PARAM7, f"altitude {z:g} m"
    return None


def attitude_target_problem(type_mask: int, rates_frd_rad_s, thrust: float) -> str | None:
    """Why a SET_ATTITUDE_TARGET is unusable as a body-rate setpoint, or None (module rules)."""
    mask = int(type_mask)
    if not mask & ATTITUDE_TARGET_RATES_ONLY:
        return "attitude setpoints are not supported, body rates only (type_mask without ATTITUDE_IGNORE)"
    if mask & _ATTITUDE_TARGET_NEEDED:
        return f"type_mask {mask} ignores a body rate or the thrust"
    for name, r in zip(("body_roll_rate", "body_pitch_rate", "body_yaw_rate"), rates_frd_rad_s):
        if not abs(float(r)) <= MAX_SETPOINT_BODY_RATE_RAD_S:
            return f"{name} {float(r):g} rad/s"
    if not 0.0 <= float(thrust) <= 1.0:
        return f"thrust {float(thrust):g} outside [0, 1]"
    return None


def outgoing_problem(msg) -> str | None:
    """Why the companion must not send ``msg`` (a pymavlink message), or None.
    Commands are judged as if the vehicle were flying (the stricter reading)."""
    t = msg.get_type()
    if t == "COMMAND_LONG":
        return command_problem(msg.command, (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5,
                                             msg.param6, msg.param7))
    if t == "COMMAND_INT":
        return command_problem(msg.command, (msg.param1, msg.param2, msg.param3, msg.param4, msg.x, msg.y,
                                             msg.z), int_frame=msg.frame)
    if t == "SET_POSITION_TARGET_LOCAL_NED":
        return position_target_problem(msg.coordinate_frame, msg.type_mask,
                                       (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz, msg.afx, msg.afy, msg.afz),
                                       msg.yaw, msg.yaw_rate, nan_ok=False)
    if t == "SET_ATTITUDE_TARGET":
        return attitude_target_problem(msg.type_mask, (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate),
                                       msg.thrust)
    if t == "HIL_ACTUATOR_CONTROLS":
        c = msg.controls
        return actuator_problem(c[0], c[1], c[2], c[3])
    if t == "MISSION_ITEM_INT":
        r = mission_item_problem(msg.frame, (msg.param1, msg.param2, msg.param3, msg.param4), msg.x, msg.y, msg.z)
        return None if r is None else f"MISSION_ITEM_INT {msg.seq}: {r[1]}"
    return None
