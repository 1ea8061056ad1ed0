"""MAVLink encode/decode of the SITL: the only SITL module that speaks NED/FRD,
wire units (1e7 degrees, mm, cm, cdeg, mG) and MAVLink's [w, x, y, z]
quaternions.

Everything it takes and returns is ENU world / FLU body, SI units
(docs/frames.md); every frame change goes through
``mavcore.frames``. Encoders take a pymavlink ``MAVLink`` protocol object
(``conn.mav``, it only supplies the message classes) and return the message
object, ready for ``conn.mav.send``; decoders take a pymavlink message and
return a small named result, or ``None`` for a message that must be ignored
(wrong target, unsupported frame, out-of-range or non-finite values).

The encoders of the per-frame messages (HIGHRES_IMU, LOCAL_POSITION_NED,
ATTITUDE) write the frame change component by component instead of calling
``frames.flu2frd`` on a stacked array: they run at up to 250 Hz and the
explicit form is several times cheaper. ``tests/test_sitl_codec.py`` checks
each of them against ``mavcore.frames``.

Wire conventions chosen here (documented once)
----------------------------------------------
- PX4 custom modes: ``custom_mode = main_mode << 16 | sub_mode << 24``,
  ``base_mode`` always has ``MAV_MODE_FLAG_CUSTOM_MODE_ENABLED``.
- DISTANCE_SENSOR: centimetres; a reading with no return (nothing within
  ``max_m``) is sent as ``current_distance = max_distance + 1`` cm with
  ``signal_quality = 1`` (MAVLink: 1 = invalid signal). DISTANCE_SENSOR's own
  definition does not say how to send "no return"; ``max_distance + 1`` is
  OBSTACLE_DISTANCE's definition of "no obstacle", and a value outside
  ``[min_distance, max_distance]`` is what every PX4 consumer (EKF2,
  collision prevention) treats as "no valid reading". Valid readings have
  ``signal_quality = 100``. ``covariance`` is the range noise variance in
  cm^2 (rounded, at most 254; 255 would mean unknown). ``quaternion`` is
  the sensor's mounting rotation, sensor frame -> body FRD, [w, x, y, z]
  with w >= 0 (MAVLink: "zero-rotation is along the vehicle body x-axis";
  required for MAV_SENSOR_ROTATION_CUSTOM). It is sent for every sensor, the
  enum's own rotation for the others (MAVLink asks for it only with CUSTOM
  and says "0 if invalid"; PX4 sends zeros there): a reader can always use
  it, or use ``orientation`` unless it is 100.
- NAV_TAKEOFF ``param7`` is an altitude AMSL (m), as PX4; NaN means "the
  default takeoff height" (MIS_TAKEOFF_ALT above home).
- SET_POSITION_TARGET_LOCAL_NED: ``type_mask`` bits as MAVLink's
  POSITION_TARGET_TYPEMASK; an ignored or non-finite component becomes NaN
  per axis (PX4's trajectory_setpoint convention). With FORCE_SET the
  acceleration fields are ignored and the rest is used (PX4 and ArduCopter
  do not support force setpoints either, but reject the whole message when
  it also uses the acceleration). Frames: MAV_FRAME_LOCAL_NED, and
  MAV_FRAME_BODY_NED as ArduCopter reads it: velocity, acceleration and
  position rotated by the current heading, the position an offset from the
  current position, the yaw an offset from the current heading (clockwise).
  PX4 differs: it ignores the position and keeps the yaw absolute (MAVLink's
  own text: BODY_NED positions are LOCAL_NED); the usual body-velocity
  setpoint (MAVSDK ``set_velocity_body``: position and yaw ignored) means the
  same on all three. Every other frame (LOCAL_OFFSET_NED, BODY_OFFSET_NED,
  BODY_FRD, ...) is rejected, as PX4 does.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from mavcore import frames
from mavcore.link.command_rules import (MAX_SETPOINT_ACC_M_S2, MAX_SETPOINT_POS_M, MAX_SETPOINT_VEL_M_S,
                                        attitude_target_problem)

from .mission_items import GeoOrigin


__all__ = ['RateSetpoint', 'ARM_FORCE_MAGIC', 'HIGHRES_IMU_FIELDS', 'TM_X', 'TM_Y', 'TM_Z', 'TM_VX', 'TM_VY',
           'TM_VZ', 'TM_AX', 'TM_AY', 'TM_AZ', 'TM_FORCE', 'TM_YAW', 'TM_YAW_RATE', 'TM_POS', 'TM_VEL', 'TM_ACC',
           'base_mode', 'param_to_wire', 'param_from_wire', 'PositionTarget', 'addressed_to_us',
           'decode_position_target', 'decode_attitude_rates', 'ObstacleSectors', 'FRAME_BODY_FRD',
           'decode_obstacle_distance', 'decode_takeoff_altitude', 'heartbeat', 'highres_imu_args', 'G0_M_S2',
           'raw_imu_args', 'scaled_imu2', 'highres_imu', 'attitude_args', 'attitude', 'attitude_quaternion_args',
           'attitude_quaternion', 'local_position_ned_args', 'local_position_ned', 'quat_wxyz_of',
           'odometry_truth_args', 'heading_cdeg', 'yaw_enu_of', 'global_position_int', 'gps_raw_int',
           'home_position', 'distance_sensor_args', 'mount_quaternion_frd', 'mount_rotation_flu_of',
           'distance_sensor', 'position_target_local_ned', 'STATUSTEXT_CHUNK', 'STATUSTEXT_MAX', 'statustext',
           'statustext_chunks', 'yaw_ned2enu', 'odometry_truth', 'sys_status', 'battery_status']


#: MAV_CMD_COMPONENT_ARM_DISARM param2 magic that bypasses the arming checks.
ARM_FORCE_MAGIC = 21196


#: HIGHRES_IMU.fields_updated: acc, gyro, mag (bits 0-8), abs pressure (9),
#: pressure altitude (11), temperature (12). No differential pressure.
HIGHRES_IMU_FIELDS = 0x1FF | (1 << 9) | (1 << 11) | (1 << 12)
TM_X = mavlink.POSITION_TARGET_TYPEMASK_X_IGNORE
TM_Y = mavlink.POSITION_TARGET_TYPEMASK_Y_IGNORE
TM_Z = mavlink.POSITION_TARGET_TYPEMASK_Z_IGNORE
TM_VX = mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE
TM_VY = mavlink.POSITION_TARGET_TYPEMASK_VY_IGNORE
TM_VZ = mavlink.POSITION_TARGET_TYPEMASK_VZ_IGNORE
TM_AX = mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE
TM_AY = mavlink.POSITION_TARGET_TYPEMASK_AY_IGNORE
TM_AZ = mavlink.POSITION_TARGET_TYPEMASK_AZ_IGNORE
TM_FORCE = mavlink.POSITION_TARGET_TYPEMASK_FORCE_SET
TM_YAW = mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE
TM_YAW_RATE = mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
TM_POS = TM_X | TM_Y | TM_Z
TM_VEL = TM_VX | TM_VY | TM_VZ
TM_ACC = TM_AX | TM_AY | TM_AZ
_NAN3 = (math.nan, math.nan, math.nan)


# International Standard Atmosphere (for HIGHRES_IMU's barometer fields).
_P0_HPA = 1013.25
_T0_K = 288.15
_LAPSE_K_M = 0.0065
_ISA_EXP = 5.25588


def base_mode(armed: bool) -> int:
    """HEARTBEAT ``base_mode``: custom mode enabled, plus the armed flag."""
    flags = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if armed:
        flags |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    return flags


def param_to_wire(value: float | int, param_type: int) -> float:
    """Parameter value -> the float carried in PARAM_VALUE/PARAM_SET.

    PX4 sends integer parameters byte-wise: the int32 bit pattern
    reinterpreted as a float32 (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE,
    announced in AUTOPILOT_VERSION). MAVSDK and MAVProxy decode it so.
    """
    if param_type == mavlink.MAV_PARAM_TYPE_INT32:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def param_from_wire(wire_value: float, param_type: int) -> float | int:
    """Inverse of ``param_to_wire``."""
    if param_type == mavlink.MAV_PARAM_TYPE_INT32:
        return struct.unpack("<i", struct.pack("<f", float(wire_value)))[0]
    return float(wire_value)


@dataclass(frozen=True, slots=True)
class RateSetpoint:
    """A decoded attitude-rate setpoint (SET_ATTITUDE_TARGET, attitude ignored).

    Attributes
    ----------
    rates_flu_rad_s : tuple (3,)
        Body rates, FLU (rad/s).
    thrust : float
        Collective thrust normalised to [0, 1] (1: every rotor at full thrust).
    """

    rates_flu_rad_s: tuple
    thrust: float


@dataclass(frozen=True, slots=True)
class PositionTarget:
    """A decoded SET_POSITION_TARGET_LOCAL_NED, in world ENU, SI units.

    Attributes
    ----------
    pos_enu_m, vel_enu_m_s, acc_enu_m_s2 : ndarray (3,)
        Per-axis targets; NaN where the type_mask ignores the component (or it
        was not finite). All-NaN means "not given".
    yaw_enu_rad : float or None
        Heading of body x, ENU (from east, counter-clockwise); None = ignored.
    yaw_rate_enu_rad_s : float or None
        Yaw rate about world up (rad/s); None = ignored.
    type_mask : int
        The raw MAVLink type_mask, for the echo in POSITION_TARGET_LOCAL_NED.
    """

    pos_enu_m: np.ndarray
    vel_enu_m_s: np.ndarray
    acc_enu_m_s2: np.ndarray
    yaw_enu_rad: float | None
    yaw_rate_enu_rad_s: float | None
    type_mask: int


def addressed_to_us(msg, system_id: int = 1, component_id: int = 1) -> bool:
    """True if a targeted message is for this vehicle (or broadcast, 0)."""
    ts = getattr(msg, "target_system", 0)
    tc = getattr(msg, "target_component", 0)
    return ts in (0, system_id) and tc in (0, component_id)


def _triple(mask: int, x, y, z, bx: int, by: int, bz: int, limit: float) -> tuple:
    """Three setpoint components (floats): NaN where ``mask`` ignores one or it is
    not finite; ValueError when a used one exceeds ``limit``."""
    out = []
    for v, bit in ((float(x), bx), (float(y), by), (float(z), bz)):
        if not (mask & bit) and math.isfinite(v):
            if abs(v) > limit:
                raise ValueError
            out.append(v)
        else:
            out.append(math.nan)
    return out


def decode_position_target(msg, yaw_enu_rad: float = 0.0,
                           pos_enu_m=(0.0, 0.0, 0.0)) -> PositionTarget | None:
    """SET_POSITION_TARGET_LOCAL_NED -> ``PositionTarget`` (ENU), or None.

    Parameters
    ----------
    msg : pymavlink MAVLink_set_position_target_local_ned_message
    yaw_enu_rad : float
        Current heading (ENU), used only for MAV_FRAME_BODY_NED.
    pos_enu_m : array_like (3,)
        Current position (ENU, m), used only for MAV_FRAME_BODY_NED.

    Returns
    -------
    PositionTarget or None
        None for an unsupported coordinate frame or a value beyond the sanity
        limits (the message is then ignored as PX4 does).
    """
    mask = int(msg.type_mask)
    frame = int(msg.coordinate_frame)
    if frame not in (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_NED):
        return None

    try:
        p_ned = _triple(mask, msg.x, msg.y, msg.z, TM_X, TM_Y, TM_Z, MAX_SETPOINT_POS_M)
        v_ned = _triple(mask, msg.vx, msg.vy, msg.vz, TM_VX, TM_VY, TM_VZ, MAX_SETPOINT_VEL_M_S)
        if mask & TM_FORCE:
            a_ned = _NAN3
        else:
            a_ned = _triple(mask, msg.afx, msg.afy, msg.afz, TM_AX, TM_AY, TM_AZ, MAX_SETPOINT_ACC_M_S2)
    except ValueError:
        return None

    yaw = None
    if not mask & TM_YAW and math.isfinite(msg.yaw):
        yaw = frames.yaw_ned2enu(float(msg.yaw))
    yaw_rate = None
    if not mask & TM_YAW_RATE and math.isfinite(msg.yaw_rate):
        if abs(msg.yaw_rate) > 100.0:
            return None
        yaw_rate = -float(msg.yaw_rate)  # about down (NED) -> about up (ENU)

    # NED -> ENU (frames.ned2enu, on floats: (y, x, -z))
    p = np.array((p_ned[1], p_ned[0], -p_ned[2]))
    v = np.array((v_ned[1], v_ned[0], -v_ned[2]))
    a = np.array((a_ned[1], a_ned[0], -a_ned[2]))
    if frame == mavlink.MAV_FRAME_BODY_NED:
        # Body-NED: x forward along the heading, y right, z down; the
        # horizontal parts rotate by the current heading, z stays vertical.
        # In ENU terms a body-FLU frame yawed by yaw_enu_rad: rotate (x, -y).
        c, s = math.cos(yaw_enu_rad), math.sin(yaw_enu_rad)

        def rot(u_enu):
            # ned2enu swapped axes: forward is u_enu[1], right is u_enu[0]
            fwd, right, up = u_enu[1], u_enu[0], u_enu[2]
            return np.array([c * fwd + s * right, s * fwd - c * right, up])

        p = rot(p) + np.asarray(pos_enu_m, dtype=float)
        v = rot(v)
        a = rot(a)
        if yaw is not None:
            # Body yaw is an offset from the current heading (clockwise in NED).
            yaw = frames.wrap_pi(yaw_enu_rad - float(msg.yaw))
    return PositionTarget(p, v, a, yaw, yaw_rate, mask)


def decode_attitude_rates(msg):
    """SET_ATTITUDE_TARGET (a body-rate setpoint) -> ``RateSetpoint`` (FLU).

    Returns (setpoint or None, problem or None): None with the reason of
    ``command_rules.attitude_target_problem`` when the message is not a
    usable rate setpoint (an attitude one, an ignored rate or thrust, a
    value out of range). Rates FRD -> FLU: ``(p, -q, -r)``.
    """
    rates = (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate)
    why = attitude_target_problem(msg.type_mask, rates, msg.thrust)
    if why is not None:
        return None, why
    return RateSetpoint((float(rates[0]), -float(rates[1]), -float(rates[2])), float(msg.thrust)), None


@dataclass(frozen=True)
class ObstacleSectors:
    """OBSTACLE_DISTANCE decoded (``decode_obstacle_distance``), body FLU, SI.

    Attributes
    ----------
    azimuth_flu_rad : (n,) array
        Centre of each used sector, from body x toward body y (left).
    half_width_rad : float
        Half a sector's width.
    distance_m : (n,) array
        Horizontal distance to the obstacle (m); inf: no obstacle within
        ``max_distance``; NaN: unknown (no sensor looks there).
    """

    azimuth_flu_rad: np.ndarray
    half_width_rad: float
    distance_m: np.ndarray


#: MAV_FRAME_BODY_FRD (OBSTACLE_DISTANCE.frame for body-mounted sensors).
FRAME_BODY_FRD = 12


def decode_obstacle_distance(msg) -> ObstacleSectors | None:
    """OBSTACLE_DISTANCE (cm, sectors clockwise from forward, body FRD) -> ``ObstacleSectors``.

    Only ``MAV_FRAME_BODY_FRD`` is read (None otherwise, and for an increment
    that is not a positive finite angle of at most 360 deg). ``increment_f``
    wins over ``increment`` when non-zero (MAVLink); a negative one runs
    counter-clockwise. Sectors beyond one full turn are unused. Values:
    ``UINT16_MAX`` unknown, above ``max_distance`` no obstacle, anything else
    a distance (below ``min_distance``: as close as ``min_distance``).
    """
    if int(msg.frame) != FRAME_BODY_FRD:
        return None
    inc = float(msg.increment_f) if float(msg.increment_f) != 0.0 else float(msg.increment)
    offset = float(msg.angle_offset)
    if not (math.isfinite(inc) and 0.0 < abs(inc) <= 360.0 and math.isfinite(offset)):
        return None
    n = min(len(msg.distances), int(math.floor(360.0 / abs(inc) + 1e-9)))
    d_cm = np.asarray(msg.distances[:n], dtype=float)
    lo, hi = float(msg.min_distance), float(msg.max_distance)
    dist = np.where(d_cm == 65535.0, math.nan, np.where(d_cm > hi, math.inf, np.maximum(d_cm, lo) / 100.0))
    angles_frd_deg = offset + inc * np.arange(n)
    az = frames.wrap_pi(frames.angle_frd_deg2azimuth_flu(angles_frd_deg))
    return ObstacleSectors(np.asarray(az, dtype=float), math.radians(abs(inc)) / 2.0, dist)


def decode_takeoff_altitude(param7: float, origin_alt_amsl_m: float) -> float | None:
    """NAV_TAKEOFF param7 (altitude AMSL, m, as PX4) -> ENU z (m), None = default.

    ENU z is measured from the map origin, whose altitude AMSL is the
    mission's ``home.alt_m``.
    """
    if not math.isfinite(param7):
        return None
    return float(param7) - origin_alt_amsl_m


def heartbeat(mav, armed: bool, custom_mode: int, system_status: int,
              autopilot: int = mavlink.MAV_AUTOPILOT_PX4):
    """Vehicle HEARTBEAT: quadrotor, the personality's MAV_AUTOPILOT and custom mode."""
    return mav.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, autopilot,
                                base_mode(armed), custom_mode, system_status)


