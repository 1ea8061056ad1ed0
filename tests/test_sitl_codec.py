"""mavcore.codec: known points worked by hand, round trips against
mavcore.frames and pymavlink, type_mask decoding table."""

from __future__ import annotations

import dataclasses
import math
import struct
from pathlib import Path

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from mavcore import frames
from mavcore.mission import load_mission
from mavcore import codec
from sitl.sensors import RangeReading
from sitl.sim import Setpoint, Simulation

ROOT = Path(__file__).resolve().parents[1]
MISSION = ROOT / "missions" / "flat-rectangle" / "mission.yaml"
G = 9.81


@pytest.fixture()
def mav():
    return mavlink.MAVLink(None, srcSystem=1, srcComponent=1)


def roundtrip(mav, msg):
    """Pack with pymavlink and parse back (what a client sees)."""
    buf = msg.pack(mav)
    rx = mavlink.MAVLink(None)
    out = rx.parse_buffer(buf)
    assert out and len(out) == 1
    return out[0]


def test_local_position_known_point(mav):
    m = roundtrip(mav, codec.local_position_ned(mav, 1234, (1.0, 2.0, 3.0), (4.0, 5.0, 6.0)))
    assert (m.x, m.y, m.z) == (2.0, 1.0, -3.0)       # docs/frames.md: ENU (1, 2, 3) is NED (2, 1, -3)
    assert (m.vx, m.vy, m.vz) == (5.0, 4.0, -6.0)
    assert m.time_boot_ms == 1234


def test_local_position_matches_frames(mav):
    rng = np.random.default_rng(3)
    for _ in range(20):
        p, v = rng.normal(size=3) * 50, rng.normal(size=3) * 5
        m = roundtrip(mav, codec.local_position_ned(mav, 0, p, v))
        np.testing.assert_allclose([m.x, m.y, m.z], frames.enu2ned(p), rtol=1e-6, atol=1e-5)
        np.testing.assert_allclose([m.vx, m.vy, m.vz], frames.enu2ned(v), rtol=1e-6, atol=1e-5)


def test_highres_imu_at_rest_reads_minus_g_on_frd_z(mav):
    """A level vehicle at rest: specific force is +g up (FLU +z), i.e. zacc = -g in FRD."""
    mission = load_mission(MISSION)
    quiet = dataclasses.replace(mission.sim.noise, vector_variance=0.0, gyro_variance=0.0)
    mission = dataclasses.replace(mission, sim=dataclasses.replace(mission.sim, noise=quiet))
    sim = Simulation(mission, np.random.default_rng(0))
    f = sim.step_frame((0.0, 0.0, 0.0, 0.0))
    m = roundtrip(mav, codec.highres_imu(mav, f.time_us, f.accel_flu_m_s2, f.gyro_flu_rad_s,
                                         f.mag_flu_gauss, 30.0))
    assert m.zacc == pytest.approx(-G, abs=1e-5)
    assert m.xacc == pytest.approx(0.0, abs=1e-6) and m.yacc == pytest.approx(0.0, abs=1e-6)
    assert (m.xgyro, m.ygyro, m.zgyro) == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    assert m.time_usec == f.time_us == sim.sensor_period_us
    # ISA at 30 m AMSL: 1013.25 (1 - 0.0065 * 30 / 288.15)^5.25588 = 1009.65 hPa
    assert m.abs_pressure == pytest.approx(1013.25 * (1 - 0.0065 * 30 / 288.15) ** 5.25588, rel=1e-6)
    assert m.pressure_alt == pytest.approx(30.0)


def test_highres_imu_vectors_match_frames(mav):
    rng = np.random.default_rng(4)
    a, w, b = rng.normal(size=(3, 3))
    m = roundtrip(mav, codec.highres_imu(mav, 42, a, w, b, 0.0))
    np.testing.assert_allclose([m.xacc, m.yacc, m.zacc], frames.flu2frd(a), rtol=1e-6)
    np.testing.assert_allclose([m.xgyro, m.ygyro, m.zgyro], frames.flu2frd(w), rtol=1e-6)
    np.testing.assert_allclose([m.xmag, m.ymag, m.zmag], frames.flu2frd(b), rtol=1e-6)


