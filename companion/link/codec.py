"""MAVLink encode/decode for the companion: the only companion module that
speaks NED/FRD, wire units and MAVLink's [w, x, y, z] quaternions.

Everything it returns is ENU world / FLU body, SI units (docs/frames.md);
every frame change goes through ``mavcore.frames``. Decoders take a
pymavlink message object and return a small named result; encoders take a
pymavlink ``MAVLink`` protocol object (``conn.mav``) and return the message
object, ready for ``conn.send``.

The decoders of the per-frame messages (HIGHRES_IMU, LOCAL_POSITION_NED) are
written out component by component instead of via ``frames.frd2flu`` on a
stacked array: they run 250 times per simulated second and the explicit form
is several times cheaper. Their tests check them against ``mavcore.frames``.
"""

from __future__ import annotations

import math
import operator
import struct
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from mavcore import frames
from mavcore.link.command_rules import ATTITUDE_TARGET_RATES_ONLY

# --- MAVLink constants used by the companion (named here once) --------------

MAV_FRAME_GLOBAL_INT = mavlink.MAV_FRAME_GLOBAL_INT
MAV_FRAME_LOCAL_NED = mavlink.MAV_FRAME_LOCAL_NED

#: PX4 custom main modes (``custom_mode = main << 16 | sub << 24``).
PX4_MAIN_MODE_MANUAL = 1
PX4_MAIN_MODE_AUTO = 4
PX4_MAIN_MODE_OFFBOARD = 6
PX4_SUB_MODE_AUTO_TAKEOFF = 2
PX4_SUB_MODE_AUTO_LAND = 6

#: SET_POSITION_TARGET_LOCAL_NED type_mask: use position, velocity,
#: acceleration (as acceleration, not force) and yaw; ignore yaw rate.
TYPE_MASK_POS_VEL_ACC_YAW = mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE

#: HIL_ACTUATOR_CONTROLS.flags bit: this answer is a lockstep tick.
HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP = 1

_NAN16 = (float("nan"),) * 16


# --- decoded messages ------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ImuSample:
    """One HIGHRES_IMU frame in body FLU.

    Attributes
    ----------
    time_usec : int
        Vehicle time (us since boot); the lockstep answer echoes it.
    accel_flu_m_s2 : tuple (3,)
        Specific force (accelerometer), body FLU, m/s^2 (hover: +g along +z).
    gyro_flu_rad_s : tuple (3,)
        Angular velocity Omega, body FLU, rad/s.
    mag_flu_gauss : tuple (3,)
        Magnetic field, body FLU, gauss.

    Float tuples, not arrays: the controller's hot path is plain-float code.
    """

    time_usec: int
    accel_flu_m_s2: tuple
    gyro_flu_rad_s: tuple
    mag_flu_gauss: tuple


@dataclass(frozen=True, slots=True)
class LocalPosition:
    """LOCAL_POSITION_NED converted to ENU.

    Attributes
    ----------
    time_boot_ms : int
        Vehicle time (ms since boot).
    pos_enu_m : tuple (3,)
        Position about the local origin (the mission home), ENU, m.
    vel_enu_m_s : tuple (3,)
        Velocity, ENU, m/s.
    """

    time_boot_ms: int
    pos_enu_m: tuple
    vel_enu_m_s: tuple


@dataclass(frozen=True, slots=True)
class Attitude:
    """Attitude (ATTITUDE or ATTITUDE_QUATERNION) as ``R_enu_flu`` (3x3, body FLU -> world ENU)."""

    time_boot_ms: int
    R_enu_flu: np.ndarray


@dataclass(frozen=True, slots=True)
class VehicleState:
    """The vehicle's HEARTBEAT: armed flag and PX4 main/sub mode."""

    armed: bool
    main_mode: int
    sub_mode: int
    system_status: int

    @property
    def offboard(self) -> bool:
        return self.main_mode == PX4_MAIN_MODE_OFFBOARD


