"""CPU per sensor frame of the SITL's telemetry send (``SitlServer._send_telemetry``), run against a
tree given as argv[1] (issue 17 "h17-svc": the stream schedule moved to ``mavcore.services.telemetry``
and the encoders to ``sitl.telemetry``; compare with the branch point, interleaved, fresh processes).

A ``SitlServer`` (no sockets) of the flat-rectangle mission holds on the ground with one stand-in link
that packs every message as the real link does (``FastPacker.pack`` / ``msg.pack``) and keeps nothing;
``step_once`` runs 5000 frames (20 s of vehicle time at 250 Hz, the default streams plus LOCAL_POSITION_NED
and ODOMETRY every frame as ``companion demo`` asks) and only the time inside ``_send_telemetry`` is
summed (``time.process_time``). Prints us per frame.

``--opcodes`` (h17-fin): instead of timing, count the Python bytecode instructions executed and the
Python frames entered per frame inside ``_send_telemetry`` (``--opcodes step``: the whole
``step_once``) over 1000 frames, with ``sys.settrace`` and ``f_trace_opcodes``: a deterministic
figure, independent of the machine's load (the trace itself is slow; nothing is timed).
"""
import sys
import time

root = sys.argv[1]
opcodes = sys.argv[2:3] == ["--opcodes"]
whole_step = opcodes and sys.argv[3:4] == ["step"]
sys.path.insert(0, root)
from pymavlink.dialects.v20 import common as mavlink   # noqa: E402

from mavcore.mission import load_mission   # noqa: E402
from sitl.server import SitlServer   # noqa: E402


class _Link:
    has_peer = True

    def __init__(self):
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self.n = 0

    def begin_frame(self):
        pass

    def end_frame(self):
        pass

    def send_fast(self, packer, args):
        self.n += len(packer.pack(self.mav, args))

    def send(self, msg):
        self.n += len(msg.pack(self.mav))

    def reply(self, msg, addr=None):
        self.send(msg)


srv = SitlServer(load_mission(f"{root}/missions/flat-rectangle/mission.yaml"))
srv.links = [_Link()]
period = srv.vehicle.sim.sensor_period_us
for mid in (mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, mavlink.MAVLINK_MSG_ID_ODOMETRY):
    # through the command table, as a SET_MESSAGE_INTERVAL from the companion (``CommandServer.handle``;
    # SitlServer's own ``_command`` went to sitl/command_link.py in h17-svc2, which broke this script)
    reply = srv.commands.handle(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, (mid, period, 0, 0, 0, 0, 0))
    assert reply.result == mavlink.MAV_RESULT_ACCEPTED, reply
send = srv._send_telemetry
spent = [0.0]


def timed(frame):
    c0 = time.process_time()
    send(frame)
    spent[0] += time.process_time() - c0


counts = [0, 0]    # opcodes, frames entered


def _local(frame, event, arg):
    frame.f_trace_opcodes = True
    if event == "opcode":
        counts[0] += 1
    return _local


def _enter(frame, event, arg):
    frame.f_trace_opcodes = True
    counts[1] += 1
    return _local


def traced(call, *args):
    sys.settrace(_enter)
    try:
        call(*args)
    finally:
        sys.settrace(None)


if opcodes:
    N = 1000
    if whole_step:
        for _ in range(N):
            traced(srv.step_once)
    else:
        srv._send_telemetry = lambda frame: traced(send, frame)
        for _ in range(N):
            srv.step_once()
    where = "step_once" if whole_step else "send_telemetry"
    print(f"{where}_opcodes={counts[0] / N:.1f} {where}_frames={counts[1] / N:.2f}")
else:
    srv._send_telemetry = timed
    N = 5000
    for _ in range(N):
        srv.step_once()
    print(f"send_telemetry_us={spent[0] / N * 1e6:.3f} bytes={srv.links[0].n}")