def highres_imu_args(time_us: int, accel_flu_m_s2, gyro_flu_rad_s, mag_flu_gauss,
                     alt_amsl_m: float) -> tuple:
    """HIGHRES_IMU fields (``highres_imu_encode`` order) from body-FLU measurements.

    Body FLU -> FRD is (x, -y, -z) (``frames.flu2frd``), written out per
    component. ``time_usec`` is vehicle time; accelerometer = specific force
    (m/s^2; g R^T e3 with ``sim.vector_sensors: paper``, ``sitl.sensors``),
    gyro rad/s, magnetometer gauss. Barometer fields follow the ISA
    from the altitude AMSL (hPa, m, degC).
    """
    ax, ay, az = accel_flu_m_s2
    gx, gy, gz = gyro_flu_rad_s
    mx, my, mz = mag_flu_gauss
    t_k = _T0_K - _LAPSE_K_M * alt_amsl_m
    p_hpa = _P0_HPA * (t_k / _T0_K) ** _ISA_EXP if t_k > 0 else 0.0
    return (int(time_us), float(ax), -float(ay), -float(az), float(gx), -float(gy), -float(gz),
            float(mx), -float(my), -float(mz), p_hpa, 0.0, float(alt_amsl_m), t_k - 273.15,
            HIGHRES_IMU_FIELDS, 0)