@dataclass(frozen=True, slots=True)
class Range:
    """DISTANCE_SENSOR reading, frame-free (the sensor's rotation is in body FLU).

    Attributes
    ----------
    time_boot_ms : int
    sensor_id : int
    distance_m : float
        Measured range (m); NaN when outside [min, max] (no return, or too close).
    min_m, max_m : float
        Sensor limits (m).
    orientation : int
        MAV_SENSOR_ORIENTATION as on the wire (100: MAV_SENSOR_ROTATION_CUSTOM).
    hfov_rad, vfov_rad : float
        Full horizontal/vertical fields of view (rad; 0 when the sender leaves them unset).
    covariance_m2 : float
        Measurement variance (m^2); NaN when unknown (255 on the wire).
    no_return : bool
        The sensor saw nothing within ``max_m`` (``current_distance > max_distance``,
        as PX4 and the bundled SITL send it): the whole beam is free up to ``max_m``.
    R_flu_sensor : tuple (9,) or None
        Rotation from the sensor frame (x along the beam, y left, z up: the
        FLU convention) to body FLU, row-major; its first column is the beam
        direction in body FLU. From the orientation (0..7, 24, 25) or, for
        MAV_SENSOR_ROTATION_CUSTOM, the quaternion field. None when the
        orientation is not supported or the quaternion is invalid (zero).
    """

    time_boot_ms: int
    sensor_id: int
    distance_m: float
    min_m: float
    max_m: float
    orientation: int
    hfov_rad: float = 0.0
    vfov_rad: float = 0.0
    covariance_m2: float = math.nan
    no_return: bool = False
    R_flu_sensor: tuple | None = None


@dataclass(frozen=True, slots=True)
class TruthState:
    """The simulator's true state, ENU/FLU.

    Attributes
    ----------
    time_usec : int
        Vehicle time (us since boot).
    pos_enu_m : tuple (3,)
        True position about the mission home, ENU, m.
    vel_enu_m_s : tuple (3,)
        True velocity, ENU, m/s.
    R_enu_flu : ndarray (3, 3) or None
        True attitude (body FLU -> world ENU).
    """

    time_usec: int
    pos_enu_m: tuple
    vel_enu_m_s: tuple
    R_enu_flu: np.ndarray | None = None


def decode_highres_imu(msg) -> ImuSample:
    """HIGHRES_IMU (body FRD) -> ``ImuSample`` (body FLU); FRD->FLU is (x, -y, -z)."""
    return ImuSample(
        time_usec=int(msg.time_usec),
        accel_flu_m_s2=(msg.xacc, -msg.yacc, -msg.zacc),
        gyro_flu_rad_s=(msg.xgyro, -msg.ygyro, -msg.zgyro),
        mag_flu_gauss=(msg.xmag, -msg.ymag, -msg.zmag),
    )


def decode_local_position_ned(msg) -> LocalPosition:
    """LOCAL_POSITION_NED -> ``LocalPosition`` in ENU; NED->ENU is (y, x, -z)."""
    return LocalPosition(
        time_boot_ms=int(msg.time_boot_ms),
        pos_enu_m=(msg.y, msg.x, -msg.z),
        vel_enu_m_s=(msg.vy, msg.vx, -msg.vz),
    )


def decode_attitude(msg) -> Attitude:
    """ATTITUDE (Z-Y-X Euler angles of body FRD in NED, rad) -> ``R_enu_flu``."""
    R_ned_frd = frames.euler_zyx2rotmat(msg.roll, msg.pitch, msg.yaw)
    return Attitude(int(msg.time_boot_ms), frames.R_ned_frd2enu_flu(R_ned_frd))


def decode_attitude_quaternion(msg) -> Attitude:
    """ATTITUDE_QUATERNION ([w, x, y, z], body FRD -> NED) -> ``R_enu_flu``."""
    R_ned_frd = frames.quat_wxyz2rotmat((msg.q1, msg.q2, msg.q3, msg.q4))
    return Attitude(int(msg.time_boot_ms), frames.R_ned_frd2enu_flu(R_ned_frd))


def decode_param_value(msg, bytewise: bool = True) -> float | int:
    """PARAM_VALUE's value: INT32 parameters travel byte-wise in the float field
    (PX4's convention, MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE); ``bytewise``
    False: as a C cast to float (ArduPilot's, PARAM_ENCODE_C_CAST)."""
    if not bytewise:
        return int(msg.param_value) if int(msg.param_type) == mavlink.MAV_PARAM_TYPE_INT32 else float(msg.param_value)
    if int(msg.param_type) == mavlink.MAV_PARAM_TYPE_INT32:
        return struct.unpack("<i", struct.pack("<f", float(msg.param_value)))[0]
    return float(msg.param_value)


def decode_heartbeat(msg) -> VehicleState:
    """HEARTBEAT -> armed flag and PX4 custom main/sub mode."""
    custom = int(msg.custom_mode)
    return VehicleState(
        armed=bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED),
        main_mode=(custom >> 16) & 0xFF,
        sub_mode=(custom >> 24) & 0xFF,
        system_status=int(msg.system_status),
    )


