"""companion.link: codec round trips and known points, .tlog, garbage tolerance,
connection and mission upload against a scripted vehicle over real UDP."""

from __future__ import annotations

import math
import socket
import struct
import threading
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore import frames
from mavcore.errors import CommandRejected, InputError, LinkError
from mavcore import codec
from companion.link.connection import Connection, check_connection_string
from mavcore.services.command import CommandClient
from mavcore.services.mission import MissionRejected, MissionUploadClient
from service_driver import drive
from companion.link.tlog import TlogWriter, read_tlog


def _vehicle_mav():
    """A protocol object packing as the vehicle (1/1)."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.robust_parsing = True
    return mav


def _wire(msg, mav):
    """Pack ``msg`` and decode it with a fresh parser: what the peer would see."""
    buf = msg.pack(mav)
    rx = mavlink.MAVLink(None)
    out = rx.parse_buffer(buf)
    assert out is not None and len(out) == 1
    return out[0]


# --- codec: known points -------------------------------------------------------


def test_setpoint_known_point_enu_123_is_ned_21m3():
    mav = _vehicle_mav()
    msg = _wire(codec.encode_set_position_target(mav, 1234, (1.0, 2.0, 3.0), (0.1, 0.2, 0.3),
                                                 (-1.0, 0.5, 2.0), 0.0), mav)
    assert (msg.x, msg.y, msg.z) == pytest.approx((2.0, 1.0, -3.0))
    assert (msg.vx, msg.vy, msg.vz) == pytest.approx((0.2, 0.1, -0.3))
    assert (msg.afx, msg.afy, msg.afz) == pytest.approx((0.5, -1.0, -2.0))
    # nose east: ENU heading 0 is NED heading +90 deg
    assert msg.yaw == pytest.approx(math.pi / 2)
    assert msg.coordinate_frame == mavlink.MAV_FRAME_LOCAL_NED
    # position, velocity, acceleration and yaw used; yaw rate ignored; not force
    assert msg.type_mask & 0b111111111 == 0
    assert msg.type_mask & mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
    assert not msg.type_mask & mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE
    assert not msg.type_mask & mavlink.POSITION_TARGET_TYPEMASK_FORCE_SET
    assert msg.time_boot_ms == 1234


@pytest.mark.parametrize("yaw_enu", [0.3, -2.0, 3.0, math.pi / 2])
def test_setpoint_round_trip(yaw_enu):
    mav = _vehicle_mav()
    p, v, a = np.array((3.5, -7.25, 1.5)), np.array((0.9, -0.1, 0.05)), np.array((0.0, 0.2, -0.1))
    msg = _wire(codec.encode_set_position_target(mav, 0, p, v, a, yaw_enu), mav)
    p2, v2, a2, yaw2 = codec.decode_position_target_local_ned(msg)
    np.testing.assert_allclose(p2, p, atol=1e-6)   # float32 on the wire
    np.testing.assert_allclose(v2, v, atol=1e-6)
    np.testing.assert_allclose(a2, a, atol=1e-6)
    assert frames.wrap_pi(yaw2 - yaw_enu) == pytest.approx(0.0, abs=1e-6)


def test_highres_imu_frd_to_flu():
    mav = _vehicle_mav()
    # hover, level, nose north: specific force is +g up = FRD (0, 0, -g)
    m = mav.highres_imu_encode(5_000_000, 0.1, 0.2, -9.81, 0.01, -0.02, 0.03, 0.21, 0.0, 0.42,
                               0, 0, 0, 0, 0xFFFF, 0)
    s = codec.decode_highres_imu(_wire(m, mav))
    assert s.time_usec == 5_000_000
    np.testing.assert_allclose(s.accel_flu_m_s2, (0.1, -0.2, 9.81), rtol=1e-6)
    np.testing.assert_allclose(s.gyro_flu_rad_s, (0.01, 0.02, -0.03), rtol=1e-6)
    np.testing.assert_allclose(s.mag_flu_gauss, (0.21, 0.0, -0.42), rtol=1e-6)
    # the hand-written fast path agrees with mavcore.frames
    np.testing.assert_allclose(s.accel_flu_m_s2, frames.frd2flu((0.1, 0.2, -9.81)), rtol=1e-6)


def test_local_position_ned_to_enu():
    mav = _vehicle_mav()
    m = mav.local_position_ned_encode(4321, 2.0, 1.0, -3.0, 0.5, -0.25, 0.125)
    lp = codec.decode_local_position_ned(_wire(m, mav))
    assert lp.time_boot_ms == 4321
    np.testing.assert_allclose(lp.pos_enu_m, (1.0, 2.0, 3.0))
    np.testing.assert_allclose(lp.vel_enu_m_s, (-0.25, 0.5, -0.125))


def test_attitude_nose_north_and_quaternion_agree():
    mav = _vehicle_mav()
    # level, nose north: body forward = ENU north, body left = ENU west
    R_expected = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    att = codec.decode_attitude(_wire(mav.attitude_encode(10, 0.0, 0.0, 0.0, 0, 0, 0), mav))
    np.testing.assert_allclose(att.R_enu_flu, R_expected, atol=1e-12)
    # an arbitrary attitude: Euler and quaternion encodings decode to the same R
    roll, pitch, yaw = 0.3, -0.2, 2.5
    q = frames.rotmat2quat_wxyz(frames.euler_zyx2rotmat(roll, pitch, yaw))
    a1 = codec.decode_attitude(_wire(mav.attitude_encode(10, roll, pitch, yaw, 0, 0, 0), mav))
    a2 = codec.decode_attitude_quaternion(_wire(mav.attitude_quaternion_encode(10, *q, 0, 0, 0), mav))
    np.testing.assert_allclose(a1.R_enu_flu, a2.R_enu_flu, atol=1e-6)
    # a proper rotation
    np.testing.assert_allclose(a1.R_enu_flu @ a1.R_enu_flu.T, np.eye(3), atol=1e-6)
    assert np.linalg.det(a1.R_enu_flu) == pytest.approx(1.0, abs=1e-6)


def test_heartbeat_px4_offboard_armed():
    mav = _vehicle_mav()
    m = mav.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4,
                             mavlink.MAV_MODE_FLAG_SAFETY_ARMED | mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                             6 << 16, mavlink.MAV_STATE_ACTIVE)
    st = codec.decode_heartbeat(_wire(m, mav))
    assert st.armed and st.offboard and st.main_mode == 6 and st.sub_mode == 0
    # AUTO.LAND = main 4, sub 6
    m = mav.heartbeat_encode(2, 12, 0, codec.px4_custom_mode(4, 6), 3)
    st = codec.decode_heartbeat(_wire(m, mav))
    assert not st.armed and (st.main_mode, st.sub_mode) == (4, 6)


def test_distance_sensor_cm_to_m_and_no_return():
    mav = _vehicle_mav()
    m = mav.distance_sensor_encode(100, 20, 500, 137, 0, 3, mavlink.MAV_SENSOR_ROTATION_NONE, 0)
    r = codec.decode_distance_sensor(_wire(m, mav))
    assert (r.distance_m, r.min_m, r.max_m, r.sensor_id) == (1.37, 0.2, 5.0, 3)
    # exactly max_distance is a valid range (PX4); max + 1 cm is "no return"
    m = mav.distance_sensor_encode(100, 20, 500, 500, 0, 3, 0, 0)
    assert codec.decode_distance_sensor(_wire(m, mav)).distance_m == 5.0
    m = mav.distance_sensor_encode(100, 20, 500, 501, 0, 3, 0, 0)
    assert math.isnan(codec.decode_distance_sensor(_wire(m, mav)).distance_m)
    m = mav.distance_sensor_encode(100, 20, 500, 19, 0, 3, 0, 0)
    assert math.isnan(codec.decode_distance_sensor(_wire(m, mav)).distance_m)


def _meridian_m_per_deg(lat_deg: float) -> float:
    """Length of one degree of latitude (m), the standard WGS-84 series
    (independent of mavcore.frames' radius-of-curvature formula)."""
    phi = math.radians(lat_deg)
    return 111132.954 - 559.822 * math.cos(2 * phi) + 1.175 * math.cos(4 * phi)


def test_mission_item_geodetic_known_points():
    mav = _vehicle_mav()
    home = (44.80, -0.60, 30.0)
    m = _wire(codec.encode_mission_item_int(mav, 0, (0.0, 0.0, 1.5), *home), mav)
    assert (m.x, m.y) == (448000000, -6000000)
    assert m.z == pytest.approx(31.5)          # AMSL = home + up
    assert m.frame == mavlink.MAV_FRAME_GLOBAL_INT and m.command == mavlink.MAV_CMD_NAV_WAYPOINT
    # 1000 m north: latitude grows by 1000 / (m per degree)
    m = _wire(codec.encode_mission_item_int(mav, 1, (0.0, 1000.0, 0.0), *home), mav)
    dlat = (m.x - 448000000) * 1e-7
    assert dlat == pytest.approx(1000.0 / _meridian_m_per_deg(44.80), abs=2e-7)
    assert m.seq == 1
    # 1000 m east: longitude grows by 1000 / (m per degree of longitude);
    # east-west degree = pi/180 * N(phi) cos(phi), N prime-vertical radius
    phi = math.radians(44.80)
    n_m = 6378137.0 / math.sqrt(1 - 0.00669437999014 * math.sin(phi) ** 2)
    m = _wire(codec.encode_mission_item_int(mav, 2, (1000.0, 0.0, 0.0), *home), mav)
    assert (m.y + 6000000) * 1e-7 == pytest.approx(1000.0 / (math.pi / 180 * n_m * math.cos(phi)), abs=2e-7)
    # round trip within the 1e-7 degree (~1 cm) quantisation
    p = np.array((12.3, -45.6, 2.5))
    m = _wire(codec.encode_mission_item_int(mav, 3, p, *home), mav)
    np.testing.assert_allclose(codec.decode_mission_item_int(m, *home), p, atol=0.012)


def test_hil_actuator_controls_commands_and_nan_tick():
    mav = _vehicle_mav()
    m = _wire(codec.encode_hil_actuator_controls(mav, 123456789, np.array((0.1, 0.2, 0.3, 0.4)), True), mav)
    assert m.time_usec == 123456789 and m.flags == 1
    assert m.controls[:4] == pytest.approx([0.1, 0.2, 0.3, 0.4])
    assert all(c == 0.0 for c in m.controls[4:])
    assert m.mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    m = _wire(codec.encode_hil_actuator_controls(mav, 7, None, False), mav)
    assert all(math.isnan(c) for c in m.controls[:4]) and m.flags == 1
    assert not m.mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED


def test_odometry_truth_round_trip():
    mav = _vehicle_mav()
    R = frames.euler_zyx2rotmat(0.1, -0.3, 2.0)     # any attitude (body FLU -> ENU)
    p, v, w = (3.0, -4.0, 1.5), (1.0, 0.5, -0.25), (0.1, 0.2, 0.3)
    m = _wire(codec.encode_odometry_truth(mav, 123456, p, v, R, w), mav)
    # the wire holds NED: ENU (3, -4, 1.5) is NED (-4, 3, -1.5)
    assert (m.x, m.y, m.z) == pytest.approx((-4.0, 3.0, -1.5))
    t = codec.decode_odometry(m)
    assert t.time_usec == 123456
    np.testing.assert_allclose(t.pos_enu_m, p, atol=1e-6)
    np.testing.assert_allclose(t.vel_enu_m_s, v, atol=1e-6)
    np.testing.assert_allclose(t.R_enu_flu, R, atol=1e-6)
    # the runner's float-only pose decode gives the same numbers, R row-major
    pos, R9 = codec.decode_odometry_pose(m)
    assert pos == tuple(t.pos_enu_m)
    assert R9 == tuple(t.R_enu_flu.ravel().tolist())


# --- tlog ----------------------------------------------------------------------------


def test_tlog_write_read_and_pymavlink_reads_it(tmp_path):
    from pymavlink import mavutil

    mav = _vehicle_mav()
    msgs = [mav.heartbeat_encode(2, 12, 0, 0, 3),
            mav.local_position_ned_encode(20, 1.0, 2.0, 3.0, 0, 0, 0),
            mav.hil_actuator_controls_encode(30, [0.5] * 16, 0, 1)]
    path = tmp_path / "x.tlog"
    stamps = [1_700_000_000_000_000 + 1000 * i for i in range(3)]
    with TlogWriter(path) as w:
        for m, t in zip(msgs, stamps):
            w.write(m.pack(mav), t)
    # the format: 8-byte big-endian timestamp, then the packet
    raw = path.read_bytes()
    assert struct.unpack(">Q", raw[:8])[0] == stamps[0]
    assert raw[8] == 0xFD
    recs = list(read_tlog(path))
    assert [r.msg.get_type() for r in recs] == ["HEARTBEAT", "LOCAL_POSITION_NED", "HIL_ACTUATOR_CONTROLS"]
    assert [r.time_usec for r in recs] == stamps
    assert recs[1].msg.y == 2.0
    # pymavlink's own reader understands the file
    log = mavutil.mavlink_connection(str(path))
    types, times = [], []
    while (m := log.recv_msg()) is not None:
        types.append(m.get_type())
        times.append(m._timestamp)
    assert types == ["HEARTBEAT", "LOCAL_POSITION_NED", "HIL_ACTUATOR_CONTROLS"]
    assert times[2] == pytest.approx(stamps[2] * 1e-6)


def test_tlog_flushes_by_wall_clock_and_survives_truncation(tmp_path):
    mav = _vehicle_mav()
    path = tmp_path / "y.tlog"
    w = TlogWriter(path, flush_interval_s=0.0).open()
    for i in range(5):
        w.write(mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav), 1000 + i)
    # readable before close: flushed
    assert len(list(read_tlog(path))) == 5
    w.close()
    data = path.read_bytes()
    path.write_bytes(data[:-5])               # a torn last record
    assert len(list(read_tlog(path))) == 4


