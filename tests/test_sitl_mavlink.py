"""The SITL's MAVLink face over real UDP sockets, with pymavlink's mavutil as
the client: heartbeat, commands, parameters, missions, an OFFBOARD flight,
garbage on the link, lockstep."""

from __future__ import annotations

import math
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from mavcore import frames
from sitl.api import SitlProcess, SitlThread
from sitl.flightstack import PARAM_SPECS

ROOT = Path(__file__).resolve().parents[1]
MISSION = ROOT / "missions" / "flat-rectangle" / "mission.yaml"
NAN = float("nan")
POS_ONLY = 0xDF8
LPOS = mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED


def join_statustext(pending: dict, msg) -> str | None:
    """The whole text once a STATUSTEXT ends (MAVLink 2 chunks share a non-zero
    ``id``, the last one is shorter than 50 bytes), else None."""
    text_id = int(getattr(msg, "id", 0) or 0)
    if text_id == 0:
        return msg.text
    parts = pending.setdefault(text_id, [])
    parts.append(msg.text)
    if len(msg.text) < 50:
        return "".join(pending.pop(text_id))
    return None


class Client:
    """A ground station (255/190) on pymavlink's mavutil, MAVLink 2."""

    def __init__(self, url: str, sysid: int = 255, compid: int = 190, local_port: int | None = None) -> None:
        self.conn = mavutil.mavlink_connection(url, source_system=sysid, source_component=compid)
        if local_port is not None:
            # The SITL binds a controller's ids to the address it first controlled
            # from: successive clients of one SITL (one ground station) share a port.
            self.conn.port.bind(("127.0.0.1", local_port))
        self.conn.mav = mavlink.MAVLink(self.conn, srcSystem=sysid, srcComponent=compid)
        self.conn.mav.robust_parsing = True
        self.conn.WIRE_PROTOCOL_VERSION = "2.0"
        self.mav = self.conn.mav
        self.texts: list[str] = []
        self.latest: dict[str, object] = {}
        self._chunks: dict = {}

    def hello(self):
        self.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        hb = self.recv("HEARTBEAT", 5.0)
        assert hb is not None, "no heartbeat from the SITL"
        return hb

    def _take(self, msg) -> None:
        t = msg.get_type()
        self.latest[t] = msg
        if t == "STATUSTEXT":
            text = join_statustext(self._chunks, msg)
            if text is not None:
                self.texts.append(text)

    def recv(self, mtype, timeout: float, cond=None):
        """First message of type ``mtype`` (str or tuple) satisfying ``cond``."""
        types = (mtype,) if isinstance(mtype, str) else tuple(mtype)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            m = self.conn.recv_match(blocking=True, timeout=min(0.05, max(0.0, deadline - time.monotonic())))
            if m is None:
                continue
            self._take(m)
            if m.get_type() in types and (cond is None or cond(m)):
                return m
        return None

    def pump(self, seconds: float, every=None, period: float = 0.05) -> None:
        """Receive everything for ``seconds`` (wall), calling ``every()`` each ``period``."""
        end = time.monotonic() + seconds
        next_call = 0.0
        while time.monotonic() < end:
            now = time.monotonic()
            if every is not None and now >= next_call:
                every()
                next_call = now + period
            m = self.conn.recv_match(blocking=True, timeout=0.01)
            while m is not None:
                self._take(m)
                m = self.conn.recv_msg()

    def command(self, cmd: int, *params, timeout: float = 3.0, target=(1, 1)) -> int | None:
        p = list(params) + [0.0] * (7 - len(params))
        self.mav.command_long_send(target[0], target[1], cmd, 0, *p)
        ack = self.recv("COMMAND_ACK", timeout,
                        lambda m: m.command == cmd and m.target_system in (0, self.mav.srcSystem))
        return None if ack is None else ack.result

    def set_param(self, name: str, value, ptype=mavlink.MAV_PARAM_TYPE_REAL32):
        self.mav.param_set_send(1, 1, name.encode(), value, ptype)
        return self.recv("PARAM_VALUE", 3.0, lambda m: m.param_id == name)

    def close(self) -> None:
        self.conn.close()