#: MAV_SENSOR_ORIENTATION -> (roll, pitch, yaw) degrees of the sensor frame
#: in body FRD (MAVLink's definition): the yaw-only rotations and the
#: vertical ones a rangefinder uses.
SENSOR_ORIENTATION_EULER_DEG = {
    **{k: (0.0, 0.0, 45.0 * k) for k in range(8)},   # NONE (forward), YAW_45 .. YAW_315
    24: (0.0, 90.0, 0.0),                             # PITCH_90: up
    25: (0.0, 270.0, 0.0),                            # PITCH_270: down
}
MAV_SENSOR_ROTATION_CUSTOM = mavlink.MAV_SENSOR_ROTATION_CUSTOM


def _sensor_R_flu(R_frd) -> tuple:
    R = frames.R_frd2flu(R_frd)
    R[np.abs(R) < 1e-15] = 0.0
    return tuple(R.ravel().tolist())


_SENSOR_R_FLU = {k: _sensor_R_flu(frames.euler_zyx2rotmat(*np.radians(e)))
                 for k, e in SENSOR_ORIENTATION_EULER_DEG.items()}


def sensor_rotation_flu(orientation: int, quaternion_wxyz=None) -> tuple | None:
    """Rotation sensor (FLU convention) -> body FLU, row-major 9-tuple, or None.

    Parameters
    ----------
    orientation : int
        MAV_SENSOR_ORIENTATION: 0..7 (yaw k 45 deg, turning from forward to
        the right as in FRD), 24 (PITCH_90, up), 25 (PITCH_270, down) or 100
        (MAV_SENSOR_ROTATION_CUSTOM).
    quaternion_wxyz : sequence of 4 floats, optional
        DISTANCE_SENSOR.quaternion: the sensor's rotation in body FRD
        ([w, x, y, z], zero rotation = along body x), used with CUSTOM;
        all zeros (MAVLink's "invalid") or non-finite gives None.
    """
    if orientation == MAV_SENSOR_ROTATION_CUSTOM:
        if quaternion_wxyz is None:
            return None
        q = [float(c) for c in quaternion_wxyz]
        if len(q) != 4 or not all(math.isfinite(c) for c in q) or sum(c * c for c in q) < 0.25:
            return None
        # A rangefinder ring sends the same few quaternions with every reading: the
        # rotation is cached by the quaternion's exact bits (a tuple result, immutable).
        key = _Q4.pack(*q)
        R = _CUSTOM_R_FLU.get(key)
        if R is None:
            R = _sensor_R_flu(frames.quat_wxyz2rotmat(q))
            if len(_CUSTOM_R_FLU) >= _CUSTOM_CACHE_MAX:
                _CUSTOM_R_FLU.clear()
            _CUSTOM_R_FLU[key] = R
        return R
    return _SENSOR_R_FLU.get(int(orientation))


_Q4 = struct.Struct("<4d")
#: quaternion bits -> rotation of MAV_SENSOR_ROTATION_CUSTOM sensors (bounded: cleared when full)
_CUSTOM_R_FLU: dict = {}
_CUSTOM_CACHE_MAX = 256


def decode_distance_sensor(msg) -> Range:
    """DISTANCE_SENSOR (cm on the wire, sensor rotation in FRD) -> ``Range`` (m, body FLU).

    A reading beyond ``max_distance`` (PX4 and the bundled SITL send
    ``max_distance + 1`` for "no return") or below ``min_distance`` decodes
    to NaN (the first with ``no_return``); a reading of exactly
    ``max_distance`` is a valid range, as in PX4. ``covariance`` is cm^2
    (255: unknown).
    """
    d_cm, lo_cm, hi_cm = msg.current_distance, msg.min_distance, msg.max_distance
    d_m = d_cm / 100.0 if lo_cm <= d_cm <= hi_cm else math.nan
    cov = int(msg.covariance)
    orientation = int(msg.orientation)
    q = msg.quaternion if orientation == MAV_SENSOR_ROTATION_CUSTOM else None
    return Range(int(msg.time_boot_ms), int(msg.id), d_m, lo_cm / 100.0, hi_cm / 100.0, orientation,
                 float(msg.horizontal_fov), float(msg.vertical_fov),
                 math.nan if cov == 255 else cov * 1e-4, d_cm > hi_cm, sensor_rotation_flu(orientation, q))