# --- connection: strings, garbage, UDP ------------------------------------------------


@pytest.mark.parametrize("url", ["udpout:127.0.0.1:14540", "udpin:0.0.0.0:14550", "tcp:localhost:5760",
                                 "/dev/ttyACM0"])
def test_connection_strings_accepted(url):
    check_connection_string(url)


@pytest.mark.parametrize("url", ["flight.tlog", "udpout:127.0.0.1", "udp:host:notaport", "http://x"])
def test_connection_strings_rejected(url):
    with pytest.raises(InputError):
        check_connection_string(url)


def test_constructor_does_no_io():
    c = Connection("udpin:127.0.0.1:1")       # port 1 would fail to bind if opened
    with pytest.raises(LinkError):
        c.poll()


def _free_udp_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def test_garbage_never_crashes_and_good_packets_survive():
    rng = np.random.default_rng(4)
    port = _free_udp_port()
    conn = Connection(f"udpin:127.0.0.1:{port}").open()
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    mav = _vehicle_mav()
    try:
        # the vehicle's heartbeat binds its address (companion.link.auth)
        tx.sendto(mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav), ("127.0.0.1", port))
        sent = 0
        for i in range(60):
            kind = i % 4
            if kind == 0:
                data = rng.integers(0, 256, rng.integers(1, 300)).astype(np.uint8).tobytes()
            elif kind == 1:   # a v2 header promising a long packet, then nothing
                data = bytes([0xFD, 250, 0, 0, 1, 1, 1, 105, 0, 0]) + rng.bytes(20)
            elif kind == 2:   # a valid packet with a broken CRC
                buf = bytearray(mav.local_position_ned_encode(i, 1, 2, 3, 0, 0, 0).pack(mav))
                buf[-1] ^= 0xFF
                data = bytes(buf)
            else:
                data = mav.local_position_ned_encode(i, float(i), 0, 0, 0, 0, 0).pack(mav)
                sent += 1
            tx.sendto(data, ("127.0.0.1", port))
        got = []
        deadline = time.monotonic() + 2.0
        while len(got) < sent and time.monotonic() < deadline:
            got += [m for m in conn.poll(0.05) if m.get_type() == "LOCAL_POSITION_NED"]
        assert [m.time_boot_ms for m in got] == [i for i in range(60) if i % 4 == 3]
        assert conn.n_bad >= 30
        # also through feed(): a byte stream of pure noise
        for _ in range(50):
            conn.feed(rng.bytes(int(rng.integers(1, 512))))
    finally:
        tx.close()
        conn.close()


