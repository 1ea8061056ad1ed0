"""Frame and sign consistency at the MAVLink edges (review R1).

One tilted, yawed, moving true state is built by hand (roll 10 deg, pitch
-20 deg, yaw 30 deg in the NED/FRD sense, i.e. ENU/FLU heading 60 deg,
rotation +20 deg about body left, +10 deg about body forward), every SITL
telemetry message is encoded with ``mavcore.codec``, framed to bytes and parsed
back with pymavlink, and each field is checked against values derived
independently of ``mavcore.frames`` (hand-worked axes, the standard
Euler->quaternion formula, the textbook degree-length series). Then the
companion's decoders are checked to be the inverses of the SITL's encoders,
the setpoint yaw conventions, the SITL's SET_POSITION_TARGET_LOCAL_NED frames
and type_mask, and the DISTANCE_SENSOR ray directions.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore import codec as ccodec
from mavcore import frames
from mavcore.mission.sim import NoiseConfig, RangefinderConfig, SimConfig
from companion.runner import setpoint_yaw_enu
from mavcore import codec as scodec
from sitl.sensors import Rangefinder, SensorSuite
from sitl.sim import Setpoint

D2R = math.pi / 180.0
G = 9.81
ROLL, PITCH, YAW = 10.0 * D2R, -20.0 * D2R, 30.0 * D2R     # NED/FRD Euler angles


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def hand_R_enu_flu(roll, pitch, yaw):
    """ENU/FLU attitude of NED/FRD Euler angles, derived without T matrices.

    Heading from east = 90 deg - yaw; a nose-up pitch about FRD right is the
    same turn with the opposite sign about FLU left; roll is about the shared
    forward axis, same sign (right wing down = left wing up).
    """
    return _rz(math.pi / 2 - yaw) @ _ry(-pitch) @ _rx(roll)


R_HAND = hand_R_enu_flu(ROLL, PITCH, YAW)
OMEGA_FLU = (0.1, 0.2, 0.3)          # rad/s about forward, left, up
POS_ENU = (100.0, 200.0, 15.0)       # 100 m east, 200 m north, 15 m up
VEL_ENU = (3.0, 4.0, -0.5)


def body_axes_ned(roll, pitch, yaw):
    """Body FRD axes (forward, right, down) in NED, from the aerospace formulas."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    fwd = np.array([cp * cy, cp * sy, -sp])
    right = np.array([sr * sp * cy - cr * sy, sr * sp * sy + cr * cy, sr * cp])
    down = np.array([cr * sp * cy + sr * sy, cr * sp * sy - sr * cy, cr * cp])
    return fwd, right, down


def ned_to_enu_hand(v):
    return np.array([v[1], v[0], -v[2]])


@pytest.fixture()
def mav():
    return mavlink.MAVLink(None, srcSystem=1, srcComponent=1)


def parse(buf: bytes):
    rx = mavlink.MAVLink(None)
    out = rx.parse_buffer(buf)
    assert out and len(out) == 1
    return out[0]


def wire(mav, msg):
    return parse(msg.pack(mav))


def qmul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def qrotate(q, v):
    """Rotate v by the Hamilton quaternion q (q v q*)."""
    qc = np.array([q[0], -q[1], -q[2], -q[3]])
    return qmul(qmul(q, np.concatenate([[0.0], v])), qc)[1:]


def hand_quat(roll, pitch, yaw):
    """[w, x, y, z] of Rz(yaw) Ry(pitch) Rx(roll), the standard half-angle formula."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


# --- 1. the SITL's telemetry of one hand-built state ---------------------------------


def test_hand_R_is_what_the_axes_say():
    """The hand ENU/FLU matrix maps body forward to the NED formula's forward."""
    fwd, right, down = body_axes_ned(ROLL, PITCH, YAW)
    np.testing.assert_allclose(R_HAND[:, 0], ned_to_enu_hand(fwd), atol=1e-12)
    np.testing.assert_allclose(R_HAND[:, 1], -ned_to_enu_hand(right), atol=1e-12)   # left = -right
    np.testing.assert_allclose(R_HAND[:, 2], -ned_to_enu_hand(down), atol=1e-12)    # up = -down
    # nose down 20 deg, heading 60 deg from east
    assert R_HAND[2, 0] == pytest.approx(-math.sin(20 * D2R))
    assert math.degrees(math.atan2(R_HAND[1, 0], R_HAND[0, 0])) == pytest.approx(60.0)