def decode_odometry(msg) -> TruthState:
    """ODOMETRY (pose in MAV_FRAME_LOCAL_NED, velocity in MAV_FRAME_BODY_FRD) -> ENU/FLU.

    The bundled SITL sends its ground truth this way (float32 metres, so
    the position keeps micrometre resolution, unlike SIM_STATE's 1e-7
    degree latitude/longitude, about 1 cm). A velocity in
    MAV_FRAME_LOCAL_NED (child frame) is accepted as well. Plain float
    arithmetic (it runs every frame): ``R_enu_flu = T_en R_ned_frd T_fb``
    written out, checked against ``mavcore.frames`` by the tests.
    """
    w, x, y, z = msg.q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    # R_ned_frd from the quaternion (Hamilton, body -> world)
    r00, r01, r02 = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    r10, r11, r12 = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    vx, vy, vz = msg.vx, msg.vy, msg.vz
    if msg.child_frame_id == MAV_FRAME_LOCAL_NED:
        vn, ve, vd = vx, vy, vz
    else:
        vn = r00 * vx + r01 * vy + r02 * vz
        ve = r10 * vx + r11 * vy + r12 * vz
        vd = r20 * vx + r21 * vy + r22 * vz
    R = np.array(((r10, -r11, -r12), (r00, -r01, -r02), (-r20, r21, r22)))
    return TruthState(int(msg.time_usec), (msg.y, msg.x, -msg.z), (ve, vn, -vd), R)


def decode_odometry_pose(msg) -> tuple:
    """Position and attitude of an ODOMETRY, as floats (the runner's per-frame
    ground truth: ``decode_odometry`` without the velocity and the array).

    Returns
    -------
    (pos_enu_m, R_enu_flu) : a 3-tuple (m) and the rotation body FLU -> world
    ENU as a row-major 9-tuple; the same numbers as ``decode_odometry``.
    """
    w, x, y, z = msg.q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    r00, r01, r02 = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    r10, r11, r12 = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    return (msg.y, msg.x, -msg.z), (r10, -r11, -r12, r00, -r01, -r02, -r20, r21, r22)


def encode_odometry_truth(mav, time_usec: int, pos_enu_m, vel_enu_m_s, R_enu_flu, omega_flu_rad_s):
    """ODOMETRY carrying a true state (the inverse of ``decode_odometry``; tests and tools).

    Pose in MAV_FRAME_LOCAL_NED, velocity and rates in MAV_FRAME_BODY_FRD,
    covariances unknown (NaN first element), estimator MAV_ESTIMATOR_TYPE_UNKNOWN.
    """
    R_ned_frd = frames.R_enu_flu2ned_frd(R_enu_flu)
    p = frames.enu2ned(pos_enu_m)
    v_frd = R_ned_frd.T @ frames.enu2ned(vel_enu_m_s)
    w = frames.flu2frd(omega_flu_rad_s)
    q = frames.rotmat2quat_wxyz(R_ned_frd)
    cov = [math.nan] + [0.0] * 20
    return mav.odometry_encode(
        int(time_usec), MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD,
        float(p[0]), float(p[1]), float(p[2]), [float(c) for c in q],
        float(v_frd[0]), float(v_frd[1]), float(v_frd[2]), float(w[0]), float(w[1]), float(w[2]),
        cov, cov, 0, mavlink.MAV_ESTIMATOR_TYPE_UNKNOWN, 100)


# --- encoders ---------------------------------------------------------------


def encode_set_attitude_rates(mav, time_boot_ms: int, rates_flu_rad_s, thrust: float,
                              target_system: int = 1, target_component: int = 1):
    """SET_ATTITUDE_TARGET as a body-rate setpoint: rates and collective thrust, attitude ignored.

    Parameters
    ----------
    mav : pymavlink MAVLink
    time_boot_ms : int
        Vehicle time of the setpoint (ms).
    rates_flu_rad_s : sequence (3,)
        Body rates (rad/s), FLU; sent FRD: ``(p, -q, -r)`` (``frames.flu2frd``).
    thrust : float
        Collective thrust normalised to [0, 1] (``companion.control.rates.normalised_thrust``).

    Returns
    -------
    MAVLink_set_attitude_target_message
        ``type_mask`` = ATTITUDE_IGNORE, ``q`` = (1, 0, 0, 0) (ignored).
    """
    w = rates_flu_rad_s
    return mav.set_attitude_target_encode(
        int(time_boot_ms) & 0xFFFFFFFF, target_system, target_component, ATTITUDE_TARGET_RATES_ONLY,
        (1.0, 0.0, 0.0, 0.0), float(w[0]), -float(w[1]), -float(w[2]), float(thrust))