class _ScriptedVehicle(threading.Thread):
    """A minimal vehicle on a UDP socket: heartbeats, acks commands, mission protocol."""

    def __init__(self, port: int, drop_first_count: bool = False, reject_cmd: int | None = None) -> None:
        super().__init__(daemon=True)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", port))
        self.sock.settimeout(0.02)
        self.mav = _vehicle_mav()
        self.drop_first_count = drop_first_count
        self.reject_cmd = reject_cmd
        self.items: dict[int, object] = {}
        self.stop = threading.Event()
        self.peer = None
        self.count = None

    def send(self, m) -> None:
        if self.peer is not None:
            self.sock.sendto(m.pack(self.mav), self.peer)

    def run(self) -> None:
        rx = mavlink.MAVLink(None)
        last_hb = 0.0
        while not self.stop.is_set():
            if time.monotonic() - last_hb > 0.2:
                self.send(self.mav.heartbeat_encode(2, 12, 0, 0, 3))
                last_hb = time.monotonic()
            try:
                data, self.peer = self.sock.recvfrom(4096)
            except socket.timeout:
                continue
            for m in rx.parse_buffer(data) or []:
                t = m.get_type()
                if t == "COMMAND_LONG":
                    res = 4 if m.command == self.reject_cmd else 0
                    self.send(self.mav.command_ack_encode(m.command, res, 0, 0, 0, 0))
                elif t == "MISSION_COUNT":
                    if self.drop_first_count:
                        self.drop_first_count = False
                        continue
                    self.count = m.count
                    self.send(self.mav.mission_request_int_encode(255, 0, 0, 0))
                elif t == "MISSION_ITEM_INT":
                    self.items[m.seq] = m
                    if m.seq + 1 < self.count:
                        self.send(self.mav.mission_request_int_encode(255, 0, m.seq + 1, 0))
                    else:
                        self.send(self.mav.mission_ack_encode(255, 0, 0, 0))

    def close(self) -> None:
        self.stop.set()
        self.join(2.0)
        self.sock.close()