@pytest.mark.parametrize("fast", [False, True])
def test_attitude_euler_and_rates(mav, fast):
    args = scodec.attitude_args(77, R_HAND, OMEGA_FLU)
    m = parse(scodec.PACK_ATTITUDE.pack(mav, args)) if fast else wire(mav, scodec.attitude(mav, 77, R_HAND, OMEGA_FLU))
    assert m.time_boot_ms == 77
    assert (m.roll, m.pitch, m.yaw) == pytest.approx((ROLL, PITCH, YAW), abs=1e-6)
    # FRD rates: FLU (p, q, r) with q, r negated
    assert (m.rollspeed, m.pitchspeed, m.yawspeed) == pytest.approx((0.1, -0.2, -0.3), abs=1e-7)


@pytest.mark.parametrize("fast", [False, True])
def test_attitude_quaternion_is_frd_to_ned(mav, fast):
    args = scodec.attitude_quaternion_args(5, R_HAND, OMEGA_FLU)
    m = (parse(scodec.PACK_ATTITUDE_QUATERNION.pack(mav, args)) if fast
         else wire(mav, scodec.attitude_quaternion(mav, 5, R_HAND, OMEGA_FLU)))
    q = np.array([m.q1, m.q2, m.q3, m.q4])
    qh = hand_quat(ROLL, PITCH, YAW)
    np.testing.assert_allclose(q * np.sign(q[0]), qh * np.sign(qh[0]), atol=1e-6)
    fwd, right, down = body_axes_ned(ROLL, PITCH, YAW)
    np.testing.assert_allclose(qrotate(q, [1, 0, 0]), fwd, atol=1e-6)
    np.testing.assert_allclose(qrotate(q, [0, 1, 0]), right, atol=1e-6)
    np.testing.assert_allclose(qrotate(q, [0, 0, 1]), down, atol=1e-6)
    assert (m.rollspeed, m.pitchspeed, m.yawspeed) == pytest.approx((0.1, -0.2, -0.3), abs=1e-7)
    assert list(m.repr_offset_q) == [1.0, 0.0, 0.0, 0.0] or list(m.repr_offset_q) == [0.0] * 4


@pytest.mark.parametrize("fast", [False, True])
def test_local_position_ned(mav, fast):
    args = scodec.local_position_ned_args(9, POS_ENU, VEL_ENU)
    m = (parse(scodec.PACK_LOCAL_POSITION_NED.pack(mav, args)) if fast
         else wire(mav, scodec.local_position_ned(mav, 9, POS_ENU, VEL_ENU)))
    assert (m.x, m.y, m.z) == pytest.approx((200.0, 100.0, -15.0))
    assert (m.vx, m.vy, m.vz) == pytest.approx((4.0, 3.0, 0.5))


def test_global_position_int(mav):
    origin = scodec.GeoOrigin(45.0, 7.0, 250.0)
    home = (1.0, 2.0, 3.0)
    m = wire(mav, scodec.global_position_int(mav, 11, origin, home, POS_ENU, VEL_ENU,
                                             math.atan2(R_HAND[1, 0], R_HAND[0, 0])))
    # textbook series at 45 deg: 111132.954 - 559.822 cos 2phi + 1.175 cos 4phi m per degree of
    # latitude, 111412.84 cos phi - 93.5 cos 3phi + 0.118 cos 5phi per degree of longitude
    phi = 45.0 * D2R
    m_per_deg_lat = 111132.954 - 559.822 * math.cos(2 * phi) + 1.175 * math.cos(4 * phi)
    m_per_deg_lon = 111412.84 * math.cos(phi) - 93.5 * math.cos(3 * phi) + 0.118 * math.cos(5 * phi)
    assert m.lat == pytest.approx((45.0 + 200.0 / m_per_deg_lat) * 1e7, abs=3)   # 3e-7 deg ~ 3 cm
    assert m.lon == pytest.approx((7.0 + 100.0 / m_per_deg_lon) * 1e7, abs=3)
    # mm AMSL: 250 + 15 m, plus the tangent plane's rise over the ellipsoid 224 m out,
    # e^2 / 2(N + h) + n^2 / 2(M + h) = 100^2 / 12777.6 km + 200^2 / 12734.8 km = 3.9 mm
    assert m.alt == 265004
    assert m.relative_alt == 12000         # mm above home (15 - 3 m)
    assert (m.vx, m.vy, m.vz) == (400, 300, 50)     # cm/s NED: north 4, east 3, down 0.5
    assert m.hdg == 3000                   # NED yaw 30 deg in cdeg