def encode_set_position_target(mav, time_boot_ms: int, pos_enu_m, vel_enu_m_s, acc_enu_m_s2,
                               yaw_enu_rad: float, target_system: int = 1, target_component: int = 1):
    """SET_POSITION_TARGET_LOCAL_NED from an ENU setpoint.

    Parameters
    ----------
    mav : pymavlink MAVLink
        Protocol object of the connection (``conn.mav``).
    time_boot_ms : int
        Vehicle time of the setpoint (ms since the vehicle's boot).
    pos_enu_m, vel_enu_m_s, acc_enu_m_s2 : array_like (3,)
        Reference position (m), velocity (m/s), acceleration (m/s^2), ENU.
    yaw_enu_rad : float
        Heading of the body x axis in ENU (from east, counter-clockwise).

    Returns
    -------
    MAVLink_set_position_target_local_ned_message
        ``MAV_FRAME_LOCAL_NED``, type_mask using position, velocity,
        acceleration and yaw (yaw rate ignored).
    """
    # ENU -> NED is (y, x, -z) (``frames.enu2ned``), written out: it runs at
    # the setpoint rate and the tests check it against ``frames``.
    p, v, a = pos_enu_m, vel_enu_m_s, acc_enu_m_s2
    return mav.set_position_target_local_ned_encode(
        int(time_boot_ms) & 0xFFFFFFFF, target_system, target_component, MAV_FRAME_LOCAL_NED,
        TYPE_MASK_POS_VEL_ACC_YAW,
        float(p[1]), float(p[0]), -float(p[2]),
        float(v[1]), float(v[0]), -float(v[2]),
        float(a[1]), float(a[0]), -float(a[2]),
        float(frames.yaw_enu2ned(yaw_enu_rad)), 0.0,
    )


def decode_position_target_local_ned(msg):
    """(POSITION|SET_POSITION)_TARGET_LOCAL_NED -> (pos_enu_m, vel_enu_m_s, acc_enu_m_s2, yaw_enu_rad).

    The inverse of ``encode_set_position_target`` (used by tests and replay).
    """
    return (
        frames.ned2enu((msg.x, msg.y, msg.z)),
        frames.ned2enu((msg.vx, msg.vy, msg.vz)),
        frames.ned2enu((msg.afx, msg.afy, msg.afz)),
        frames.yaw_ned2enu(msg.yaw),
    )


def encode_mission_item_int(mav, seq: int, pos_enu_m, home_lat_deg: float, home_lon_deg: float,
                            home_alt_m: float, target_system: int = 1, target_component: int = 1,
                            current: bool = False):
    """MISSION_ITEM_INT (NAV_WAYPOINT, ``MAV_FRAME_GLOBAL_INT``) from an ENU way-point.

    Parameters
    ----------
    pos_enu_m : array_like (3,)
        Way-point about the mission home, ENU, m.
    home_lat_deg, home_lon_deg, home_alt_m : float
        Geodetic pose of the mission home (the map origin), WGS-84, m AMSL.

    Notes
    -----
    The altitude is AMSL (``home_alt_m + z``), so the item does not depend
    on where the vehicle happened to set its own home.
    """
    x, y, z = (float(c) for c in pos_enu_m)
    lat, lon, alt = frames.enu2geodetic(x, y, z, home_lat_deg, home_lon_deg, home_alt_m)
    return mav.mission_item_int_encode(
        target_system, target_component, seq, MAV_FRAME_GLOBAL_INT, mavlink.MAV_CMD_NAV_WAYPOINT,
        1 if current else 0, 1, 0.0, 0.0, 0.0, math.nan,
        int(round(lat * 1e7)), int(round(lon * 1e7)), float(alt), mavlink.MAV_MISSION_TYPE_MISSION,
    )