def command(conn, cmd, params=(), **kw):
    return CommandClient(conn.mav, conn.target_system, conn.target_component, cmd, params, **kw)


def upload(conn, items, **kw):
    return MissionUploadClient(conn.mav, conn.target_system, conn.target_component, items, **kw)


def test_heartbeat_command_and_mission_upload_over_udp():
    """The companion's client state machines (``mavcore.services``) over real UDP with a
    scripted vehicle that drops the first MISSION_COUNT: the count is re-sent."""
    port = _free_udp_port()
    veh = _ScriptedVehicle(port, drop_first_count=True, reject_cmd=mavlink.MAV_CMD_NAV_TAKEOFF)
    veh.start()
    conn = Connection(f"udpout:127.0.0.1:{port}").open()
    seen = []
    conn.handler = seen.append
    try:
        hb = conn.wait_heartbeat(timeout_s=5.0)
        assert hb.get_srcSystem() == 1 and hb.get_srcComponent() == 1
        ack = drive(conn, command(conn, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (1,), timeout_s=1.0))
        assert ack.result == mavlink.MAV_RESULT_ACCEPTED
        with pytest.raises(CommandRejected) as exc:
            drive(conn, command(conn, mavlink.MAV_CMD_NAV_TAKEOFF, timeout_s=1.0))
        assert exc.value.result == 4
        home = (44.8, -0.6, 30.0)
        wps = [(float(i), 2.0 * i, 1.5) for i in range(7)]
        items = [codec.encode_mission_item_int(conn.mav, i, p, *home) for i, p in enumerate(wps)]
        assert drive(conn, upload(conn, items, timeout_s=0.3)) == 7
        got = [codec.decode_mission_item_int(veh.items[i], *home) for i in range(7)]
        np.testing.assert_allclose(got, wps, atol=0.012)
        assert any(m.get_type() == "HEARTBEAT" for m in seen)   # others went to the handler
    finally:
        conn.close()
        veh.close()