def test_attitude_known_points(mav):
    # Body x pointing east (ENU yaw 0) is a NED heading of +90 deg.
    m = codec.attitude(mav, 0, np.eye(3), (0.1, 0.2, 0.3))
    assert (m.roll, m.pitch, m.yaw) == pytest.approx((0.0, 0.0, math.pi / 2))
    assert (m.rollspeed, m.pitchspeed, m.yawspeed) == pytest.approx((0.1, -0.2, -0.3))
    # A rotation of +0.3 rad about body FLU y (the left axis) puts the nose down: FRD pitch -0.3.
    c, s = math.cos(0.3), math.sin(0.3)
    Ry = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    m = codec.attitude(mav, 0, Ry, (0, 0, 0))
    assert m.pitch == pytest.approx(-0.3) and m.roll == pytest.approx(0.0, abs=1e-12)
    # +0.2 rad about body x (forward) lifts the left side: FRD roll +0.2.
    c, s = math.cos(0.2), math.sin(0.2)
    Rx = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    assert codec.attitude(mav, 0, Rx, (0, 0, 0)).roll == pytest.approx(0.2)


def test_attitude_quaternion_east_is_yaw_90(mav):
    m = roundtrip(mav, codec.attitude_quaternion(mav, 0, np.eye(3), (0, 0, 0)))
    h = math.sqrt(0.5)
    assert (m.q1, m.q2, m.q3, m.q4) == pytest.approx((h, 0.0, 0.0, h), abs=1e-6)


def random_rotations(n, seed=6):
    """Uniform random rotations (normalised Gaussian quaternions, an independent construction)."""
    rng = np.random.default_rng(seed)
    for q in rng.normal(size=(n, 4)):
        yield frames.quat_wxyz2rotmat(q / np.linalg.norm(q))


def test_float_quaternion_paths_match_frames(mav):
    for R in random_rotations(50):
        R_nf = frames.R_enu_flu2ned_frd(R)
        ref = frames.rotmat2quat_wxyz(R_nf)
        m = codec.attitude_quaternion(mav, 0, R, (0.0, 0.0, 0.0))
        assert (m.q1, m.q2, m.q3, m.q4) == pytest.approx(tuple(ref), abs=1e-12)


def test_odometry_truth_round_trip(mav):
    """Ground truth in ODOMETRY (pose NED, velocity body FRD) decodes back to ENU/FLU."""
    rng = np.random.default_rng(7)
    for R in random_rotations(10, seed=8):
        p, v, w = rng.normal(size=(3, 3)) * np.array([[10.0], [2.0], [1.0]])
        args = codec.odometry_truth_args(77, p, v, R, w)
        msg = roundtrip(mav, mavlink.MAVLink_odometry_message(*args))
        assert (msg.frame_id, msg.child_frame_id) == (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD)
        np.testing.assert_allclose([msg.x, msg.y, msg.z], frames.enu2ned(p), atol=1e-5)
        R_nf = frames.quat_wxyz2rotmat(msg.q)
        np.testing.assert_allclose(frames.R_ned_frd2enu_flu(R_nf), R, atol=1e-6)
        # body FRD velocity rotated back to the world gives the NED velocity
        np.testing.assert_allclose(R_nf @ [msg.vx, msg.vy, msg.vz], frames.enu2ned(v), atol=1e-5)
        np.testing.assert_allclose([msg.rollspeed, msg.pitchspeed, msg.yawspeed], frames.flu2frd(w), atol=1e-6)


def test_global_position_and_heading(mav):
    origin = codec.GeoOrigin(44.8, -0.6, 30.0)
    home = (0.0, 0.0, 0.5)
    m = roundtrip(mav, codec.global_position_int(mav, 0, origin, home, (0.0, 0.0, 2.5), (1.0, 2.0, -0.5), 0.0))
    assert (m.lat, m.lon) == (448000000, -6000000)
    assert m.alt == 32500 and m.relative_alt == 2000          # mm AMSL, mm above home
    assert (m.vx, m.vy, m.vz) == (200, 100, 50)                # cm/s north, east, down
    assert m.hdg == 9000                                       # facing east
    m = codec.global_position_int(mav, 0, origin, home, (0, 0, 0), (0, 0, 0), math.pi / 2)
    assert m.hdg == 0                                          # facing north
    # 1 km north: latitude grows by 1000 m over the meridian radius of curvature (WGS-84)
    lat0 = math.radians(44.8)
    e2 = (1 / 298.257223563) * (2 - 1 / 298.257223563)
    r_m = 6378137.0 * (1 - e2) / (1 - e2 * math.sin(lat0) ** 2) ** 1.5
    m = codec.global_position_int(mav, 0, origin, home, (0.0, 1000.0, 0.0), (0, 0, 0), 0.0)
    assert m.lat == round((44.8 + math.degrees(1000.0 / r_m)) * 1e7)