def encode_mission_item(mav, seq: int, item, target_system: int = 1, target_component: int = 1,
                        mission_type: int = mavlink.MAV_MISSION_TYPE_MISSION, current: bool = False):
    """MISSION_ITEM_INT from a ``companion.mission_items.MissionItem`` (degrees, m AMSL).

    Latitude/longitude become 1e7 degrees here (the only place they may).
    ``mission_type``: MAV_MISSION_TYPE_MISSION or MAV_MISSION_TYPE_FENCE.
    """
    p1, p2, p3, p4 = (float(v) for v in item.params)
    return mav.mission_item_int_encode(
        target_system, target_component, seq, int(item.frame), int(item.command), 1 if current else 0,
        1 if item.autocontinue else 0, p1, p2, p3, p4,
        int(round(item.lat_deg * 1e7)), int(round(item.lon_deg * 1e7)), float(item.alt_m), mission_type,
    )


def decode_mission_item_int(msg, home_lat_deg: float, home_lon_deg: float, home_alt_m: float) -> np.ndarray:
    """MISSION_ITEM_INT in ``MAV_FRAME_GLOBAL_INT`` -> ENU way-point (3,) m about home."""
    x, y, z = frames.geodetic2enu(msg.x * 1e-7, msg.y * 1e-7, float(msg.z), home_lat_deg, home_lon_deg, home_alt_m)
    return np.array((x, y, z))


def encode_hil_actuator_controls(mav, time_usec: int, motor_cmd, armed: bool):
    """HIL_ACTUATOR_CONTROLS answering one lockstep sensor frame.

    Parameters
    ----------
    time_usec : int
        The ``time_usec`` of the HIGHRES_IMU being answered.
    motor_cmd : sequence of 4 floats or None
        Normalised motor commands 0..1 in PX4 quad-X order
        (``mavcore.vehicle``); None sends four NaN: a lockstep tick that
        leaves the vehicle's own controller in charge.
    armed : bool
        Sets ``MAV_MODE_FLAG_SAFETY_ARMED`` in ``mode``.
    """
    if motor_cmd is None:
        controls = _NAN16
    else:
        m0, m1, m2, m3 = motor_cmd
        controls = (float(m0), float(m1), float(m2), float(m3)) + (0.0,) * 12
    mode = mavlink.MAV_MODE_FLAG_HIL_ENABLED | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
    return mav.hil_actuator_controls_encode(int(time_usec), controls, mode, HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP)


def px4_custom_mode(main_mode: int, sub_mode: int = 0) -> int:
    """PX4 custom_mode value of a main/sub mode pair."""
    return (main_mode << 16) | (sub_mode << 24)


@dataclass(frozen=True, slots=True)
class GlobalPosition:
    """GLOBAL_POSITION_INT in SI units and ENU.

    Attributes
    ----------
    time_boot_ms : int
    lat_deg, lon_deg : float
        WGS-84 (1e-7 degree resolution on the wire: about 1.1 cm north, less east).
    alt_m : float
        Altitude AMSL (m).
    relative_alt_m : float
        Altitude above the vehicle's home (m).
    vel_enu_m_s : tuple (3,)
        Ground velocity, ENU, m/s (cm/s resolution on the wire).
    """

    time_boot_ms: int
    lat_deg: float
    lon_deg: float
    alt_m: float
    relative_alt_m: float
    vel_enu_m_s: tuple


@dataclass(frozen=True, slots=True)
class HomePosition:
    """HOME_POSITION: the vehicle's home, geodetic and in its local frame.

    Attributes
    ----------
    lat_deg, lon_deg, alt_m : float
        WGS-84, altitude AMSL (m).
    pos_enu_m : tuple (3,)
        The home in the vehicle's local frame (ENU, m).
    """

    lat_deg: float
    lon_deg: float
    alt_m: float
    pos_enu_m: tuple


def decode_home_position(msg) -> HomePosition:
    """HOME_POSITION (1e7 deg, mm, local NED) -> ``HomePosition`` (deg, m, ENU)."""
    return HomePosition(msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3, (msg.y, msg.x, -msg.z))


def decode_global_position_int(msg) -> GlobalPosition:
    """GLOBAL_POSITION_INT (1e7 deg, mm, cm/s NED) -> ``GlobalPosition`` (deg, m, m/s ENU)."""
    return GlobalPosition(int(msg.time_boot_ms), msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3,
                          msg.relative_alt * 1e-3, (msg.vy * 0.01, msg.vx * 0.01, -msg.vz * 0.01))


# --- fast MAVLink 2 framing of the per-frame messages ---------------------------
#
# In lockstep every sensor frame is one datagram (LOCAL_POSITION_NED, ODOMETRY,
# DISTANCE_SENSOR, HIGHRES_IMU) answered by one HIL_ACTUATOR_CONTROLS. pymavlink
# parses byte by byte and builds a generic message object per packet; doing
# those few types with one precompiled ``struct.Struct`` each, after the same
# framing and CRC checks, is several times cheaper. Everything else (and any
# packet that does not frame or CRC-check) still goes through pymavlink.