#: Standard gravity (m/s^2): ArduPilot's GRAVITY_MSS, RAW_IMU/SCALED_IMU's milli-g.
G0_M_S2 = 9.80665


def _i16(v: float) -> int:
    """Round to the nearest int16 (saturating, as the stack's int16 fields do)."""
    x = round(v) if math.isfinite(v) else 0
    return -32768 if x < -32768 else 32767 if x > 32767 else int(x)


def raw_imu_args(time_us: int, accel_flu_m_s2, gyro_flu_rad_s, mag_flu_gauss) -> tuple:
    """RAW_IMU fields (``raw_imu_encode`` order) in ArduPilot's units: accelerometer
    milli-g (m/s^2 * 1000 / 9.80665), gyro mrad/s, magnetometer milligauss, body
    FRD (FLU (x, -y, -z)), int16 each; ``time_usec`` vehicle time; id 0."""
    ax, ay, az = accel_flu_m_s2
    gx, gy, gz = gyro_flu_rad_s
    mx, my, mz = mag_flu_gauss
    ka = 1000.0 / G0_M_S2
    return (int(time_us), _i16(ax * ka), _i16(-ay * ka), _i16(-az * ka), _i16(gx * 1e3), _i16(-gy * 1e3),
            _i16(-gz * 1e3), _i16(mx * 1e3), _i16(-my * 1e3), _i16(-mz * 1e3), 0, 0)