@pytest.mark.parametrize("yaw_ned_deg, hdg", [(0.0, 0), (90.0, 9000), (-90.0, 27000), (180.0, 18000),
                                               (-30.0, 33000), (359.996, 0)])
def test_heading_cdeg_range(yaw_ned_deg, hdg):
    h = scodec.heading_cdeg(math.pi / 2 - yaw_ned_deg * D2R)
    assert h == hdg and 0 <= h <= 35999


def test_gps_raw_int_course_over_ground(mav):
    origin = scodec.GeoOrigin(45.0, 7.0, 250.0)
    m = wire(mav, scodec.gps_raw_int(mav, 1, origin, POS_ENU, VEL_ENU))
    assert m.vel == 500                                      # |(3, 4)| = 5 m/s
    assert m.cog == round(math.degrees(math.atan2(3.0, 4.0)) * 100)   # from north, clockwise: 36.87 deg
    m = wire(mav, scodec.gps_raw_int(mav, 1, origin, POS_ENU, (-1.0, 0.0, 0.0)))
    assert m.cog == 27000                                    # moving west
    assert m.alt == 265004                                   # as GLOBAL_POSITION_INT's


def test_home_position_local_ned(mav):
    origin = scodec.GeoOrigin(45.0, 7.0, 250.0)
    m = wire(mav, scodec.home_position(mav, origin, (1.0, 2.0, 3.0), 0))
    assert (m.x, m.y, m.z) == pytest.approx((2.0, 1.0, -3.0))
    assert m.altitude == 253000
    q = np.array(m.q)
    assert np.linalg.norm(q) == pytest.approx(1.0)          # a valid (identity) quaternion


@pytest.mark.parametrize("fast", [False, True])
def test_odometry_frames(mav, fast):
    fwd, right, down = body_axes_ned(ROLL, PITCH, YAW)
    # velocity 2 forward, 0.5 right, 0.3 down, expressed in ENU
    v_enu = ned_to_enu_hand(2.0 * fwd + 0.5 * right + 0.3 * down)
    if fast:
        m = parse(scodec.PACK_ODOMETRY.pack(mav, scodec.odometry_truth_args(123, POS_ENU, v_enu, R_HAND, OMEGA_FLU)))
    else:
        m = wire(mav, scodec.odometry_truth(mav, 123, POS_ENU, v_enu, R_HAND, OMEGA_FLU))
    assert m.frame_id == mavlink.MAV_FRAME_LOCAL_NED
    assert m.child_frame_id == mavlink.MAV_FRAME_BODY_FRD
    assert (m.x, m.y, m.z) == pytest.approx((200.0, 100.0, -15.0))
    qh = hand_quat(ROLL, PITCH, YAW)
    np.testing.assert_allclose(np.array(m.q) * np.sign(m.q[0]), qh * np.sign(qh[0]), atol=1e-6)
    assert (m.vx, m.vy, m.vz) == pytest.approx((2.0, 0.5, 0.3), abs=1e-6)
    assert (m.rollspeed, m.pitchspeed, m.yawspeed) == pytest.approx((0.1, -0.2, -0.3), abs=1e-7)
    assert math.isnan(m.pose_covariance[0]) and math.isnan(m.velocity_covariance[0])


def _quiet_suite(rangefinders=(), world=None):
    sim = SimConfig(noise=NoiseConfig(vector_variance=0.0, gyro_variance=0.0, range_std_m=0.0),
                    rangefinders=rangefinders, magnetic_field_enu_gauss=(0.0, 0.2, -0.4))
    return SensorSuite(sim, world, np.random.default_rng(0))