@pytest.fixture()
def sitl():
    with SitlThread(MISSION, speed=4.0) as s:
        yield s


@pytest.fixture()
def gcs(sitl):
    c = Client(sitl.url)
    c.hello()
    yield c
    c.close()


def test_heartbeat_and_telemetry(gcs):
    hb = gcs.recv("HEARTBEAT", 3.0)
    assert hb.get_srcSystem() == 1 and hb.get_srcComponent() == 1
    assert hb.type == mavlink.MAV_TYPE_QUADROTOR and hb.autopilot == mavlink.MAV_AUTOPILOT_PX4
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert not hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    assert hb.system_status == mavlink.MAV_STATE_STANDBY
    assert mavutil.mode_string_v10(hb) == "LOITER"
    assert gcs.recv("EXTENDED_SYS_STATE", 3.0).landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND
    assert gcs.recv("GPS_RAW_INT", 3.0).fix_type == mavlink.GPS_FIX_TYPE_3D_FIX
    home = gcs.recv("HOME_POSITION", 3.0)
    lp = gcs.recv("LOCAL_POSITION_NED", 3.0)
    assert (home.x, home.y) == pytest.approx((lp.x, lp.y), abs=1e-3)     # home is the start point
    lat, lon, alt = frames.enu2geodetic(home.y, home.x, -home.z, 44.8, -0.6, 30.0)   # mission home = map origin
    assert (home.latitude, home.longitude) == (round(lat * 1e7), round(lon * 1e7))
    assert home.altitude == round(alt * 1000)
    assert gcs.recv("SYS_STATUS", 3.0).onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_PREARM_CHECK
    assert gcs.recv("DISTANCE_SENSOR", 3.0) is not None
    imus = []
    while len(imus) < 200:
        m = gcs.recv("HIGHRES_IMU", 3.0)
        imus.append(m)
    t = np.array([m.time_usec for m in imus])
    assert np.all(np.diff(t) == 4000)              # every 250 Hz frame, vehicle time
    zacc = np.mean([m.zacc for m in imus])
    assert zacc == pytest.approx(-9.81, abs=0.05)   # at rest: specific force -g along FRD z
    # ATTITUDE is the onboard estimate (sim.onboard_state: estimate): level
    # within what one second of alignment on the paper's noise leaves
    # (a few mrad), not the exact true attitude
    att = gcs.recv("ATTITUDE", 3.0, lambda m: m.time_boot_ms > 2500)
    assert abs(att.roll) < 0.02 and abs(att.pitch) < 0.02
    assert (att.roll, att.pitch) != (0.0, 0.0)


def test_every_command_is_acked(gcs):
    assert gcs.command(mavlink.MAV_CMD_DO_SET_SERVO, 1, 1500) == mavlink.MAV_RESULT_UNSUPPORTED
    gcs.mav.command_int_send(1, 1, 0, mavlink.MAV_CMD_DO_SET_ROI_NONE, 0, 0, 0, 0, 0, 0, 0, 0, 0)
    ack = gcs.recv("COMMAND_ACK", 3.0, lambda m: m.command == mavlink.MAV_CMD_DO_SET_ROI_NONE)
    assert ack.result == mavlink.MAV_RESULT_UNSUPPORTED
    assert gcs.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == 0
    ver = gcs.recv("AUTOPILOT_VERSION", 3.0)
    assert ver.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    assert ver.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    assert gcs.command(mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1) == mavlink.MAV_RESULT_ACCEPTED
    assert gcs.recv("AUTOPILOT_VERSION", 3.0) is not None
    # AUTO.MISSION is refused without a stored mission; OFFBOARD needs a setpoint stream.
    assert gcs.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 4, 4) == mavlink.MAV_RESULT_DENIED
    assert gcs.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 6, 0) == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    assert gcs.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 3, 0) == mavlink.MAV_RESULT_ACCEPTED
    assert gcs.recv("HEARTBEAT", 3.0, lambda m: mavutil.mode_string_v10(m) == "POSCTL") is not None
    assert "Mode POSCTL" in gcs.texts
    # A command for another system is not ours: no answer at all.
    assert gcs.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, target=(42, 1), timeout=0.5) is None