def test_mission_rejected_and_link_timeout():
    port = _free_udp_port()
    conn = Connection(f"udpout:127.0.0.1:{port}").open()
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", port))
    try:
        # nobody answers: a LinkError, not a hang
        with pytest.raises(LinkError):
            drive(conn, command(conn, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (1,), timeout_s=0.05, sends=2))
        # the vehicle NACKs the count
        mav = _vehicle_mav()
        _, peer = rx.recvfrom(4096)
        rx.sendto(mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav), peer)   # binds the vehicle's address
        rx.sendto(mav.mission_ack_encode(191, 1, mavlink.MAV_MISSION_NO_SPACE, 0).pack(mav), peer)
        with pytest.raises(MissionRejected) as exc:
            drive(conn, upload(conn, [codec.encode_mission_item_int(conn.mav, 0, (0, 0, 1), 0.0, 0.0, 0.0)],
                               timeout_s=0.5))
        assert exc.value.result == mavlink.MAV_MISSION_NO_SPACE
    finally:
        rx.close()
        conn.close()


# --- fast framing of the per-frame messages (codec.split_datagram / pack_hil_actuator_controls) ---


def _random_fields(rng, msg_class):
    """Random field values (``*_encode`` argument order) that survive a float32/int round trip."""
    vals = []
    for name, ftype, n in zip(msg_class.fieldnames, msg_class.fieldtypes,
                              [msg_class.array_lengths[msg_class.ordered_fieldnames.index(f)]
                               for f in msg_class.fieldnames]):
        def one():
            if ftype == "float":
                return float(np.float32(rng.normal(0, 100)))
            bits = {"uint8_t": 8, "int8_t": 8, "uint16_t": 16, "uint32_t": 32, "uint64_t": 63}[ftype]
            v = int(rng.integers(0, 2 ** bits))
            return v - 128 if ftype == "int8_t" and v >= 128 else v
        vals.append([one() for _ in range(n)] if n else one())
    return vals