try:   # the CRC implementation pymavlink itself uses when fastcrc is installed
    from fastcrc import crc16 as _fastcrc16
    _mcrf4xx = _fastcrc16.mcrf4xx
except ImportError:   # pragma: no cover - pymavlink's pure Python CRC
    _mcrf4xx = None

_V2_HEADER = struct.Struct("<BBBBBBBBBB")
_CRC16 = struct.Struct("<H")


def x25_crc(data: bytes) -> int:
    """MAVLink's CRC-16/MCRF4XX (X.25) of ``data`` (include the crc_extra byte)."""
    if _mcrf4xx is not None:
        return _mcrf4xx(data, 0xFFFF)
    return mavlink.x25crc(data).crc   # pragma: no cover


class FastMessage(tuple):
    """A decoded packet of one of the per-frame types: a tuple of the field
    values in wire order (arrays as lists, as pymavlink gives them) followed by
    system id, component id and the raw packet; fields read by name like a
    pymavlink message (``m.xacc``, ``m.get_type()``, ``m.get_msgbuf()``)."""

    __slots__ = ()
    # underscored: a field may be called ``id`` (HIGHRES_IMU, DISTANCE_SENSOR)
    _msgname = ""
    _msgid = -1
    _fieldnames: tuple = ()

    def get_type(self) -> str:
        return self._msgname

    def get_msgId(self) -> int:
        return self._msgid

    def get_srcSystem(self) -> int:
        return self[-3]

    def get_srcComponent(self) -> int:
        return self[-2]

    def get_msgbuf(self) -> bytes:
        return self[-1]

    def get_seq(self) -> int:
        return self[-1][4]

    def get_fieldnames(self) -> list:
        return list(self._fieldnames)

    def to_dict(self) -> dict:
        d = {"mavpackettype": self._msgname}
        d.update((k, getattr(self, k)) for k in self._fieldnames)
        return d

    def __repr__(self) -> str:
        return f"{self._msgname} {{{', '.join(f'{k} : {getattr(self, k)}' for k in self._fieldnames)}}}"


def _array_field(a: int, b: int, name: str) -> property:
    """An array field: a fresh list of the flat values a..b (built only when read)."""
    return property(lambda self: list(self[a:b]), doc=f"field {name}")


class FastDecoder:
    """struct decoder of one message type (``msg_class``: pymavlink's class).

    The message is the flat unpacked tuple (then system id, component id,
    packet); an array field (ODOMETRY's ``q`` and covariances) is a list made
    from its slice of that tuple when it is read, not at every decode.
    """

    def __init__(self, msg_class) -> None:
        self.msgid = int(msg_class.id)
        self.crc_extra = bytes((int(msg_class.crc_extra),))
        self.unpacker = msg_class.unpacker
        self.size = int(msg_class.unpacker.size)
        names = tuple(msg_class.ordered_fieldnames)
        lengths = tuple(int(k) for k in msg_class.array_lengths)
        types = dict(zip(msg_class.fieldnames, msg_class.fieldtypes))
        attrs = {"__slots__": (), "_msgname": msg_class.msgname, "_msgid": self.msgid,
                 "_fieldnames": tuple(msg_class.fieldnames)}
        i = 0
        for n, k in zip(names, lengths):
            if k and types[n] == "char":
                raise ValueError(f"FastDecoder: {msg_class.msgname}.{n} is text (not supported)")
            if k:
                attrs[n] = _array_field(i, i + k, n)
                i += k
            else:
                attrs[n] = property(operator.itemgetter(i), doc=f"field {n}")
                i += 1
        self.cls = type("Fast_" + msg_class.msgname, (FastMessage,), attrs)

    def decode(self, packet: bytes, payload: bytes, sysid: int, compid: int) -> FastMessage:
        """Message from a framed, CRC-checked packet and its payload bytes."""
        n = len(payload)
        if n != self.size:   # MAVLink 2 zero truncation, or a longer (newer) payload
            payload = payload + bytes(self.size - n) if n < self.size else payload[:self.size]
        return tuple.__new__(self.cls, self.unpacker.unpack(payload) + (sysid, compid, packet))