def test_message_interval(gcs):
    assert gcs.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, LPOS, 4000) == mavlink.MAV_RESULT_ACCEPTED
    gcs.pump(0.2)
    n_imu = n_lpos = 0
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        m = gcs.recv(("HIGHRES_IMU", "LOCAL_POSITION_NED"), 1.0)
        if m is None:
            continue
        if m.get_type() == "HIGHRES_IMU":
            n_imu += 1
        else:
            n_lpos += 1
    assert n_imu > 100 and abs(n_lpos - n_imu) <= 2            # every frame now
    assert gcs.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, LPOS, -1) == mavlink.MAV_RESULT_ACCEPTED
    gcs.pump(0.1)
    assert gcs.recv("LOCAL_POSITION_NED", 0.5) is None
    assert gcs.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_HIGHRES_IMU, 1e5) == \
        mavlink.MAV_RESULT_DENIED                                   # the lockstep frame marker is fixed


def test_params_list_set_read(gcs):
    gcs.mav.param_request_list_send(1, 1)
    got = {}
    while len(got) < len(PARAM_SPECS):
        m = gcs.recv("PARAM_VALUE", 3.0)
        assert m is not None
        assert m.param_count == len(PARAM_SPECS)
        got[m.param_id] = m
    assert set(got) == {s.name for s in PARAM_SPECS}
    assert got["COM_OF_LOSS_T"].param_value == pytest.approx(1.0)
    assert got["COM_OBL_ACT"].param_type == mavlink.MAV_PARAM_TYPE_INT32

    m = gcs.set_param("COM_OF_LOSS_T", 2.5)
    assert m.param_value == pytest.approx(2.5)
    gcs.mav.param_request_read_send(1, 1, b"COM_OF_LOSS_T", -1)
    assert gcs.recv("PARAM_VALUE", 3.0).param_value == pytest.approx(2.5)
    # INT32 byte-wise, as PX4 and MAVSDK/MAVProxy expect
    import struct
    wire = struct.unpack("<f", struct.pack("<i", 2))[0]
    m = gcs.set_param("COM_OBL_ACT", wire, mavlink.MAV_PARAM_TYPE_INT32)
    assert struct.unpack("<i", struct.pack("<f", m.param_value))[0] == 2
    # out of range: refused, the old value is reported back, with a STATUSTEXT
    m = gcs.set_param("COM_OF_LOSS_T", 1e6)
    assert m.param_value == pytest.approx(2.5)
    assert any("COM_OF_LOSS_T" in t for t in gcs.texts)
    # unknown: no PARAM_VALUE (as PX4)
    gcs.mav.param_request_read_send(1, 1, b"NO_SUCH_PARAM", -1)
    assert gcs.recv("PARAM_VALUE", 0.5) is None


def upload(gcs, items):
    gcs.mav.mission_count_send(1, 1, len(items), 0)
    for _ in range(len(items)):
        req = gcs.recv(("MISSION_REQUEST_INT", "MISSION_REQUEST"), 3.0)
        assert req is not None
        it = items[req.seq]
        gcs.mav.mission_item_int_send(1, 1, req.seq, *it)
    return gcs.recv("MISSION_ACK", 3.0)