def test_distance_sensor_cm_and_out_of_range(mav):
    r = RangeReading(3, 25, 3.456, 0.1, 10.0, 0.1, 0.05)
    m = roundtrip(mav, codec.distance_sensor(mav, 5, r))
    assert (m.current_distance, m.min_distance, m.max_distance) == (346, 10, 1000)
    assert (m.id, m.orientation, m.signal_quality) == (3, 25, 100)
    none = dataclasses.replace(r, distance_m=None)
    m = roundtrip(mav, codec.distance_sensor(mav, 5, none))
    assert m.current_distance == 1001 and m.signal_quality == 1   # outside [min, max]: no return


def test_position_target_echo(mav):
    sp = Setpoint((1.0, 2.0, 3.0), None, (0.0, 0.0, 1.0), 0.0, None)
    m = roundtrip(mav, codec.position_target_local_ned(mav, 0, sp))
    assert (m.x, m.y, m.z) == (2.0, 1.0, -3.0)
    assert m.afz == -1.0 and m.yaw == pytest.approx(math.pi / 2)
    assert m.type_mask == codec.TM_VEL | codec.TM_YAW_RATE


# --- SET_POSITION_TARGET_LOCAL_NED type_mask table -----------------------------

NAN = float("nan")
POS_ONLY = codec.TM_VEL | codec.TM_ACC | codec.TM_YAW | codec.TM_YAW_RATE          # 0xDF8
VEL_ONLY = codec.TM_POS | codec.TM_ACC | codec.TM_YAW | codec.TM_YAW_RATE          # 0xDC7


def target(mask, pos=(1.0, 2.0, -3.0), vel=(0.5, -0.5, 0.25), acc=(0.1, 0.2, 0.3), yaw=0.0,
           yaw_rate=0.5, frame=mavlink.MAV_FRAME_LOCAL_NED):
    return mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, frame, mask, *pos, *vel, *acc, yaw, yaw_rate)


def same(a, b):
    return np.allclose(np.asarray(a, float), np.asarray(b, float), equal_nan=True)


@pytest.mark.parametrize("mask, pos, vel, acc, yaw, yaw_rate", [
    (POS_ONLY, (2, 1, 3), (NAN,) * 3, (NAN,) * 3, None, None),
    (VEL_ONLY, (NAN,) * 3, (-0.5, 0.5, -0.25), (NAN,) * 3, None, None),
    (codec.TM_YAW_RATE, (2, 1, 3), (-0.5, 0.5, -0.25), (0.2, 0.1, -0.3), math.pi / 2, None),
    (codec.TM_YAW, (2, 1, 3), (-0.5, 0.5, -0.25), (0.2, 0.1, -0.3), None, -0.5),
    # FORCE_SET: force setpoints are not supported (as PX4): the acceleration is ignored
    (codec.TM_FORCE | codec.TM_YAW | codec.TM_YAW_RATE, (2, 1, 3), (-0.5, 0.5, -0.25), (NAN,) * 3, None, None),
    # per axis: velocity in x/y (NED), position in z
    (codec.TM_X | codec.TM_Y | codec.TM_VZ | codec.TM_ACC | codec.TM_YAW | codec.TM_YAW_RATE,
     (NAN, NAN, 3), (-0.5, 0.5, NAN), (NAN,) * 3, None, None),
    (0xFFF, (NAN,) * 3, (NAN,) * 3, (NAN,) * 3, None, None),
])
def test_type_mask_table(mask, pos, vel, acc, yaw, yaw_rate):
    t = codec.decode_position_target(target(mask))
    assert t is not None and t.type_mask == mask
    assert same(t.pos_enu_m, pos) and same(t.vel_enu_m_s, vel) and same(t.acc_enu_m_s2, acc)
    assert (t.yaw_enu_rad is None) == (yaw is None) and (t.yaw_rate_enu_rad_s is None) == (yaw_rate is None)
    if yaw is not None:
        assert t.yaw_enu_rad == pytest.approx(yaw)
    if yaw_rate is not None:
        assert t.yaw_rate_enu_rad_s == pytest.approx(yaw_rate)


def test_nan_component_is_ignored_per_axis():
    t = codec.decode_position_target(target(POS_ONLY, pos=(1.0, NAN, -3.0)))
    assert same(t.pos_enu_m, (NAN, 1.0, 3.0))       # NED y (east) missing -> ENU x missing


@pytest.mark.parametrize("kw", [
    {"pos": (1e9, 0.0, 0.0)}, {"vel": (0.0, 500.0, 0.0)}, {"frame": mavlink.MAV_FRAME_GLOBAL_INT},
])
def test_out_of_range_or_unsupported_frame_is_rejected(kw):
    mask = 0 if "vel" in kw else POS_ONLY
    assert codec.decode_position_target(target(mask, **kw)) is None


