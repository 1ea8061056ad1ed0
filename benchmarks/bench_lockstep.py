"""SITL in lockstep over MAVLink/UDP against a minimal peer: frames per second
and real-time factor.

Usage::

    python benchmarks/bench_lockstep.py [--mission missions/flat-rectangle/mission.yaml]
        [--seconds 60] [--runs 3]

Starts ``python -m sitl MISSION --lockstep --speed 0`` (1 kHz physics, 250 Hz
sensor frames) as a subprocess. The peer (this script) arms the vehicle and
commands NAV_TAKEOFF to 2 m, so the SITL's own cascaded controller flies
(take-off, then hold) while the peer answers every HIGHRES_IMU with a NaN-tick
HIL_ACTUATOR_CONTROLS (lockstep flag, no override) straight from the datagram
bytes, doing as little as possible itself; like the SITL (SIM_LS_SPIN) and the
companion (RunnerConfig.spin_us) it busy-polls its socket for 300 us before
sleeping in the kernel. Each run measures ``--seconds`` of
vehicle time after lockstep engages; prints per-run and median frames/s and
real-time factor, plus the SITL's CPU time per frame (from /proc). ``--free``: no
lockstep; the SITL free-runs at ``--speed 0`` and the peer only listens. Target
(issue 3): >= 50x real time.
"""

from __future__ import annotations

import argparse
import os
import socket
import statistics
import struct
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

from mavcore import codec  # noqa: E402
from sitl.api import SitlProcess  # noqa: E402

_IMU_ID = mavlink.MAVLINK_MSG_ID_HIGHRES_IMU
_Q = struct.Struct("<Q")


def _last_packet(data: bytes):
    """(msgid, payload offset) of the last MAVLink 2 packet of a datagram, or None."""
    i, n, last = 0, len(data), None
    while i + 12 <= n and data[i] == 0xFD:
        end = i + 12 + data[i + 1] + (13 if data[i + 2] & 1 else 0)
        last = (data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16, i + 10)
        i = end
    return last


def _proc_cpu_s(pid: int) -> tuple[float, float]:
    """(user, system) CPU seconds of process ``pid``."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    tck = os.sysconf("SC_CLK_TCK")
    return int(fields[11]) / tck, int(fields[12]) / tck


def one_run(mission: str, seconds: float, lockstep: bool = True) -> dict:
    """One measured run. ``lockstep=False``: the SITL free-runs at ``--speed 0``
    (no actuator peer, nothing waits) and the peer only reads the telemetry."""
    with SitlProcess(mission, lockstep=lockstep, speed=0.0) as sitl:
        host, port = sitl.listen.split(":", 1)[1].rsplit(":", 1)
        addr = (host, int(port))
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.settimeout(5.0)
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
        seq = [0]

        def send(msg):
            sock.sendto(msg.pack(mav), addr)

        def answer(t_us):
            sock.sendto(codec.pack_hil_actuator_controls(seq[0], 1, 191, t_us, None, True), addr)
            seq[0] = (seq[0] + 1) & 0xFF

        send(mav.heartbeat_encode(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 4))
        # engage lockstep and arm/take off (commands are served between frames)
        cmds = [mav.command_long_encode(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0),
                mav.command_long_encode(1, 1, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, math_nan, math_nan,
                                        math_nan, 2.0 + 30.0)]
        frames = 0
        t_first = None
        wall0 = cpu0 = None
        n_target = None
        t0_pending = True
        sock.setblocking(False)
        def recv():
            # spin on the socket (the SITL answers within tens of microseconds), then block
            t_end = time.perf_counter() + 300e-6
            while time.perf_counter() < t_end:
                try:
                    return sock.recv(65536)
                except BlockingIOError:
                    pass
            sock.settimeout(5.0)
            try:
                return sock.recv(65536)
            finally:
                sock.setblocking(False)

        while True:
            data = recv()
            last = _last_packet(data)
            if last is None or last[0] != _IMU_ID:
                continue
            (t_us,) = _Q.unpack_from(data, last[1])
            if t_first is None:
                t_first = t_us
            # a few frames in, send the commands once
            if cmds and frames in (5, 10):
                send(cmds.pop(0))
            if lockstep:
                answer(t_us)
                frames += 1
            else:  # free running: datagrams may be dropped; count vehicle frames
                frames = (t_us - t_first) // 4000 + 1
            if t0_pending and frames >= 250:   # 1 s of vehicle time: lockstep engaged, take-off started
                wall0, cpu0, t0 = time.perf_counter(), _proc_cpu_s(sitl.proc.pid), t_us
                n0, t0_pending = frames, False
                n_target = frames + int(seconds * 250)
            if n_target is not None and frames >= n_target:
                wall = time.perf_counter() - wall0
                u1, s1 = _proc_cpu_s(sitl.proc.pid)
                usr, sys_ = u1 - cpu0[0], s1 - cpu0[1]
                cpu = usr + sys_
                vt = (t_us - t0) * 1e-6
                n = frames - n0
                sock.close()
                return {"frames_per_s": n / wall, "rtf": vt / wall, "sitl_cpu_us_per_frame": cpu / n * 1e6,
                        "wall_us_per_frame": wall / n * 1e6, "sitl_sys_us_per_frame": sys_ / n * 1e6}


math_nan = float("nan")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mission", default=str(ROOT / "missions/flat-rectangle/mission.yaml"))
    ap.add_argument("--seconds", type=float, default=60.0, help="vehicle seconds per run")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--free", action="store_true",
                    help="no lockstep: the SITL free-runs at --speed 0 (onboard controller, telemetry over UDP)")
    args = ap.parse_args()
    res = []
    for k in range(args.runs):
        r = one_run(args.mission, args.seconds, lockstep=not args.free)
        res.append(r)
        print(f"run {k + 1}: {r['frames_per_s']:.0f} frames/s, {r['rtf']:.1f}x real time, "
              f"wall {r['wall_us_per_frame']:.0f} us/frame, SITL CPU {r['sitl_cpu_us_per_frame']:.0f} us/frame "
              f"({r['sitl_sys_us_per_frame']:.0f} system)",
              flush=True)
    med = {k: statistics.median(r[k] for r in res) for k in res[0]}
    mode = "free-running --speed 0" if args.free else "lockstep"
    print(f"median of {args.runs} ({mode}): {med['frames_per_s']:.0f} frames/s, {med['rtf']:.1f}x real time "
          f"(target >= 50x), SITL CPU {med['sitl_cpu_us_per_frame']:.0f} us/frame")
    return 0


if __name__ == "__main__":
    sys.exit(main())
