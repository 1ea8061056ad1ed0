"""Frame and unit conversions: the only place where NED/FRD math is written.

Inside the project everything is ENU world / FLU body, z up, SI units
(docs/frames.md). MAVLink speaks NED world / FRD body, [w, x, y, z] quaternions,
1e7 degrees, mm and cm. The MAVLink encode/decode module of each side
(``mavcore.codec``, ``mavcore.codec``) calls these functions and nothing
else does.

Conventions
-----------
- ENU -> NED: (x, y, z) -> (y, x, -z). The map is its own inverse.
- FLU -> FRD: (x, y, z) -> (x, -y, -z). Also an involution.
- Attitude: ``R_enu_flu`` maps body FLU vectors to world ENU vectors.
  The equivalent NED/FRD rotation is ``R_ned_frd = T_ne @ R_enu_flu @ T_fb``
  with the two constant permutation/reflection matrices below.
- Quaternions on the wire are [w, x, y, z] (Hamilton, body FRD -> world NED).
- Geodetic: the local tangent plane at the mission home (geodetic -> ECEF ->
  ENU on the WGS-84 ellipsoid, through pyproj: ``mavcore.geodesy``).
"""

from __future__ import annotations

import math

import numpy as np

from . import geodesy as _geodesy

# Constant frame maps (each is its own inverse).
T_ENU_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
T_FLU_FRD = np.diag([1.0, -1.0, -1.0])


def enu2ned(v_enu):
    """ENU vector(s) (..., 3) -> NED vector(s) (..., 3)."""
    v = np.asarray(v_enu, dtype=float)
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], axis=-1)


def ned2enu(v_ned):
    """NED vector(s) (..., 3) -> ENU vector(s) (..., 3)."""
    return enu2ned(v_ned)


def flu2frd(v_flu):
    """FLU body vector(s) (..., 3) -> FRD body vector(s) (..., 3)."""
    v = np.asarray(v_flu, dtype=float)
    return np.stack([v[..., 0], -v[..., 1], -v[..., 2]], axis=-1)


def frd2flu(v_frd):
    """FRD body vector(s) (..., 3) -> FLU body vector(s) (..., 3)."""
    return flu2frd(v_frd)


def R_enu_flu2ned_frd(R_enu_flu):
    """Attitude body FLU->world ENU (3x3) -> body FRD->world NED (3x3)."""
    return T_ENU_NED @ np.asarray(R_enu_flu, dtype=float) @ T_FLU_FRD


def R_ned_frd2enu_flu(R_ned_frd):
    """Attitude body FRD->world NED (3x3) -> body FLU->world ENU (3x3)."""
    return T_ENU_NED @ np.asarray(R_ned_frd, dtype=float) @ T_FLU_FRD


def R_frd2flu(R_frd_x):
    """A rotation into body FRD (3x3) -> the same rotation into body FLU.

    For a frame X attached to the body (a sensor) given in the FRD
    convention (x forward, y right, z down, both for X and for the body),
    ``R_flu_x = T_fb @ R_frd_x @ T_fb``: the rotation from X in the FLU
    convention (x forward, y left, z up) to body FLU. Its own inverse.
    """
    return T_FLU_FRD @ np.asarray(R_frd_x, dtype=float) @ T_FLU_FRD


def rotmat2quat_wxyz(R):
    """Rotation matrix (3x3, proper) -> unit quaternion [w, x, y, z], w >= 0.

    Shepperd's method (numerically safe for every rotation).
    """
    R = np.asarray(R, dtype=float)
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def quat_wxyz2rotmat(q):
    """Unit quaternion [w, x, y, z] -> rotation matrix (3x3). Normalises q."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def rotmat2euler_zyx(R):
    """Rotation matrix -> (roll, pitch, yaw) in rad, Z-Y-X (aerospace) order.

    For ``R_ned_frd`` this gives MAVLink's ATTITUDE angles.
    """
    R = np.asarray(R, dtype=float)
    roll = math.atan2(R[2, 1], R[2, 2])
    pitch = -math.asin(max(-1.0, min(1.0, R[2, 0])))
    yaw = math.atan2(R[1, 0], R[0, 0])
    return roll, pitch, yaw


def euler_zyx2rotmat(roll, pitch, yaw):
    """(roll, pitch, yaw) rad, Z-Y-X order -> rotation matrix."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def yaw_enu2ned(yaw_enu_rad):
    """Heading of the body x axis: ENU (from east, CCW) -> NED (from north, CW)."""
    return wrap_pi(math.pi / 2.0 - yaw_enu_rad)


def yaw_ned2enu(yaw_ned_rad):
    """Heading of the body x axis: NED (from north, CW) -> ENU (from east, CCW)."""
    return wrap_pi(math.pi / 2.0 - yaw_ned_rad)


def azimuth_flu2frd_deg(azimuth_flu_rad):
    """Body-horizontal direction: FLU azimuth (rad, from body x toward body y = left)
    -> FRD angle (deg, from forward, clockwise: OBSTACLE_DISTANCE's sectors)."""
    return -np.degrees(azimuth_flu_rad)


def angle_frd_deg2azimuth_flu(angle_frd_deg):
    """Inverse of ``azimuth_flu2frd_deg``: FRD angle (deg, clockwise) -> FLU azimuth (rad)."""
    return -np.radians(angle_frd_deg)


def wrap_pi(a):
    """Wrap an angle (rad) to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def enu2geodetic(x_east_m, y_north_m, z_up_m, lat0_deg, lon0_deg, alt0_m):
    """Local ENU (m) about a home point -> (lat_deg, lon_deg, alt_m).

    The local tangent plane at the home on the WGS-84 ellipsoid, through
    pyproj (``mavcore.geodesy``); the inverse of ``geodetic2enu``.
    """
    return _geodesy.enu2geodetic(x_east_m, y_north_m, z_up_m, lat0_deg, lon0_deg, alt0_m)


def geodetic2enu(lat_deg, lon_deg, alt_m, lat0_deg, lon0_deg, alt0_m):
    """(lat_deg, lon_deg, alt_m) -> local ENU (m) about a home point (``mavcore.geodesy``)."""
    return _geodesy.geodetic2enu(lat_deg, lon_deg, alt_m, lat0_deg, lon0_deg, alt0_m)
