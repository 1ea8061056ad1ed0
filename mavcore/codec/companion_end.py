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
import struct
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from mavcore import frames
from mavcore.link.command_rules import ATTITUDE_TARGET_RATES_ONLY


__all__ = ['MAV_FRAME_GLOBAL_INT', 'MAV_FRAME_LOCAL_NED', 'PX4_MAIN_MODE_MANUAL', 'PX4_MAIN_MODE_AUTO',
           'PX4_MAIN_MODE_OFFBOARD', 'PX4_SUB_MODE_AUTO_TAKEOFF', 'PX4_SUB_MODE_AUTO_LAND',
           'TYPE_MASK_POS_VEL_ACC_YAW', 'ImuSample', 'LocalPosition', 'Attitude', 'VehicleState', 'Range',
           'TruthState', 'decode_highres_imu', 'decode_local_position_ned', 'decode_attitude',
           'decode_attitude_quaternion', 'decode_param_value', 'decode_heartbeat', 'SENSOR_ORIENTATION_EULER_DEG',
           'MAV_SENSOR_ROTATION_CUSTOM', 'sensor_rotation_flu', 'decode_distance_sensor', 'decode_odometry',
           'decode_odometry_pose', 'encode_odometry_truth', 'encode_set_attitude_rates',
           'encode_set_position_target', 'decode_position_target_local_ned', 'GlobalPosition', 'HomePosition',
           'decode_home_position', 'decode_global_position_int']


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