@pytest.mark.parametrize("roll_deg, pitch_deg, acc_frd", [
    (0.0, 0.0, (0.0, 0.0, -G)),      # level hover: the accelerometer reads "up" = -z FRD
    (90.0, 0.0, (0.0, -G, 0.0)),     # right wing down: body right points down, up = -right
    (0.0, 90.0, (G, 0.0, 0.0)),      # nose straight up: the forward axis points up
])
def test_highres_imu_specific_force_frd(mav, roll_deg, pitch_deg, acc_frd):
    """At rest (a = 0) the specific force is +g world up. In FRD, up = -down
    axis; with roll 90 the right axis points down, so up = -right: yacc = -g;
    with pitch +90 (nose up) the forward axis points up: xacc = +g."""
    R = hand_R_enu_flu(roll_deg * D2R, pitch_deg * D2R, 0.0)
    suite = _quiet_suite()
    a, w, b = suite.imu_tuples(tuple(R.ravel()), (0.0, 0.0, 0.0), OMEGA_FLU, G)
    m = parse(scodec.PACK_HIGHRES_IMU.pack(mav, scodec.highres_imu_args(1, a, w, b, 0.0)))
    assert (m.xacc, m.yacc, m.zacc) == pytest.approx(acc_frd, abs=1e-5)
    assert (m.xgyro, m.ygyro, m.zgyro) == pytest.approx((0.1, -0.2, -0.3), abs=1e-7)


def test_highres_imu_magnetometer_frd(mav):
    """Earth field 0.2 G north, 0.4 G down. Level, facing east (NED yaw 90):
    forward = east, right = south, down = down -> FRD (0, -0.2, 0.4)."""
    R = hand_R_enu_flu(0.0, 0.0, 90.0 * D2R)
    suite = _quiet_suite()
    a, w, b = suite.imu_tuples(tuple(R.ravel()), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), G)
    m = wire(mav, scodec.highres_imu(mav, 1, a, w, b, 0.0))
    assert (m.xmag, m.ymag, m.zmag) == pytest.approx((0.0, -0.2, 0.4), abs=1e-6)
    # and with the tilted state: the body components are the field dotted with the FRD axes
    a, w, b = suite.imu_tuples(tuple(R_HAND.ravel()), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), G)
    m = wire(mav, scodec.highres_imu(mav, 1, a, w, b, 0.0))
    field_ned = np.array([0.2, 0.0, 0.4])
    fwd, right, down = body_axes_ned(ROLL, PITCH, YAW)
    assert (m.xmag, m.ymag, m.zmag) == pytest.approx((field_ned @ fwd, field_ned @ right, field_ned @ down),
                                                      abs=1e-6)
    # specific force of the tilted hover: g up = -g along NED down, dotted with the FRD axes
    up_ned = np.array([0.0, 0.0, -G])
    assert (m.xacc, m.yacc, m.zacc) == pytest.approx((up_ned @ fwd, up_ned @ right, up_ned @ down), abs=1e-5)


# --- 2. companion decoders invert the SITL encoders -----------------------------------