def test_mission_upload_download_clear(gcs):
    items = [(mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mavlink.MAV_CMD_NAV_WAYPOINT, 0, 1,
              0.0, 0.5, 0.0, 0.0, 448000000 + 100 * i, -6000000 - 50 * i, 1.5 + i, 0) for i in range(4)]
    ack = upload(gcs, items)
    assert ack.type == mavlink.MAV_MISSION_ACCEPTED
    gcs.mav.mission_request_list_send(1, 1, 0)
    count = gcs.recv("MISSION_COUNT", 3.0)
    assert count.count == 4
    for i in range(4):
        gcs.mav.mission_request_int_send(1, 1, i, 0)
        it = gcs.recv("MISSION_ITEM_INT", 3.0, lambda m: m.seq == i)
        assert (it.x, it.y, it.z, it.command) == (items[i][8], items[i][9], items[i][10], items[i][1])
    gcs.mav.mission_ack_send(1, 1, 0, 0)
    # legacy MISSION_REQUEST is answered with MISSION_ITEM_INT
    gcs.mav.mission_request_send(1, 1, 2, 0)
    assert gcs.recv("MISSION_ITEM_INT", 3.0, lambda m: m.seq == 2).x == items[2][8]
    gcs.mav.mission_clear_all_send(1, 1, 0)
    assert gcs.recv("MISSION_ACK", 3.0).type == mavlink.MAV_MISSION_ACCEPTED
    gcs.mav.mission_request_list_send(1, 1, 0)
    assert gcs.recv("MISSION_COUNT", 3.0).count == 0


def offboard_flight(gcs, height=2.0):
    """Arm, OFFBOARD after streaming setpoints, climb to ``height``; returns the
    start position (NED) and the setpoint sender."""
    p0 = gcs.recv("LOCAL_POSITION_NED", 3.0)
    sp = lambda: gcs.mav.set_position_target_local_ned_send(   # noqa: E731
        0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, POS_ONLY, p0.x, p0.y, p0.z - height, 0, 0, 0, 0, 0, 0, 0, 0)
    gcs.pump(0.3, sp)                                          # stream first (PX4 rule)
    assert gcs.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 6, 0) == mavlink.MAV_RESULT_ACCEPTED
    assert gcs.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    return p0, sp


def test_offboard_takeoff_hold_land_disarm(gcs):
    p0, sp = offboard_flight(gcs, 2.0)
    gcs.pump(2.0, sp)                                          # 8 s of vehicle time at speed 4
    lp = gcs.recv("LOCAL_POSITION_NED", 3.0)
    assert -lp.z == pytest.approx(-p0.z + 2.0, abs=0.1)
    assert math.hypot(lp.x - p0.x, lp.y - p0.y) < 0.1
    hb = gcs.recv("HEARTBEAT", 3.0)
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED and mavutil.mode_string_v10(hb) == "OFFBOARD"
    assert gcs.recv("EXTENDED_SYS_STATE", 3.0).landed_state == mavlink.MAV_LANDED_STATE_IN_AIR
    tgt = gcs.recv("POSITION_TARGET_LOCAL_NED", 3.0)
    assert tgt.z == pytest.approx(p0.z - 2.0, abs=1e-5)        # echo of the active setpoint
    assert gcs.command(mavlink.MAV_CMD_NAV_LAND) == mavlink.MAV_RESULT_ACCEPTED
    landed = gcs.recv("EXTENDED_SYS_STATE", 8.0, lambda m: m.landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND)
    assert landed is not None
    assert gcs.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0) == mavlink.MAV_RESULT_ACCEPTED
    hb = gcs.recv("HEARTBEAT", 3.0)
    assert not hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    lp = gcs.recv("LOCAL_POSITION_NED", 3.0)
    assert abs(lp.z - p0.z) < 0.05
    for t in ("Mode OFFBOARD", "Armed in OFFBOARD", "Mode AUTO.LAND", "Landing detected"):
        assert t in gcs.texts