def scaled_imu2(mav, time_boot_ms: int, accel_flu_m_s2, gyro_flu_rad_s, mag_flu_gauss):
    """SCALED_IMU2 (the second IMU as ArduPilot reports it): RAW_IMU's units, ``time_boot_ms``."""
    a = raw_imu_args(0, accel_flu_m_s2, gyro_flu_rad_s, mag_flu_gauss)
    return mav.scaled_imu2_encode(int(time_boot_ms), *a[1:10], 0)


def highres_imu(mav, time_us: int, accel_flu_m_s2, gyro_flu_rad_s, mag_flu_gauss,
                alt_amsl_m: float):
    """HIGHRES_IMU message (see ``highres_imu_args``)."""
    return mav.highres_imu_encode(*highres_imu_args(time_us, accel_flu_m_s2, gyro_flu_rad_s,
                                                    mag_flu_gauss, alt_amsl_m))


def attitude_args(time_boot_ms: int, R_enu_flu, omega_flu_rad_s) -> tuple:
    """ATTITUDE fields: Z-Y-X Euler angles of R_ned_frd (rad) and body FRD rates.

    ``frames.rotmat2euler_zyx(frames.R_enu_flu2ned_frd(R))`` written out on
    floats (``R_ned_frd`` as in ``odometry_truth_args``: only exact sign
    changes, so the angles are bit-identical). ``R_enu_flu``: (3, 3), rows,
    or a row-major 9-tuple.
    """
    r00, _, _, r10, _, _, r20, r21, r22 = _flat9(R_enu_flu)
    roll = math.atan2(r21, r22)
    pitch = -math.asin(max(-1.0, min(1.0, -r20)))
    yaw = math.atan2(r00, r10)
    wx, wy, wz = omega_flu_rad_s
    return (int(time_boot_ms), roll, pitch, yaw, float(wx), -float(wy), -float(wz))