@pytest.mark.parametrize("cls", [mavlink.MAVLink_highres_imu_message, mavlink.MAVLink_local_position_ned_message,
                                 mavlink.MAVLink_odometry_message, mavlink.MAVLink_distance_sensor_message,
                                 mavlink.MAVLink_attitude_message])
def test_fast_decoders_match_pymavlink(cls):
    rng = np.random.default_rng(7)
    mav = _vehicle_mav()
    for k in range(40):
        fields = _random_fields(rng, cls)
        if k % 4 == 0:   # trailing zeros: MAVLink 2 truncates the payload
            fields[-1] = [0] * len(fields[-1]) if isinstance(fields[-1], list) else 0
        buf = bytes(cls(*fields).pack(mav))
        ref = mavlink.MAVLink(None).parse_buffer(buf)[0]
        parts = list(codec.split_datagram(buf))
        assert len(parts) == 1 and isinstance(parts[0], codec.FastMessage)
        m = parts[0]
        assert m.get_type() == ref.get_type() and m.get_msgId() == ref.get_msgId()
        assert (m.get_srcSystem(), m.get_srcComponent()) == (1, 1)
        assert bytes(m.get_msgbuf()) == buf
        for name in cls.fieldnames:
            a, b = getattr(m, name), getattr(ref, name)
            assert a == b or (isinstance(a, float) and math.isnan(a) and math.isnan(b)), name
        assert m.to_dict() == {k2: v for k2, v in ref.to_dict().items()}