def test_failsafes_actuator_stream_then_offboard_loss(gcs):
    assert gcs.set_param("COM_FAIL_ACT_T", 1.0).param_value == pytest.approx(1.0)
    p0, sp = offboard_flight(gcs, 2.0)
    gcs.pump(1.5, sp)
    z0 = -gcs.recv("LOCAL_POSITION_NED", 3.0).z
    assert z0 == pytest.approx(-p0.z + 2.0, abs=0.1)
    # Direct actuation overrides the onboard controller: 4 x 0.4 x 25 N < m g, it sinks.
    def sp_and_motors():
        sp()
        gcs.mav.hil_actuator_controls_send(0, [0.4] * 4 + [0.0] * 12, 0, 0)
    # (pumped until it has sunk: a loaded machine slows the free-running SITL's wall pacing)
    end = time.monotonic() + 5.0
    sunk = z0
    while sunk >= z0 - 0.1 and time.monotonic() < end:
        gcs.pump(0.05, sp_and_motors, period=0.01)
        sunk = -gcs.recv("LOCAL_POSITION_NED", 3.0).z
    assert sunk < z0 - 0.1 and "Actuator override active" in gcs.texts
    # Stream stops: the onboard controller takes over and holds the (still fresh) setpoint.
    gcs.pump(0.3, sp)
    assert "Actuator stream lost: onboard controller holds" in gcs.texts
    back = None
    end = time.monotonic() + 5.0
    while back is None and time.monotonic() < end:
        gcs.pump(0.05, sp)
        back = gcs.recv("LOCAL_POSITION_NED", 0.5, lambda m: abs(-m.z - (-p0.z + 2.0)) < 0.1)
    assert back is not None
    # Setpoints stop: hold (AUTO.LOITER) for COM_FAIL_ACT_T, then land and disarm.
    hold = gcs.recv("HEARTBEAT", 3.0, lambda m: mavutil.mode_string_v10(m) == "LOITER")
    assert hold is not None and hold.system_status == mavlink.MAV_STATE_CRITICAL
    assert "Failsafe: offboard setpoints lost, holding" in gcs.texts
    assert gcs.recv("HEARTBEAT", 3.0, lambda m: mavutil.mode_string_v10(m) == "LAND") is not None
    if "Failsafe: landing" not in gcs.texts:      # the text may follow the HEARTBEAT that shows LAND
        gcs.recv("STATUSTEXT", 1.0, lambda m: "Failsafe: landing" in m.text)
    assert "Failsafe: landing" in gcs.texts
    assert gcs.recv("HEARTBEAT", 5.0, lambda m: not m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED) is not None
    assert abs(gcs.recv("LOCAL_POSITION_NED", 3.0).z - p0.z) < 0.05


def test_extra_output_link(tmp_path):
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.settimeout(3.0)
    out = f"udpout:127.0.0.1:{sink.getsockname()[1]}"
    try:
        with SitlThread(MISSION, outs=[out], speed=4.0):
            rx = mavlink.MAVLink(None)
            types = set()
            end = time.monotonic() + 3.0
            while not {"HEARTBEAT", "HIGHRES_IMU"} <= types and time.monotonic() < end:
                for m in rx.parse_buffer(sink.recv(65535)) or []:
                    types.add(m.get_type())
            assert {"HEARTBEAT", "HIGHRES_IMU"} <= types      # a ground station on --out sees the vehicle
    finally:
        sink.close()