def _random_R(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _fast(buf: bytes):
    (m,) = ccodec.split_datagram(buf)
    assert not isinstance(m, bytes)
    return m


def test_companion_decoders_invert_sitl_encoders(mav):
    rng = np.random.default_rng(20240601)
    for _ in range(50):
        R = _random_R(rng)
        p, v, w = rng.normal(size=3) * 50, rng.normal(size=3) * 5, rng.normal(size=3)
        acc, gyr, mag = rng.normal(size=3) * 10, rng.normal(size=3), rng.normal(size=3) * 0.5
        # ATTITUDE and ATTITUDE_QUATERNION (pymavlink path)
        att = ccodec.decode_attitude(wire(mav, scodec.attitude(mav, 1, R, w)))
        if abs(R[2, 0]) < 0.99:      # Euler angles are ill-conditioned near pitch +-90
            np.testing.assert_allclose(att.R_enu_flu, R, atol=2e-6)
        attq = ccodec.decode_attitude_quaternion(wire(mav, scodec.attitude_quaternion(mav, 1, R, w)))
        np.testing.assert_allclose(attq.R_enu_flu, R, atol=2e-6)
        # LOCAL_POSITION_NED and HIGHRES_IMU (the companion's fast decoder)
        lp = ccodec.decode_local_position_ned(_fast(scodec.PACK_LOCAL_POSITION_NED.pack(
            mav, scodec.local_position_ned_args(1, p, v))))
        np.testing.assert_allclose(lp.pos_enu_m, p, rtol=1e-6, atol=1e-5)
        np.testing.assert_allclose(lp.vel_enu_m_s, v, rtol=1e-6, atol=1e-6)
        imu = ccodec.decode_highres_imu(_fast(scodec.PACK_HIGHRES_IMU.pack(
            mav, scodec.highres_imu_args(7, acc, gyr, mag, 10.0))))
        assert imu.time_usec == 7
        np.testing.assert_allclose(imu.accel_flu_m_s2, acc, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(imu.gyro_flu_rad_s, gyr, rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose(imu.mag_flu_gauss, mag, rtol=1e-6, atol=1e-7)
        # ODOMETRY, both SITL encoders, full and pose-only companion decoders
        for buf in (scodec.PACK_ODOMETRY.pack(mav, scodec.odometry_truth_args(3, p, v, R, w)),
                    scodec.odometry_truth(mav, 3, p, v, R, w).pack(mav)):
            od = ccodec.decode_odometry(_fast(buf))
            np.testing.assert_allclose(od.pos_enu_m, p, rtol=1e-6, atol=1e-5)
            np.testing.assert_allclose(od.vel_enu_m_s, v, rtol=1e-5, atol=1e-5)
            np.testing.assert_allclose(od.R_enu_flu, R, atol=2e-6)
            pos, R9 = ccodec.decode_odometry_pose(_fast(buf))
            np.testing.assert_allclose(np.array(R9).reshape(3, 3), R, atol=2e-6)
            np.testing.assert_allclose(pos, p, rtol=1e-6, atol=1e-5)


def test_companion_distance_sensor_decode(mav):
    class Reading:
        sensor_id, orientation, min_m, max_m, hfov_rad, vfov_rad = 3, 25, 0.1, 20.0, 0.1, 0.1
        distance_m = 7.25
    r = ccodec.decode_distance_sensor(_fast(scodec.PACK_DISTANCE_SENSOR.pack(
        mav, scodec.distance_sensor_args(4, Reading))))
    assert (r.sensor_id, r.orientation, r.distance_m, r.min_m, r.max_m) == (3, 25, 7.25, 0.1, 20.0)
    Reading.distance_m = None
    r = ccodec.decode_distance_sensor(_fast(scodec.PACK_DISTANCE_SENSOR.pack(
        mav, scodec.distance_sensor_args(4, Reading))))
    assert math.isnan(r.distance_m)


@pytest.mark.parametrize("yaw_enu_deg, yaw_ned_deg", [(45.0, 45.0), (90.0, 0.0), (0.0, 90.0),
                                                      (180.0, -90.0), (-90.0, 180.0), (135.0, -45.0)])
def test_companion_setpoint_yaw_and_sitl_decode(mav, yaw_enu_deg, yaw_ned_deg):
    """Body x north-east (ENU 45) is NED 45; north (ENU 90) is NED 0; east is NED 90."""
    msg = wire(mav, ccodec.encode_set_position_target(mav, 10, (1.0, 2.0, 3.0), (0.1, 0.2, 0.3),
                                                      (0.01, 0.02, 0.03), yaw_enu_deg * D2R))
    assert msg.coordinate_frame == mavlink.MAV_FRAME_LOCAL_NED
    assert math.degrees(frames.wrap_pi(msg.yaw - yaw_ned_deg * D2R)) == pytest.approx(0.0, abs=1e-4)
    assert (msg.x, msg.y, msg.z) == pytest.approx((2.0, 1.0, -3.0))
    assert (msg.vx, msg.vy, msg.vz) == pytest.approx((0.2, 0.1, -0.3))
    assert (msg.afx, msg.afy, msg.afz) == pytest.approx((0.02, 0.01, -0.03))
    t = scodec.decode_position_target(msg)
    np.testing.assert_allclose(t.pos_enu_m, (1.0, 2.0, 3.0), atol=1e-6)
    np.testing.assert_allclose(t.vel_enu_m_s, (0.1, 0.2, 0.3), atol=1e-6)
    np.testing.assert_allclose(t.acc_enu_m_s2, (0.01, 0.02, 0.03), atol=1e-6)
    assert math.cos(t.yaw_enu_rad - yaw_enu_deg * D2R) == pytest.approx(1.0)
    assert t.yaw_rate_enu_rad_s is None            # the companion ignores yaw rate


@pytest.mark.parametrize("s, yaw_enu_deg", [((0.0, 1.0, 0.0), 0.0),     # point north: body left north, x east
                                            ((1.0, 0.0, 0.0), -90.0),   # point east: x south
                                            ((-1.0, 0.0, 0.0), 90.0),   # point west: x north
                                            ((0.0, -1.0, 0.0), 180.0)])
def test_runner_yaw_from_pointing_direction(mav, s, yaw_enu_deg):
    """b2d = pointing, b1d = b2d x b3d: the pointing direction is body +y (left)."""
    yaw = setpoint_yaw_enu(s, (0.0, 0.0, 0.0), G)
    assert math.cos(yaw - yaw_enu_deg * D2R) == pytest.approx(1.0)
    # body y = R e2 points along s
    R = _rz(yaw)
    np.testing.assert_allclose(R[:, 1], s, atol=1e-12)
    if s == (0.0, 1.0, 0.0):
        msg = wire(mav, ccodec.encode_set_position_target(mav, 0, (0, 0, 0), (0, 0, 0), (0, 0, 0), yaw))
        assert msg.yaw == pytest.approx(math.pi / 2)     # NED yaw +90: body x east


# --- 3. SITL decode of SET_POSITION_TARGET_LOCAL_NED -----------------------------------


def _sptl(mav, frame, mask, pos=(1.0, 2.0, -3.0), vel=(0.4, 0.5, -0.6), acc=(0.07, 0.08, -0.09),
          yaw=0.3, yaw_rate=0.2):
    return wire(mav, mav.set_position_target_local_ned_encode(0, 1, 1, frame, mask, *pos, *vel, *acc,
                                                               yaw, yaw_rate))


def test_type_mask_bits_are_ignore_flags(mav):
    F = mavlink.MAV_FRAME_LOCAL_NED
    t = scodec.decode_position_target(_sptl(mav, F, 0))
    np.testing.assert_allclose(t.pos_enu_m, (2.0, 1.0, 3.0), atol=1e-6)
    np.testing.assert_allclose(t.vel_enu_m_s, (0.5, 0.4, 0.6), atol=1e-6)
    np.testing.assert_allclose(t.acc_enu_m_s2, (0.08, 0.07, 0.09), atol=1e-6)
    assert t.yaw_enu_rad == pytest.approx(math.pi / 2 - 0.3)
    assert t.yaw_rate_enu_rad_s == pytest.approx(-0.2)        # clockwise seen from above = negative about up
    # velocity only (PX4 docs: 0b110111000111 = 3527 also ignores yaw and yaw rate);
    # here yaw ignored (bit 1024) but yaw rate used
    assert scodec.decode_position_target(_sptl(mav, F, 3527)).yaw_rate_enu_rad_s is None
    t = scodec.decode_position_target(_sptl(mav, F, 0b010111000111))
    assert np.all(np.isnan(t.pos_enu_m)) and np.all(np.isnan(t.acc_enu_m_s2))
    np.testing.assert_allclose(t.vel_enu_m_s, (0.5, 0.4, 0.6), atol=1e-6)
    assert t.yaw_enu_rad is None and t.yaw_rate_enu_rad_s is not None
    # bit 2048: yaw rate ignored; bit 512 (FORCE) ignores afx..afz
    t = scodec.decode_position_target(_sptl(mav, F, 2048 | 512))
    assert t.yaw_rate_enu_rad_s is None and np.all(np.isnan(t.acc_enu_m_s2))
    assert t.yaw_enu_rad is not None
    # per-axis: only north (x NED) position ignored -> ENU y is NaN
    t = scodec.decode_position_target(_sptl(mav, F, 1))
    assert math.isnan(t.pos_enu_m[1]) and t.pos_enu_m[0] == pytest.approx(2.0)


@pytest.mark.parametrize("frame", [mavlink.MAV_FRAME_LOCAL_OFFSET_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED,
                                   mavlink.MAV_FRAME_BODY_FRD, mavlink.MAV_FRAME_LOCAL_FRD,
                                   mavlink.MAV_FRAME_LOCAL_ENU, mavlink.MAV_FRAME_GLOBAL])
def test_unsupported_frames_are_rejected(mav, frame):
    assert scodec.decode_position_target(_sptl(mav, frame, 0), 0.7, (5.0, 6.0, 7.0)) is None


def test_body_ned_frame_hand_worked(mav):
    """Vehicle at ENU (5, 6, 7) heading north (ENU yaw 90). BODY_NED x forward =
    north, y right = east, z down: (1, 2, -3) -> ENU offset (2, 1, 3)."""
    msg = _sptl(mav, mavlink.MAV_FRAME_BODY_NED, 0, yaw=0.25)
    t = scodec.decode_position_target(msg, math.pi / 2, (5.0, 6.0, 7.0))
    np.testing.assert_allclose(t.pos_enu_m, (7.0, 7.0, 10.0), atol=1e-6)
    np.testing.assert_allclose(t.vel_enu_m_s, (0.5, 0.4, 0.6), atol=1e-6)
    np.testing.assert_allclose(t.acc_enu_m_s2, (0.08, 0.07, 0.09), atol=1e-6)
    # yaw is relative, clockwise: 0.25 rad right of north
    assert t.yaw_enu_rad == pytest.approx(math.pi / 2 - 0.25)
    # heading east (ENU yaw 0): forward = east, right = south
    t = scodec.decode_position_target(msg, 0.0, (0.0, 0.0, 0.0))
    np.testing.assert_allclose(t.pos_enu_m, (1.0, -2.0, 3.0), atol=1e-6)


def test_position_target_echo_roundtrip(mav):
    sp = Setpoint(pos_enu_m=np.array([1.0, 2.0, 3.0]), vel_enu_m_s=None, acc_enu_m_s2=None,
                  yaw_enu_rad=0.0, yaw_rate_rad_s=None)
    m = wire(mav, scodec.position_target_local_ned(mav, 1, sp))
    assert (m.x, m.y, m.z) == pytest.approx((2.0, 1.0, -3.0))
    assert m.yaw == pytest.approx(math.pi / 2)
    assert m.type_mask & scodec.TM_VEL == scodec.TM_VEL and m.type_mask & scodec.TM_YAW_RATE


# --- 4. DISTANCE_SENSOR orientations and ray directions --------------------------------


class _FlatGround:
    @staticmethod
    def height(x, y):
        return 0.0


class _Walls:
    """Hand-placed world: walls x = 10 (east) and y = 20 (north), ground z = 0 (the part of
    ``sitl.world.World``'s interface a rangefinder reads: the terrain's height, the obstacles
    within reach, and the ray cast given both)."""

    terrain = _FlatGround()

    @staticmethod
    def near_obstacles(ox, oy, oz, reach_m):
        return ()

    def raycast(self, ox, oy, oz, dx, dy, dz, max_m, ground_z=None, obstacles=None):
        best = math.inf
        for o, d, plane in ((ox, dx, 10.0), (oy, dy, 20.0), (oz, dz, 0.0)):
            if abs(d) > 1e-12:
                t = (plane - o) / d
                if 0.0 < t <= max_m:
                    best = min(best, t)
        return best


def test_orientation_enum_values():
    assert mavlink.MAV_SENSOR_ROTATION_NONE == 0
    assert mavlink.MAV_SENSOR_ROTATION_YAW_90 == 2
    assert mavlink.MAV_SENSOR_ROTATION_YAW_270 == 6
    assert mavlink.MAV_SENSOR_ROTATION_PITCH_90 == 24
    assert mavlink.MAV_SENSOR_ROTATION_PITCH_270 == 25


@pytest.mark.parametrize("yaw_enu_deg, expected", [
    # heading north: forward hits y=20 (20 m), right = east hits x=10 (10 m), left = west: nothing
    (90.0, {0: 20.0, 2: 10.0, 6: None, 25: 5.0, 1: 10.0 * math.sqrt(2)}),
    # heading east: forward hits x=10, left = north hits y=20, right = south: nothing
    (0.0, {0: 10.0, 2: None, 6: 20.0, 25: 5.0, 7: 10.0 * math.sqrt(2)}),
])
def test_distance_sensor_directions(mav, yaw_enu_deg, expected):
    cfgs = tuple(RangefinderConfig(id=o, orientation=o, max_m=30.0, hfov_deg=0.0, vfov_deg=0.0)
                 for o in expected)
    suite = _quiet_suite(cfgs, _Walls())
    R = _rz(yaw_enu_deg * D2R)
    p = (0.0, 0.0, 5.0)
    for rf in suite.rangefinders:
        reading = suite.range_reading(rf, p, tuple(R.ravel()))
        m = parse(scodec.PACK_DISTANCE_SENSOR.pack(mav, scodec.distance_sensor_args(1, reading)))
        assert m.orientation == rf.cfg.orientation and m.id == rf.cfg.id
        want = expected[rf.cfg.orientation]
        r = ccodec.decode_distance_sensor(m)
        if want is None:
            assert math.isnan(r.distance_m) and m.signal_quality == 1
        else:
            assert r.distance_m == pytest.approx(want, abs=0.006), rf.cfg.orientation


def test_down_sensor_on_tilted_vehicle_reads_slant_range(mav):
    """Roll 10 deg, pitch -20 deg at 5 m over flat ground: the down ray's
    vertical component is cos(roll) cos(pitch), so range = 5 / (cos r cos p)."""
    cfg = RangefinderConfig(id=3, orientation=25, max_m=30.0, hfov_deg=0.0, vfov_deg=0.0)
    suite = _quiet_suite((cfg,), _Walls())
    reading = suite.range_reading(suite.rangefinders[0], (0.0, 0.0, 5.0), tuple(R_HAND.ravel()))
    assert reading.distance_m == pytest.approx(5.0 / (math.cos(ROLL) * math.cos(PITCH)))
    assert isinstance(suite.rangefinders[0], Rangefinder)


# --- the simulator's own state through the wire ------------------------------------------


def test_simulation_heading_reaches_the_wire(mav):
    """A vehicle started landed with ENU heading 60 deg (NED 30 deg): ATTITUDE
    yaw 30 deg, GLOBAL_POSITION_INT hdg 3000, magnetometer = the Earth field
    (0.21 G north, 0.42 G down) on the FRD axes, accelerometer -g on FRD z."""
    import dataclasses
    from pathlib import Path

    from mavcore.mission import load_mission
    from sitl.sim import Simulation
    mission = load_mission(Path(__file__).resolve().parents[1] / "missions" / "flat-rectangle" / "mission.yaml")
    quiet = dataclasses.replace(mission.sim.noise, vector_variance=0.0, gyro_variance=0.0)
    mission = dataclasses.replace(mission, sim=dataclasses.replace(
        mission.sim, noise=quiet, magnetic_field_enu_gauss=(0.0, 0.21, -0.42)))
    sim = Simulation(mission, np.random.default_rng(0), start_yaw_rad=60.0 * D2R)
    f = sim.step_frame((0.0, 0.0, 0.0, 0.0))
    att = wire(mav, scodec.attitude(mav, 0, f.truth.R, f.truth.omega_flu_rad_s))
    assert math.degrees(att.yaw) == pytest.approx(30.0, abs=1e-4)
    origin = scodec.GeoOrigin(45.0, 7.0, 0.0)
    gp = wire(mav, scodec.global_position_int(mav, 0, origin, f.pos_enu_m, f.pos_enu_m, f.vel_enu_m_s,
                                              scodec.yaw_enu_of(f.truth.R)))
    assert gp.hdg == 3000
    imu = wire(mav, scodec.highres_imu(mav, f.time_us, f.accel_flu_m_s2, f.gyro_flu_rad_s, f.mag_flu_gauss, 0.0))
    c, s = math.cos(30 * D2R), math.sin(30 * D2R)
    # level, yaw 30 deg: forward = (c, s, 0) NED, right = (-s, c, 0), down = (0, 0, 1)
    assert (imu.xmag, imu.ymag, imu.zmag) == pytest.approx((0.21 * c, -0.21 * s, 0.42), abs=1e-6)
    assert (imu.xacc, imu.yacc, imu.zacc) == pytest.approx((0.0, 0.0, -G), abs=1e-4)


def test_hil_actuator_controls_companion_to_sitl(mav):
    """Motor order and values survive companion encode -> SITL decode (both paths)."""
    cmd = (0.1, 0.2, 0.3, 0.4)
    msg = wire(mav, ccodec.encode_hil_actuator_controls(mav, 4000, cmd, True))
    a = scodec.decode_actuator_controls(msg)
    assert a.time_usec == 4000 and a.lockstep and a.motor_cmd == pytest.approx(cmd)
    buf = ccodec.pack_hil_actuator_controls(0, 1, 191, 4000, cmd, True)
    b = scodec.decode_actuator_datagram(buf)
    assert b is not None and b.time_usec == 4000 and b.lockstep and b.motor_cmd == pytest.approx(cmd)
    none = scodec.decode_actuator_datagram(ccodec.pack_hil_actuator_controls(1, 1, 191, 5000, None, True))
    assert none.motor_cmd is None and none.lockstep