def test_body_ned_velocity_rotates_with_heading():
    fwd = target(VEL_ONLY, vel=(1.0, 0.0, 0.0), frame=mavlink.MAV_FRAME_BODY_NED)
    right = target(VEL_ONLY, vel=(0.0, 1.0, 0.0), frame=mavlink.MAV_FRAME_BODY_NED)
    t = codec.decode_position_target(fwd, yaw_enu_rad=math.pi / 2)       # heading north
    assert same(np.round(t.vel_enu_m_s, 12), (0.0, 1.0, 0.0))
    t = codec.decode_position_target(right, yaw_enu_rad=0.0)             # heading east: right is south
    assert same(np.round(t.vel_enu_m_s, 12), (0.0, -1.0, 0.0))
    up = target(POS_ONLY, pos=(2.0, 0.0, -1.0), frame=mavlink.MAV_FRAME_BODY_NED)
    t = codec.decode_position_target(up, yaw_enu_rad=0.0, pos_enu_m=(10.0, 20.0, 1.0))
    assert same(np.round(t.pos_enu_m, 12), (12.0, 20.0, 2.0))           # 2 m ahead (east), 1 m up


# --- actuator answers -------------------------------------------------------------


def hil(mav, t, controls, flags):
    return mav.hil_actuator_controls_encode(t, list(controls) + [0.0] * (16 - len(controls)), 0, flags)


def test_actuator_controls_decoding(mav):
    a = codec.decode_actuator_controls(hil(mav, 7, [0.2, -1.0, 1.0, 0.6], 1))
    assert a.time_usec == 7 and a.lockstep and a.motor_cmd == pytest.approx((0.2, 0.0, 1.0, 0.6))
    assert a.refused is None
    a = codec.decode_actuator_controls(hil(mav, 7, [0.2, -1.0, 1.5, 0.6], 1))
    assert a.motor_cmd is None and a.lockstep and "outside [-1, 1]" in a.refused   # MAVLink's range, not clipped
    a = codec.decode_actuator_controls(hil(mav, 8, [NAN] * 16, 1))
    assert a.motor_cmd is None and a.lockstep              # a lockstep tick without override
    a = codec.decode_actuator_controls(hil(mav, 9, [0.5, NAN, 0.5, 0.5], 0))
    assert a.motor_cmd is None and not a.lockstep          # unusable command: no override


def test_fast_datagram_decoder_agrees_with_pymavlink():
    tx = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    rng = np.random.default_rng(5)
    cases = [[NAN] * 16, [0.0] * 16, list(rng.uniform(-0.5, 1.5, 4)), [0.5, NAN, 0.2, 0.1]]
    for flags, controls in zip((1, 0, 1, 1), cases):
        buf = hil(tx, int(rng.integers(0, 2**40)), controls, flags).pack(tx)
        fast = codec.decode_actuator_datagram(buf)
        ref = codec.decode_actuator_controls(mavlink.MAVLink(None).parse_buffer(buf)[0])
        assert fast.time_usec == ref.time_usec and fast.lockstep == ref.lockstep
        assert (fast.motor_cmd is None) == (ref.motor_cmd is None)
        if ref.motor_cmd is not None:
            assert fast.motor_cmd == pytest.approx(ref.motor_cmd)
    good = hil(tx, 1, [0.5] * 4, 1).pack(tx)
    assert codec.decode_actuator_datagram(good[:-1] + bytes([good[-1] ^ 1])) is None   # bad CRC
    assert codec.decode_actuator_datagram(good + good) is None                        # two packets
    assert codec.decode_actuator_datagram(tx.heartbeat_encode(6, 8, 0, 0, 0).pack(tx)) is None
    assert codec.decode_actuator_datagram(b"\xfd" + bytes(40)) is None