def test_cli_bad_input_and_clean_stop(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    run = lambda *a: subprocess.run([sys.executable, "-m", "sitl", *a], capture_output=True, text=True,   # noqa: E731
                                    env=env, timeout=60)
    r = run(str(tmp_path / "nope.yaml"))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "nope.yaml: no such file" in r.stderr
    r = run(str(MISSION), "--listen", "udpin:localhost")
    assert r.returncode == 2 and "--listen" in r.stderr and r.stderr.count("\n") == 1
    r = run(str(MISSION), "--sensor-hz", "300")
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    with SitlProcess(MISSION, speed=1.0) as proc:
        c = Client(proc.url)
        c.hello()
        c.close()
        assert proc.stop() == 0                               # SIGTERM: clean exit


def test_garbage_never_crashes_then_flies(sitl, gcs):
    rng = np.random.default_rng(11)
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    host, port = sitl.listen.split(":")[1:]
    dest = (host, int(port))
    good = gcs.mav.command_long_encode(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0).pack(gcs.mav)
    for i in range(300):
        raw.sendto(rng.bytes(int(rng.integers(1, 300))), dest)                 # random bytes
        raw.sendto(good[: int(rng.integers(1, len(good)))], dest)              # truncated packets
        bad = bytearray(good)
        bad[int(rng.integers(10, len(bad)))] ^= 0xFF
        raw.sendto(bytes(bad), dest)                                           # corrupt CRC/payload
    other = Client(sitl.url, sysid=7, compid=1)
    other.mav.command_long_send(42, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 21196, 0, 0, 0, 0, 0)
    other.mav.set_position_target_local_ned_send(0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0, *([NAN] * 11))
    other.mav.set_position_target_local_ned_send(0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0, 1e30, -1e30, 1e30,
                                                 *([0.0] * 8))
    other.mav.set_position_target_local_ned_send(0, 1, 1, 99, 0, *([0.0] * 11))
    other.mav.hil_actuator_controls_send(0, [0.5, NAN, math.inf, -math.inf] + [0.0] * 12, 0, 0)
    other.mav.param_set_send(1, 1, b"COM_OF_LOSS_T", NAN, mavlink.MAV_PARAM_TYPE_REAL32)
    other.mav.param_set_send(1, 1, b"\xff\xfe", 1.0, mavlink.MAV_PARAM_TYPE_REAL32)
    other.mav.param_request_read_send(1, 1, b"", 10_000)
    other.mav.command_long_send(1, 1, mavlink.MAV_CMD_NAV_TAKEOFF, 0, *([NAN] * 6), 1e38)
    other.mav.command_long_send(1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, NAN, NAN, NAN, 0, 0, 0, 0)
    other.mav.command_long_send(1, 1, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0, 1e30, -1e30, 0, 0, 0, 0, 0)
    other.mav.mission_item_int_send(1, 1, 65535, 0, 16, 0, 1, NAN, NAN, NAN, NAN, 0, 0, NAN, 0)
    other.mav.mission_count_send(1, 1, 65535, 0)
    other.mav.mission_request_int_send(1, 1, 40000, 0)
    other.mav.setup_signing_send(9, 9, bytes(32), 0)
    other.pump(0.3)
    other.close()
    assert not gcs.recv("HEARTBEAT", 3.0).base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    raw.close()
    # Still alive and flying: AUTO takeoff to 2 m (param7 AMSL: home 30 m + 2 m), hold.
    assert gcs.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, NAN, NAN, NAN, 32.0) == mavlink.MAV_RESULT_ACCEPTED
    assert gcs.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    hold = gcs.recv("HEARTBEAT", 8.0, lambda m: mavutil.mode_string_v10(m) == "LOITER")
    assert hold is not None and "Takeoff complete: Mode AUTO.LOITER" in gcs.texts
    gcs.pump(1.0)
    assert -gcs.recv("LOCAL_POSITION_NED", 3.0).z == pytest.approx(2.0, abs=0.15)
    assert sitl.server.stats["bad_packets"] > 0


# --- lockstep ---------------------------------------------------------------------------