def test_split_datagram_order_garbage_and_fallback():
    mav = _vehicle_mav()
    lpos = bytes(mav.local_position_ned_encode(5, 1, 2, 3, 4, 5, 6).pack(mav))
    hb = bytes(mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav))
    imu = bytes(mav.highres_imu_encode(7, *([0.5] * 13), 0, 0).pack(mav))
    parts = list(codec.split_datagram(lpos + hb + imu))
    # fast types decoded, the heartbeat handed over as its own packet, order kept
    assert [type(p) is bytes for p in parts] == [False, True, False]
    assert parts[1] == hb and parts[0].time_boot_ms == 5 and parts[2].time_usec == 7
    bad = bytearray(lpos)
    bad[-1] ^= 0xFF                                       # CRC failure: the rest goes to pymavlink
    parts = list(codec.split_datagram(hb + bytes(bad) + imu))
    assert parts == [hb, bytes(bad) + imu]
    assert list(codec.split_datagram(lpos[:-3])) == [lpos[:-3]]          # truncated
    assert list(codec.split_datagram(b"\x01\x02" + lpos)) == [b"\x01\x02" + lpos]   # garbage first
    rng = np.random.default_rng(3)
    for _ in range(200):                                  # noise never raises
        for p in codec.split_datagram(rng.bytes(int(rng.integers(1, 400)))):
            assert isinstance(p, (bytes, codec.FastMessage))


@pytest.mark.parametrize("cmd,armed", [(None, True), ((0.1, 0.2, 0.3, 0.4), True), ((0.0, 0.0, 0.0, 0.0), False),
                                       ((1.0, 0.999, 0.5, 0.25), False)])
def test_hil_actuator_packer_is_byte_identical(cmd, armed):
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    rng = np.random.default_rng(11)
    for seq in (0, 1, 200, 255):
        mav.seq = seq
        t = int(rng.integers(0, 2 ** 63))
        c = None if cmd is None else tuple(float(np.float32(x)) for x in cmd)
        ref = bytes(codec.encode_hil_actuator_controls(mav, t, c, armed).pack(mav))
        assert codec.pack_hil_actuator_controls(seq, 1, 191, t, c, armed) == ref


@pytest.mark.parametrize("sync", [False, True])
def test_frame_sync_returns_a_reply_with_the_next_frame(sync):
    """Lockstep determinism: with ``frame_sync`` an immediate reply (here a
    COMMAND_ACK) that arrives alone comes back from ``poll`` together with the
    next frame datagram, however late that one arrives; without it, alone."""
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(2.0)
    port = vehicle.getsockname()[1]
    conn = Connection(f"udpout:127.0.0.1:{port}").open()
    mav = _vehicle_mav()
    try:
        conn.send_heartbeat()
        _, peer = vehicle.recvfrom(4096)
        vehicle.sendto(mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav), peer)   # binds the vehicle
        assert [m.get_type() for m in conn.poll(1.0)] == ["HEARTBEAT"]
        conn.frame_sync = sync
        ack = mav.command_ack_encode(176, 0, 0, 0, 1, 191).pack(mav)
        frame = mav.highres_imu_encode(4000, *([0.25] * 13), 0, 0).pack(mav)
        vehicle.sendto(ack, peer)
        timer = threading.Timer(0.1, lambda: vehicle.sendto(frame, peer))
        timer.start()
        got = [m.get_type() for m in conn.poll(0.5)]
        timer.join()
        if sync:
            assert got == ["COMMAND_ACK", "HIGHRES_IMU"]
        else:
            assert got == ["COMMAND_ACK"]
            assert [m.get_type() for m in conn.poll(0.5)] == ["HIGHRES_IMU"]
    finally:
        conn.close()
        vehicle.close()