def test_fast_packer_is_byte_identical_to_pymavlink():
    a, b = mavlink.MAVLink(None, 1, 1), mavlink.MAVLink(None, 1, 1)
    cases = [
        (codec.PACK_HIGHRES_IMU, codec.highres_imu_args(123456, (0.1, 0.2, 9.8), (0.01, 0.0, 0.03),
                                                        (0.2, 0.0, -0.4), 30.0)),
        (codec.PACK_LOCAL_POSITION_NED, codec.local_position_ned_args(999, (1.0, 2.0, 3.0), (0, 0, 0))),
        (codec.PACK_LOCAL_POSITION_NED, codec.local_position_ned_args(0, (0, 0, 0), (0, 0, 0))),
        (codec.PACK_ATTITUDE, codec.attitude_args(5, np.eye(3), (0.1, 0.2, 0.3))),
        (codec.PACK_ATTITUDE_QUATERNION, codec.attitude_quaternion_args(5, np.eye(3), (0.1, 0.2, 0.3))),
        (codec.PACK_DISTANCE_SENSOR, codec.distance_sensor_args(9, RangeReading(1, 0, 2.5, 0.1, 10.0, 0.1, 0.1))),
        (codec.PACK_ODOMETRY, codec.odometry_truth_args(9, (1, 2, 3), (0.5, 0, 0), np.eye(3), (0, 0, 0.1))),
    ]
    for seq, (packer, args) in enumerate(cases * 2):
        ref = packer.msg_class(*args).pack(a)
        a.seq = (a.seq + 1) & 0xFF
        assert packer.pack(b, args) == ref
        assert b.seq == a.seq
    # With signing the pymavlink path is used and the packet still parses and verifies.
    key = bytes(range(32))
    b.signing.secret_key, b.signing.sign_outgoing, b.signing.link_id = key, True, 0
    b.signing.timestamp = 1
    buf = codec.PACK_HIGHRES_IMU.pack(b, cases[0][1])
    rx = mavlink.MAVLink(None)
    rx.signing.secret_key = key
    msg = rx.parse_buffer(buf)[0]
    assert msg.get_type() == "HIGHRES_IMU" and msg.get_signed()


# --- modes, params, commands, missions ---------------------------------------------------


def test_px4_custom_modes_as_pymavlink_reads_them(mav):
    for (main, sub), name in [((6, 0), "OFFBOARD"), ((4, 3), "LOITER"), ((4, 2), "TAKEOFF"),
                              ((4, 6), "LAND"), ((3, 0), "POSCTL")]:
        custom = codec.px4_custom_mode(main, sub)
        assert codec.px4_modes_from_custom(custom) == (main, sub)
        hb = codec.heartbeat(mav, True, custom, mavlink.MAV_STATE_ACTIVE)
        assert mavutil.mode_string_v10(hb) == name
        assert hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        assert hb.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        assert hb.autopilot == mavlink.MAV_AUTOPILOT_PX4 and hb.type == mavlink.MAV_TYPE_QUADROTOR
    assert codec.px4_custom_mode(6, 0) == 6 * 65536
    assert codec.px4_custom_mode(4, 3) == (4 << 16) + (3 << 24)


def test_int_params_are_bytewise_as_px4():
    wire = codec.param_to_wire(3, mavlink.MAV_PARAM_TYPE_INT32)
    assert struct.pack("<f", wire) == struct.pack("<i", 3)
    assert codec.param_from_wire(wire, mavlink.MAV_PARAM_TYPE_INT32) == 3
    assert codec.param_to_wire(0.25, mavlink.MAV_PARAM_TYPE_REAL32) == 0.25
    neg = codec.param_to_wire(-7, mavlink.MAV_PARAM_TYPE_INT32)
    assert codec.param_from_wire(neg, mavlink.MAV_PARAM_TYPE_INT32) == -7


def test_takeoff_altitude_is_amsl():
    assert codec.decode_takeoff_altitude(32.0, 30.0) == pytest.approx(2.0)
    assert codec.decode_takeoff_altitude(NAN, 30.0) is None


def test_mission_item_units(mav):
    legacy = mavlink.MAVLink_mission_item_message(1, 1, 0, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, 16, 0, 1,
                                                  0, 0, 0, 0, 44.8, -0.6, 5.0, 0)
    item = codec.mission_item_from_float(legacy)
    assert (item.x, item.y, item.z) == (448000000, -6000000, 5.0)
    local = dataclasses.replace(item, frame=mavlink.MAV_FRAME_LOCAL_NED)
    legacy_local = mavlink.MAVLink_mission_item_message(1, 1, 0, mavlink.MAV_FRAME_LOCAL_NED, 16, 0, 1,
                                                        0, 0, 0, 0, 1.5, -2.0, 5.0, 0)
    assert (codec.mission_item_from_float(legacy_local).x, codec.mission_item_from_float(legacy_local).y) == (15000, -20000)
    back = roundtrip(mav, codec.mission_item_int(mav, 255, 190, item))
    assert codec.mission_item_from_int(back) == item
    assert local.frame == mavlink.MAV_FRAME_LOCAL_NED
    bad = mavlink.MAVLink_mission_item_message(1, 1, 0, 0, 16, 0, 1, 0, 0, 0, 0, NAN, 0.0, 5.0, 0)
    assert codec.mission_item_from_float(bad) is None