def lockstep_run(n_frames: int, seed: int = 7):
    """Fly n frames in lockstep answering each HIGHRES_IMU; returns the IMU tuples."""
    with SitlThread(MISSION, lockstep=True, speed=0.0, seed=seed) as s:
        c = Client(s.url, sysid=1, compid=191)
        c.mav.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        out = []
        engaged = False
        while len(out) < n_frames:
            m = c.recv("HIGHRES_IMU", 5.0)
            assert m is not None
            if engaged:
                out.append((m.time_usec, m.xacc, m.yacc, m.zacc, m.xgyro, m.ygyro, m.zgyro, m.xmag))
                if len(out) == 20:   # a takeoff mid-run: it must land on the same frame both times
                    c.mav.command_long_send(1, 1, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, NAN, NAN, NAN, 32.0)
                    c.mav.command_long_send(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            c.mav.hil_actuator_controls_send(m.time_usec, [NAN] * 16, 0, 1)
            engaged = True
        c.close()
    return out


def test_lockstep_is_deterministic():
    a = lockstep_run(300)
    b = lockstep_run(300)
    assert a == b
    t = np.array([x[0] for x in a])
    assert np.all(np.diff(t) == 4000)                 # no frame skipped while engaged
    # the takeoff happened: the vertical specific force exceeded g at some point
    assert min(x[3] for x in a) < -10.5
    assert lockstep_run(50, seed=8)[:50] != a[:50]


def test_lockstep_time_stalls_without_answers():
    with SitlThread(MISSION, lockstep=True, speed=1.0) as s:
        c = Client(s.url, sysid=1, compid=191)
        c.hello()
        assert c.set_param("SIM_LS_TMO", 1.5).param_value == pytest.approx(1.5)
        for _ in range(30):
            m = c.recv("HIGHRES_IMU", 3.0)
            c.mav.hil_actuator_controls_send(m.time_usec, [NAN] * 16, 0, 1)
        last = c.recv("HIGHRES_IMU", 3.0)              # answered by nobody from here on
        t_stall = time.monotonic()
        seen = []
        while time.monotonic() - t_stall < 1.2:
            m = c.recv(("HIGHRES_IMU", "HEARTBEAT"), 0.1)
            if m is not None:
                seen.append(m.get_type())
        assert "HIGHRES_IMU" not in seen               # vehicle time does not advance...
        assert s.server.time_us == last.time_usec
        assert "HEARTBEAT" in seen                     # ...but the link is kept alive
        resumed = c.recv("HIGHRES_IMU", 3.0)           # after SIM_LS_TMO: free-running
        assert resumed is not None and time.monotonic() - t_stall >= 1.4
        assert resumed.time_usec > last.time_usec
        assert "Lockstep peer silent for 1.5 s: free-running" in c.texts
        c.close()


def test_actuator_controls_without_the_lockstep_flag_do_not_engage_lockstep():
    """HIL_ACTUATOR_CONTROLS with flags & 1 == 0 answer nothing: the vehicle
    clock stays on the first frame and lockstep stays off; the same answer
    with the flag engages it (PX4's HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP)."""
    with SitlThread(MISSION, lockstep=True, speed=0.0) as s:
        c = Client(s.url, sysid=1, compid=191)
        c.mav.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        first = c.recv("HIGHRES_IMU", 5.0)
        end = time.monotonic() + 1.0
        while time.monotonic() < end:       # answer every (re-sent) frame, flag clear
            m = c.recv("HIGHRES_IMU", 0.3)
            t = first.time_usec if m is None else m.time_usec
            c.mav.hil_actuator_controls_send(t, [NAN] * 16, 0, 0)
        assert not s.server.lockstep_engaged
        assert s.server.time_us == first.time_usec          # vehicle time did not move
        assert "Lockstep engaged" not in c.texts
        c.mav.hil_actuator_controls_send(first.time_usec, [NAN] * 16, 0, 1)
        nxt = c.recv("HIGHRES_IMU", 3.0, lambda m: m.time_usec > first.time_usec)
        assert nxt is not None and s.server.lockstep_engaged
        c.close()


def signed(m) -> bool:
    return bool(m.get_msgbuf()[2] & mavlink.MAVLINK_IFLAG_SIGNED)


def test_signing(gcs):
    """SETUP_SIGNING from a controller (as MAVProxy's ``signing setup``): the SITL
    signs from then on and wants signed control; the key holder turns it off again."""
    from mavcore.link.signing import enable_outgoing_signing, signing_timestamp

    key = bytes(range(1, 33))
    gcs.mav.setup_signing_send(1, 1, key, 1)
    m = gcs.recv("HIGHRES_IMU", 3.0, signed)
    assert m is not None
    rx = mavlink.MAVLink(None)
    rx.signing.secret_key = key
    assert rx.parse_buffer(bytes(m.get_msgbuf()))[0].get_signed()    # verifies with the key
    gcs.mav.setup_signing_send(1, 1, bytes(32), 0)                   # unsigned: ignored now
    gcs.pump(0.5)
    assert any("SETUP_SIGNING" in t and t.endswith(": unsigned") for t in gcs.texts), gcs.texts
    assert gcs.recv("HIGHRES_IMU", 1.0, signed) is not None
    enable_outgoing_signing(gcs.mav, key, 0, signing_timestamp(time.time()))
    gcs.mav.signing.allow_unsigned_callback = lambda mav, msg_id: True   # to see the unsigned stream
    gcs.mav.setup_signing_send(1, 1, bytes(32), 0)                   # signed all-zero key: off
    assert gcs.recv("HIGHRES_IMU", 3.0, lambda m: not signed(m)) is not None


def test_launch_pose_option(capsys):
    """``--start X,Y[,YAW_DEG]``: the vehicle is set down there (z on the ground), heading
    YAW_DEG from east; malformed values are one line and exit 2."""
    from sitl.cli import main, parse_start

    assert parse_start("3, -4") == (3.0, -4.0, 0.0)
    assert parse_start("3,4,90") == (3.0, 4.0, 90.0)
    for bad in ("x,2", "1", "1,2,3,4", "nan,1", "1,inf"):
        assert main([str(MISSION), "--start", bad]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--start" in err
    with SitlThread(MISSION, speed=0.0, start=(6.5, 4.25, 90.0)) as s:
        t = s.server.vehicle.sim.truth
        assert tuple(t.pos_enu_m[:2]) == pytest.approx((6.5, 4.25), abs=1e-12)
        assert t.landed and t.pos_enu_m[2] == pytest.approx(s.server.vehicle.sim.world.ground_height(6.5, 4.25))
        # body x (first column of R_enu_flu) points north for a heading of 90 deg
        assert np.asarray(t.R)[:, 0] == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)
    p = SitlProcess(MISSION, start=(-1.5, 2.0))
    assert "--start=-1.5,2.0,0.0" in p.command()


def test_rangefinder_rate_parameter(sitl, gcs):
    """SIM_RNG_HZ sets every rangefinder's rate (vehicle time); 0 leaves the rates as they are."""
    def median_period_ms(seconds=1.0):
        t = {}
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            m = gcs.recv("DISTANCE_SENSOR", 0.5)
            if m is not None:
                t.setdefault(m.id, []).append(m.time_boot_ms)
        return {i: float(np.median(np.diff(v))) for i, v in t.items() if len(v) > 3}

    configured = {rf.cfg.id: 1000.0 / rf.cfg.rate_hz for rf in sitl.server.vehicle.sim.sensors.rangefinders}
    assert gcs.set_param("SIM_RNG_HZ", 50.0).param_value == pytest.approx(50.0)
    periods = median_period_ms()
    assert periods and all(p == pytest.approx(20.0, abs=4.0) for p in periods.values())
    assert gcs.set_param("SIM_RNG_HZ", 0.0).param_value == 0.0
    # the configured rates come back only through SET_MESSAGE_INTERVAL(0) (default rate)
    assert gcs.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR, 0) == 0
    periods = median_period_ms()
    assert periods and all(p == pytest.approx(configured[i], abs=4.0) for i, p in periods.items())