def test_fast_link_round_trip_over_udp_with_tlog(tmp_path):
    """The raw-socket path: frames decoded fast, others by pymavlink, answers
    packed by struct; every packet recorded in the .tlog in order."""
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(2.0)
    port = vehicle.getsockname()[1]
    tlog = TlogWriter(tmp_path / "f.tlog").open()
    conn = Connection(f"udpout:127.0.0.1:{port}", tlog=tlog).open()
    mav = _vehicle_mav()
    try:
        conn.send_heartbeat()
        _, peer = vehicle.recvfrom(4096)
        vehicle.sendto(mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav), peer)   # binds the vehicle
        assert [m.get_type() for m in conn.poll(1.0)] == ["HEARTBEAT"]
        for k in range(3):
            frame = (mav.local_position_ned_encode(k, 1.0, 2.0, -3.0, 0, 0, 0).pack(mav)
                     + mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav)
                     + mav.highres_imu_encode(1000 * k, *([0.25] * 13), 0, 0).pack(mav))
            vehicle.sendto(bytes(frame), peer)
            got = []
            deadline = time.monotonic() + 2.0
            while not (got and got[-1].get_type() == "HIGHRES_IMU") and time.monotonic() < deadline:
                got += conn.poll(0.05)
            assert [m.get_type() for m in got] == ["LOCAL_POSITION_NED", "HEARTBEAT", "HIGHRES_IMU"]
            conn.send_actuators(got[-1].time_usec, (0.5, 0.5, 0.5, 0.5), True)
            data = vehicle.recv(4096)
            ans = mavlink.MAVLink(None).parse_buffer(data)[0]
            assert ans.get_type() == "HIL_ACTUATOR_CONTROLS" and ans.time_usec == 1000 * k
            assert list(ans.controls[:4]) == [0.5] * 4 and ans.flags == 1
    finally:
        conn.close()
        tlog.close()
        vehicle.close()
    types = [r.msg.get_type() for r in read_tlog(tmp_path / "f.tlog")]
    assert types == ["HEARTBEAT"] * 2 + ["LOCAL_POSITION_NED", "HEARTBEAT", "HIGHRES_IMU", "HIL_ACTUATOR_CONTROLS"] * 3


def test_int32_parameters_are_decoded_bytewise_as_they_travel():
    import struct

    from pymavlink.dialects.v20 import common as mavlink

    from mavcore.codec import decode_param_value
    from mavcore.codec import param_to_wire

    mav = mavlink.MAVLink(None)
    for v in (0, 1, -7, 123456):
        wire = param_to_wire(v, mavlink.MAV_PARAM_TYPE_INT32)
        msg = mav.param_value_encode(b"SIM_LOCKSTEP", wire, mavlink.MAV_PARAM_TYPE_INT32, 1, 0)
        assert decode_param_value(msg) == v
        assert struct.pack("<f", wire) == struct.pack("<i", v)     # the bytes are the int's
    msg = mav.param_value_encode(b"COM_HIL_TMO", 0.2, mavlink.MAV_PARAM_TYPE_REAL32, 1, 0)
    assert decode_param_value(msg) == 0.2