def attitude(mav, time_boot_ms: int, R_enu_flu, omega_flu_rad_s):
    """ATTITUDE message (see ``attitude_args``)."""
    return mav.attitude_encode(*attitude_args(time_boot_ms, R_enu_flu, omega_flu_rad_s))


def attitude_quaternion_args(time_boot_ms: int, R_enu_flu, omega_flu_rad_s) -> tuple:
    """ATTITUDE_QUATERNION fields: [w, x, y, z] of body FRD -> world NED
    (``R_ned_frd`` written out as in ``odometry_truth_args``), FRD rates.
    ``R_enu_flu``: (3, 3), rows, or a row-major 9-tuple."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _flat9(R_enu_flu)
    q = quat_wxyz_of(r10, -r11, -r12, r00, -r01, -r02, -r20, r21, r22)
    wx, wy, wz = omega_flu_rad_s
    return (int(time_boot_ms), q[0], q[1], q[2], q[3], float(wx), -float(wy), -float(wz), _Q_IDENTITY)


def attitude_quaternion(mav, time_boot_ms: int, R_enu_flu, omega_flu_rad_s):
    """ATTITUDE_QUATERNION message (see ``attitude_quaternion_args``)."""
    return mav.attitude_quaternion_encode(*attitude_quaternion_args(time_boot_ms, R_enu_flu, omega_flu_rad_s))


def _flat9(R) -> tuple:
    """R (a (3, 3) array, three rows, or a row-major 9-tuple as ``sitl.plant``
    keeps it) as nine floats, row-major."""
    if type(R) is tuple and len(R) == 9:
        return R
    if hasattr(R, "ravel"):
        return tuple(R.ravel().tolist())
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R
    return (r00, r01, r02, r10, r11, r12, r20, r21, r22)


_Q_IDENTITY = (1.0, 0.0, 0.0, 0.0)


def local_position_ned_args(time_boot_ms: int, pos_enu_m, vel_enu_m_s) -> tuple:
    """LOCAL_POSITION_NED fields from ENU position/velocity ((x, y, z) -> (y, x, -z))."""
    x, y, z = pos_enu_m
    vx, vy, vz = vel_enu_m_s
    return (int(time_boot_ms), float(y), float(x), -float(z), float(vy), float(vx), -float(vz))


def local_position_ned(mav, time_boot_ms: int, pos_enu_m, vel_enu_m_s):
    """LOCAL_POSITION_NED message (see ``local_position_ned_args``)."""
    return mav.local_position_ned_encode(*local_position_ned_args(time_boot_ms, pos_enu_m, vel_enu_m_s))


_COV_UNKNOWN = (math.nan,) + (0.0,) * 20


def quat_wxyz_of(r00, r01, r02, r10, r11, r12, r20, r21, r22) -> tuple:
    """``frames.rotmat2quat_wxyz`` on nine floats (Shepperd, w >= 0): the
    per-frame ODOMETRY cannot afford numpy on a 3x3."""
    tr = r00 + r11 + r22
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = (0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s)
    elif r00 > r11 and r00 > r22:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        q = ((r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s)
    elif r11 > r22:
        s = 2.0 * math.sqrt(1.0 + r11 - r00 - r22)
        q = ((r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + r22 - r00 - r11)
        q = ((r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s)
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    sg = -1.0 / n if q[0] < 0 else 1.0 / n
    return (q[0] * sg, q[1] * sg, q[2] * sg, q[3] * sg)


def odometry_truth_args(time_us: int, pos_enu_m, vel_enu_m_s, R_enu_flu, omega_flu_rad_s) -> tuple:
    """ODOMETRY fields carrying the true state: pose in MAV_FRAME_LOCAL_NED,
    velocity and rates in MAV_FRAME_BODY_FRD, covariances unknown (NaN first
    element), estimator type unknown, quality 100.

    ``R_ned_frd = T_ne R_enu_flu T_fb`` (``frames.R_enu_flu2ned_frd``) is
    written out: rows (r1, r0, -r2) of R with columns 1 and 2 negated. The
    body velocity is ``R_enu_flu^T v_enu`` (FLU) mapped to FRD.
    ``R_enu_flu``: (3, 3), rows, or a row-major 9-tuple.
    """
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _flat9(R_enu_flu)
    x, y, z = pos_enu_m
    ve, vn, vu = vel_enu_m_s
    wx, wy, wz = omega_flu_rad_s
    q = quat_wxyz_of(r10, -r11, -r12, r00, -r01, -r02, -r20, r21, r22)
    bx = r00 * ve + r10 * vn + r20 * vu      # R^T v: body FLU
    by = r01 * ve + r11 * vn + r21 * vu
    bz = r02 * ve + r12 * vn + r22 * vu
    return (int(time_us), mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD,
            float(y), float(x), -float(z), q, bx, -by, -bz, float(wx), -float(wy), -float(wz),
            _COV_UNKNOWN, _COV_UNKNOWN, 0, mavlink.MAV_ESTIMATOR_TYPE_UNKNOWN, 100)


def _geo(origin: GeoOrigin, pos_enu_m):
    lat, lon, alt = frames.enu2geodetic(float(pos_enu_m[0]), float(pos_enu_m[1]),
                                        float(pos_enu_m[2]), origin.lat_deg, origin.lon_deg,
                                        origin.alt_m)
    return int(round(lat * 1e7)), int(round(lon * 1e7)), alt


def heading_cdeg(yaw_enu_rad: float) -> int:
    """ENU heading (rad) -> NED heading in centidegrees, 0..35999."""
    h = math.degrees(frames.yaw_enu2ned(yaw_enu_rad)) % 360.0
    return int(round(h * 100.0)) % 36000


def yaw_enu_of(R_enu_flu) -> float:
    """Heading of body x in ENU (rad, from east, CCW)."""
    return math.atan2(R_enu_flu[1][0], R_enu_flu[0][0])


def global_position_int(mav, time_boot_ms: int, origin: GeoOrigin, home_enu_m,
                        pos_enu_m, vel_enu_m_s, yaw_enu_rad: float):
    """GLOBAL_POSITION_INT: 1e7 deg, mm AMSL, mm above home, cm/s NED, cdeg."""
    lat, lon, alt = _geo(origin, pos_enu_m)
    rel = float(pos_enu_m[2]) - float(home_enu_m[2])
    vx, vy, vz = vel_enu_m_s
    return mav.global_position_int_encode(
        time_boot_ms, lat, lon, int(round(alt * 1000.0)), int(round(rel * 1000.0)),
        _clip16(vy * 100.0), _clip16(vx * 100.0), _clip16(-vz * 100.0), heading_cdeg(yaw_enu_rad))


def gps_raw_int(mav, time_us: int, origin: GeoOrigin, pos_enu_m, vel_enu_m_s):
    """GPS_RAW_INT: a healthy 3D fix at the (measured) position."""
    lat, lon, alt = _geo(origin, pos_enu_m)
    vx, vy = float(vel_enu_m_s[0]), float(vel_enu_m_s[1])
    speed = math.hypot(vx, vy)
    cog = int(round(math.degrees(math.atan2(vx, vy)) % 360.0 * 100.0)) % 36000 if speed > 0.1 else 65535
    return mav.gps_raw_int_encode(time_us, mavlink.GPS_FIX_TYPE_3D_FIX, lat, lon,
                                  int(round(alt * 1000.0)), 80, 120,
                                  min(int(round(speed * 100.0)), 65534), cog, 12)


def home_position(mav, origin: GeoOrigin, home_enu_m, time_us: int):
    """HOME_POSITION at the vehicle's start point (approach vector zero)."""
    lat, lon, alt = _geo(origin, home_enu_m)
    x, y, z = (float(c) for c in home_enu_m)
    return mav.home_position_encode(lat, lon, int(round(alt * 1000.0)), y, x, -z,
                                    [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, time_us)


def distance_sensor_args(time_boot_ms: int, reading) -> tuple:
    """DISTANCE_SENSOR fields (cm) from a ``RangeReading`` (see the module notes)."""
    min_cm = int(round(reading.min_m * 100.0))
    max_cm = int(round(reading.max_m * 100.0))
    d = reading.distance_m
    if d is None or not math.isfinite(d):
        dist_cm, quality = max_cm + 1, 1
    else:
        dist_cm, quality = int(round(d * 100.0)), 100
    # (getattr: readings of other makers, e.g. tests, may lack the mounting fields)
    std_cm = 100.0 * float(getattr(reading, "noise_std_m", 0.0))
    cov = min(int(round(std_cm * std_cm)), 254)
    return (int(time_boot_ms), min_cm, max_cm, min(max(dist_cm, 0), 65535),
            mavlink.MAV_DISTANCE_SENSOR_LASER, int(reading.sensor_id) & 0xFF,
            int(reading.orientation), cov, float(reading.hfov_rad), float(reading.vfov_rad),
            mount_quaternion_frd(getattr(reading, "mount_rotation_flu", _I9)), quality)


_I9 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


_MOUNT_Q: dict[tuple, tuple] = {}


def mount_quaternion_frd(mount_rotation_flu) -> tuple:
    """Quaternion [w, x, y, z] (w >= 0) of a mounting rotation sensor -> body,
    given sensor -> body FLU (row-major 9-tuple), in FRD on both sides
    (``R_frd = T R_flu T``, T = diag(1, -1, -1)). Cached: a vehicle has a few
    sensors and this runs for every reading."""
    key = tuple(mount_rotation_flu)
    q = _MOUNT_Q.get(key)
    if q is None:
        T = frames.T_FLU_FRD
        R_frd = T @ np.array(key, dtype=float).reshape(3, 3) @ T
        q = _MOUNT_Q[key] = tuple(float(c) for c in frames.rotmat2quat_wxyz(R_frd))
    return q


def mount_rotation_flu_of(quaternion_frd) -> np.ndarray:
    """Inverse of ``mount_quaternion_frd``: [w, x, y, z] sensor -> body FRD ->
    (3, 3) rotation sensor -> body FLU."""
    T = frames.T_FLU_FRD
    return T @ frames.quat_wxyz2rotmat(quaternion_frd) @ T


def distance_sensor(mav, time_boot_ms: int, reading):
    """DISTANCE_SENSOR message (see ``distance_sensor_args``)."""
    return mav.distance_sensor_encode(*distance_sensor_args(time_boot_ms, reading))


def position_target_local_ned(mav, time_boot_ms: int, setpoint):
    """POSITION_TARGET_LOCAL_NED echo of the active ``Setpoint`` (ENU inside).

    Components the setpoint leaves out (None) are flagged ignored in the
    type_mask and sent as zeros.
    """
    mask = 0
    if setpoint.pos_enu_m is None:
        p, mask = (0.0, 0.0, 0.0), mask | TM_POS
    else:
        p = frames.enu2ned(setpoint.pos_enu_m)
    if setpoint.vel_enu_m_s is None:
        v, mask = (0.0, 0.0, 0.0), mask | TM_VEL
    else:
        v = frames.enu2ned(setpoint.vel_enu_m_s)
    if setpoint.acc_enu_m_s2 is None:
        a, mask = (0.0, 0.0, 0.0), mask | TM_ACC
    else:
        a = frames.enu2ned(setpoint.acc_enu_m_s2)
    if setpoint.yaw_enu_rad is None:
        yaw, mask = 0.0, mask | TM_YAW
    else:
        yaw = frames.yaw_enu2ned(setpoint.yaw_enu_rad)
    if setpoint.yaw_rate_rad_s is None:
        yaw_rate, mask = 0.0, mask | TM_YAW_RATE
    else:
        yaw_rate = -float(setpoint.yaw_rate_rad_s)
    return mav.position_target_local_ned_encode(
        time_boot_ms, mavlink.MAV_FRAME_LOCAL_NED, mask,
        float(p[0]), float(p[1]), float(p[2]), float(v[0]), float(v[1]), float(v[2]),
        float(a[0]), float(a[1]), float(a[2]), yaw, yaw_rate)


STATUSTEXT_CHUNK = 50


#: Longest text sent in chunks (the rest is cut).
STATUSTEXT_MAX = 250


def statustext(mav, severity: int, text: str):
    """STATUSTEXT (text cut to the 50 bytes of one chunk)."""
    return mav.statustext_encode(severity, text.encode("ascii", "replace")[:STATUSTEXT_CHUNK])


def statustext_chunks(mav, severity: int, text: str, text_id: int) -> list:
    """A long text as STATUSTEXT chunks (MAVLink 2 ``id`` = ``text_id`` > 0,
    ``chunk_seq`` 0, 1, ...; the last chunk is shorter than 50 bytes, or an
    empty one follows, which is how receivers see the end), at most
    ``STATUSTEXT_MAX`` bytes."""
    b = text.encode("ascii", "replace")[:STATUSTEXT_MAX]
    parts = [b[i:i + STATUSTEXT_CHUNK] for i in range(0, len(b), STATUSTEXT_CHUNK)]
    if len(parts[-1]) == STATUSTEXT_CHUNK:
        parts.append(b"")
    return [mav.statustext_encode(severity, p, text_id, k) for k, p in enumerate(parts)]


def _clip16(x: float) -> int:
    return int(max(-32768, min(32767, round(x))))


def yaw_ned2enu(yaw_ned_rad: float) -> float:
    """Heading from north, clockwise (rad) -> ENU yaw from east, CCW (rad)."""
    return float(frames.yaw_ned2enu(yaw_ned_rad))


def odometry_truth(mav, time_us: int, pos_enu_m, vel_enu_m_s, R_enu_flu, omega_flu_rad_s):
    """ODOMETRY carrying the simulator's ground truth (requested by the companion
    for its tracking statistics; off by default). Pose in MAV_FRAME_LOCAL_NED,
    velocity and rates in MAV_FRAME_BODY_FRD, covariances unknown (NaN first
    element), estimator MAV_ESTIMATOR_TYPE_UNKNOWN."""
    R_ned_frd = frames.R_enu_flu2ned_frd(R_enu_flu)
    p = frames.enu2ned(pos_enu_m)
    v_frd = R_ned_frd.T @ frames.enu2ned(vel_enu_m_s)
    w = frames.flu2frd(omega_flu_rad_s)
    q = frames.rotmat2quat_wxyz(R_ned_frd)
    cov = [math.nan] + [0.0] * 20
    return mav.odometry_encode(
        int(time_us), mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD,
        float(p[0]), float(p[1]), float(p[2]), [float(c) for c in q],
        float(v_frd[0]), float(v_frd[1]), float(v_frd[2]), float(w[0]), float(w[1]), float(w[2]),
        cov, cov, 0, mavlink.MAV_ESTIMATOR_TYPE_UNKNOWN, 100)


def sys_status(mav, sensors_present: int, sensors_enabled: int, sensors_health: int, voltage_v: float,
               current_a: float, remaining: float):
    """SYS_STATUS with the battery: volts -> mV, amperes -> cA, 0..1 -> %."""
    return mav.sys_status_encode(sensors_present, sensors_enabled, sensors_health, 250,
                                 int(round(voltage_v * 1000.0)), int(round(current_a * 100.0)),
                                 int(round(100.0 * min(max(remaining, 0.0), 1.0))), 0, 0, 0, 0, 0, 0)


def battery_status(mav, cells: int, voltage_v: float, current_a: float, consumed_ah: float,
                   consumed_wh: float, remaining: float):
    """BATTERY_STATUS (id 0, all functions, LiPo): per-cell mV (UINT16_MAX for cells
    the pack does not have), cA, mAh, hJ, %."""
    cell_mv = int(round(voltage_v / cells * 1000.0))
    volts = [cell_mv if i < cells else 65535 for i in range(10)]
    return mav.battery_status_encode(0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO,
                                     32767, volts, int(round(current_a * 100.0)),
                                     int(round(consumed_ah * 1000.0)), int(round(consumed_wh * 36.0)),
                                     int(round(100.0 * min(max(remaining, 0.0), 1.0))))
