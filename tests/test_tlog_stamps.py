"""How the companion's link writes its .tlog: order and stamps, over real UDP on loopback.

A fake vehicle sends datagrams; the test plays the runner (handles each
message in order, sends what it would, stamps with a vehicle clock mapped
onto a fixed epoch). Every received packet must be stamped with the vehicle
time of its own sensor frame, and every packet sent must follow the packets
it answers, even when a reply goes out before the frame is handled (a
COMMAND_ACK batched with the next frame) or one poll returns several frames.
"""

from __future__ import annotations

import socket
import time

from pymavlink.dialects.v20 import common as mavlink

from companion.link.connection import Connection
from companion.link.tlog import TlogWriter, read_tlog

EPOCH_US = 1_700_000_000_000_000


class Runner:
    """The runner's part: vehicle time from HIGHRES_IMU, an answer per frame, a command per ACK."""

    def __init__(self, conn: Connection) -> None:
        self.conn = conn
        self.t_us = None
        conn.clock = lambda: EPOCH_US + (self.t_us if self.t_us is not None else 0)

    def handle(self, msgs) -> None:
        for m in msgs:
            if m.get_type() == "HIGHRES_IMU":
                self.t_us = m.time_usec
                self.conn.send_actuators(m.time_usec, (0.5, 0.5, 0.5, 0.5), True)
            elif m.get_type() == "COMMAND_ACK":
                self.conn.send(self.conn.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))


def frame(mav, t_us: int) -> bytes:
    return (mav.local_position_ned_encode(t_us // 1000, 1.0, 2.0, 3.0, 0, 0, 0).pack(mav)
            + mav.highres_imu_encode(t_us, 0, 0, -9.8, 0, 0, 0, 0.2, 0, 0.4, 0, 0, 0, 0, 0).pack(mav))


def poll_until(conn, n, runner):
    got = []
    deadline = time.monotonic() + 3.0
    while len(got) < n and time.monotonic() < deadline:
        msgs = conn.poll(0.05)
        got += msgs
        runner.handle(msgs)
    assert len(got) == n


def test_frames_stamped_with_their_own_time_and_replies_after_what_they_answer(tmp_path):
    veh = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    veh.bind(("127.0.0.1", 0))
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    path = tmp_path / "s.tlog"
    w = TlogWriter(path).open()
    conn = Connection(f"udpout:127.0.0.1:{veh.getsockname()[1]}", tlog=w).open()
    runner = Runner(conn)
    try:
        conn.send_heartbeat()                                  # before the vehicle clock: epoch + 0
        _, addr = veh.recvfrom(65536)
        # the link believes a vehicle only from the address of its first heartbeat
        veh.sendto(mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav), addr)
        poll_until(conn, 1, runner)
        # frame 1 alone; then an ACK datagram batched (frame_sync) with frame 2
        conn.frame_sync = True
        veh.sendto(frame(mav, 4000), addr)
        poll_until(conn, 2, runner)
        veh.sendto(mav.command_ack_encode(176, 0, 0, 0, 0, 0).pack(mav), addr)
        veh.sendto(frame(mav, 8000), addr)
        poll_until(conn, 3, runner)
        # two frames in one poll (a vehicle running free)
        conn.frame_sync = False
        veh.sendto(frame(mav, 12000), addr)
        veh.sendto(frame(mav, 16000), addr)
        time.sleep(0.2)
        poll_until(conn, 4, runner)
    finally:
        conn.close()
        w.close()
        veh.close()
    recs = [(r.time_usec - EPOCH_US, r.msg.get_type(), r.msg.get_srcComponent()) for r in read_tlog(path)]
    assert recs == [
        (0, "HEARTBEAT", 191), (0, "HEARTBEAT", 1),            # both before the vehicle clock runs
        (4000, "LOCAL_POSITION_NED", 1), (4000, "HIGHRES_IMU", 1), (4000, "HIL_ACTUATOR_CONTROLS", 191),
        # the reply to the ACK left before frame 2 was handled, and is recorded after the packets it answers
        (8000, "COMMAND_ACK", 1), (8000, "LOCAL_POSITION_NED", 1), (8000, "HIGHRES_IMU", 1),
        (8000, "COMMAND_LONG", 191), (8000, "HIL_ACTUATOR_CONTROLS", 191),
        (12000, "LOCAL_POSITION_NED", 1), (12000, "HIGHRES_IMU", 1), (12000, "HIL_ACTUATOR_CONTROLS", 191),
        (16000, "LOCAL_POSITION_NED", 1), (16000, "HIGHRES_IMU", 1), (16000, "HIL_ACTUATOR_CONTROLS", 191),
    ]


def test_writer_flushes_on_tick_when_nothing_new_is_written(tmp_path):
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    path = tmp_path / "t.tlog"
    w = TlogWriter(path, flush_interval_s=0.3).open()
    try:
        w.tick()                                  # nothing due yet
        w.write(mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav), 1)
        assert path.stat().st_size == 0           # buffered: the interval has not passed
        time.sleep(0.31)
        w.tick()
        assert path.stat().st_size == 8 + 21      # on disk without another write
    finally:
        w.close()