#: The types decoded without pymavlink (the per-frame telemetry of a lockstep run; ATTITUDE
#: streams at 50 Hz while the replanner flies).
FAST_DECODERS = {d.msgid: d for d in (FastDecoder(c) for c in (
    mavlink.MAVLink_highres_imu_message, mavlink.MAVLink_local_position_ned_message,
    mavlink.MAVLink_odometry_message, mavlink.MAVLink_distance_sensor_message,
    mavlink.MAVLink_attitude_message))}


def split_datagram(data: bytes, fast: bool = True) -> list:
    """The MAVLink 2 packets of one UDP datagram, in order.

    ``FastMessage`` objects for the types of ``FAST_DECODERS`` and raw
    ``bytes`` for every other packet. A well-framed unsigned packet with a
    good CRC is one item; at the first byte that does not start one
    (MAVLink 1, signed packets, garbage, bad CRC, unknown id, truncation)
    the rest of the datagram is one ``bytes`` item for pymavlink's robust
    parser, so garbage is handled exactly as before. ``fast=False`` gives
    every good packet as bytes. (A list, not a generator: it runs for every
    frame and a generator's resumptions cost more than the list.)
    """
    n = len(data)
    i = 0
    out = []
    decoders = FAST_DECODERS if fast else {}
    mmap = mavlink.mavlink_map
    crc = _mcrf4xx if _mcrf4xx is not None else (lambda b, _init: x25_crc(b))
    while i < n:
        if n - i < 12 or data[i] != 0xFD or data[i + 2] != 0:
            out.append(data[i:])
            return out
        end = i + 12 + data[i + 1]
        if end > n:
            out.append(data[i:])
            return out
        msgid = data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16
        dec = decoders.get(msgid)
        if dec is not None:
            extra = dec.crc_extra
        else:
            cls = mmap.get(msgid)
            if cls is None:
                out.append(data[i:])
                return out
            extra = bytes((cls.crc_extra,))
        if crc(data[i + 1:end - 2] + extra, 0xFFFF) != (data[end - 2] | data[end - 1] << 8):
            out.append(data[i:])
            return out
        packet = data[i:end]
        if dec is not None:
            out.append(dec.decode(packet, data[i + 10:end - 2], data[i + 5], data[i + 6]))
        else:
            out.append(packet)
        i = end
    return out


_HIL_PAYLOAD = struct.Struct("<QQ16fB")
_HIL_ID = int(mavlink.MAVLink_hil_actuator_controls_message.id)
_HIL_CRC_EXTRA = bytes((int(mavlink.MAVLink_hil_actuator_controls_message.crc_extra),))
_MODE_ARMED = mavlink.MAV_MODE_FLAG_HIL_ENABLED | mavlink.MAV_MODE_FLAG_SAFETY_ARMED
_MODE_DISARMED = mavlink.MAV_MODE_FLAG_HIL_ENABLED
_ZERO12 = (0.0,) * 12


def hil_actuator_controls_payload(time_usec: int, motor_cmd, armed: bool) -> bytes:
    """The MAVLink 2 payload (zero-truncated, as on the wire) of
    ``encode_hil_actuator_controls(mav, time_usec, motor_cmd, armed)``."""
    mode = _MODE_ARMED if armed else _MODE_DISARMED
    if motor_cmd is None:
        payload = _HIL_PAYLOAD.pack(time_usec, HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP, *_NAN16, mode)
    else:
        m0, m1, m2, m3 = motor_cmd
        payload = _HIL_PAYLOAD.pack(time_usec, HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP, m0, m1, m2, m3, *_ZERO12,
                                    mode)
    return payload.rstrip(b"\0") or b"\0"   # MAVLink 2 trailing-zero truncation


def pack_hil_actuator_controls(seq: int, system_id: int, component_id: int, time_usec: int, motor_cmd,
                               armed: bool) -> bytes:
    """The packet of ``encode_hil_actuator_controls(...)`` framed as pymavlink
    would (unsigned MAVLink 2, sequence ``seq``), without a message object:
    byte-identical to ``msg.pack(mav)`` (tested)."""
    payload = hil_actuator_controls_payload(time_usec, motor_cmd, armed)
    head = _V2_HEADER.pack(0xFD, len(payload), 0, 0, seq, system_id, component_id, _HIL_ID & 0xFF,
                           (_HIL_ID >> 8) & 0xFF, _HIL_ID >> 16)
    body = head + payload
    return body + _CRC16.pack(x25_crc(body[1:] + _HIL_CRC_EXTRA))
