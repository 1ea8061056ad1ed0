"""What the end-to-end flights of the planner's exported mission share
(tests/test_sitl_mission_e2e.py with MAVSDK, tests/test_sitl_mavproxy_mission.py
with MAVProxy): cutting the mission after its first row, MAVProxy in a
subprocess, a MAVLink listener on the SITL's telemetry link, recording the
flown path and checking it against the plan's way-points.

The path check (``check_flown_path``): every way-point within its acceptance
radius R of the flown path (horizontally), passed in order, where the truth may be off
the stack's judgement by the estimate's error; and the lateral deviation from
the planned legs at most R + v^2 / (2 g tan(tilt_max)): the leg target moves
on once the vehicle is inside R (a corner is cut by at most R), and at a
corner taken at speed v the vehicle overshoots by at most the stopping
distance at its largest tilt.
"""

from __future__ import annotations

import math
import os
import queue
import re
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

NAV_WAYPOINT, NAV_RETURN_TO_LAUNCH, DO_CHANGE_SPEED = 16, 20, 178
#: Way-points flown: the three of the transit and the seven of the first row.
N_WAYPOINTS = 10
#: The SITL's tilt limit (MPC_TILTMAX_AIR; ArduCopter ANGLE_MAX 3000 cdeg is 30 deg, tighter).
TILT_MAX_DEG = 35.0


def wait_until(pred, timeout_s: float, period_s: float = 0.02) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(period_s)
    return pred()


def point_segment_distance(p, a, b) -> float:
    ab = b - a
    t = float(np.clip((p - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * ab)))


def cut_index(commands, first: int = 0) -> int:
    """Index of the N_WAYPOINTS-th NAV_WAYPOINT at or after ``first``."""
    return [i for i, c in enumerate(commands) if c == NAV_WAYPOINT and i >= first][N_WAYPOINTS - 1]


# --- "QGC WPL 110" files (MAVProxy's ``wp load`` / ``fence load``) ----------------


@dataclass(frozen=True)
class WplItem:
    seq: int
    frame: int
    command: int
    params: tuple[float, float, float, float]
    lat_deg: float
    lon_deg: float
    alt_m: float


def wpl_items(text: str) -> list[WplItem]:
    lines = text.splitlines()
    assert lines[0] == "QGC WPL 110"
    out = []
    for line in lines[1:]:
        f = line.split("\t")
        out.append(WplItem(int(f[0]), int(f[2]), int(f[3]), tuple(float(v) for v in f[4:8]),
                           float(f[8]), float(f[9]), float(f[10])))
    return out


def cut_wpl(text: str, keep_home: bool) -> str:
    """The exported WPL cut after the first row, then its own last item (RTL),
    renumbered. Line 0 of the file is the planned home: ArduPilot's item 0
    (``keep_home``); PX4 would fly it as a way-point, so it is dropped."""
    lines = text.splitlines()
    body = lines[2:]
    commands = [int(line.split("\t")[3]) for line in body]
    k = cut_index(commands)
    kept = ([lines[1]] if keep_home else []) + body[:k + 1] + [body[-1]]
    assert int(kept[-1].split("\t")[3]) == NAV_RETURN_TO_LAUNCH
    out = [lines[0]]
    for seq, line in enumerate(kept):
        f = line.split("\t")
        f[0], f[1] = str(seq), "1" if seq == 0 else "0"
        out.append("\t".join(f))
    return "\n".join(out) + "\n"


def fence_wpl(polygon_latlon) -> str:
    """An inclusion polygon as the "QGC WPL 110" fence file MAVProxy's ``fence
    load`` reads (NAV_FENCE_POLYGON_VERTEX_INCLUSION 5001, param1 = vertex count)."""
    n = len(polygon_latlon)
    rows = [f"{i}\t0\t0\t5001\t{n}\t0\t0\t0\t{lat:.10f}\t{lon:.10f}\t0\t1" for i, (lat, lon) in enumerate(polygon_latlon)]
    return "\n".join(["QGC WPL 110", *rows]) + "\n"


# --- MAVProxy and a MAVLink listener ------------------------------------------


class MavProxy:
    """MAVProxy (from PyPI, unmodified) in a subprocess, its console read line by line."""

    def __init__(self, master: str, workdir: Path, modules: str = "param,wp,mode,cmdlong,fence") -> None:
        cmd = [sys.executable, "-m", "MAVProxy.mavproxy", f"--master={master}", "--no-state", "--mav20",
               f"--default-modules={modules}"]
        self.p = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                  text=True, bufsize=1, cwd=workdir, env=dict(os.environ, TERM="dumb"))
        self.q: queue.Queue = queue.Queue()
        self.out: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.p.stdout:
            self.q.put(line)
        self.q.put(None)

    def expect(self, pattern: str, timeout_s: float = 10.0) -> re.Match:
        rx = re.compile(pattern)
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            try:
                line = self.q.get(timeout=0.1)
            except queue.Empty:
                continue
            assert line is not None, "MAVProxy exited:\n" + "".join(self.out[-30:])
            self.out.append(line)
            m = rx.search(line)
            if m:
                return m
        raise AssertionError(f"no {pattern!r} from MAVProxy within {timeout_s} s:\n" + "".join(self.out[-30:]))

    def send(self, command: str) -> None:
        self.p.stdin.write(command + "\n")
        self.p.stdin.flush()

    def close(self) -> None:
        if self.p.poll() is None:
            self.p.terminate()
            try:
                self.p.wait(5)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait(5)
        self.p.stdin.close()
        self.p.stdout.close()


class Listener:
    """The SITL's telemetry on a UDP port of its own (``SitlThread(outs=...)``),
    read on a thread: MISSION_ITEM_REACHED sequence numbers and STATUSTEXTs."""

    def __init__(self) -> None:
        from pymavlink import mavutil

        probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        probe.bind(("127.0.0.1", 0))
        self.port = probe.getsockname()[1]
        probe.close()
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{self.port}")
        self.conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        self.reached: list[int] = []
        self.texts: list[str] = []
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()

    @property
    def url(self) -> str:
        return f"udpout:127.0.0.1:{self.port}"

    def _run(self) -> None:
        while not self._stop.is_set():
            m = self.conn.recv_match(type=["MISSION_ITEM_REACHED", "STATUSTEXT"], blocking=True, timeout=0.2)
            if m is None:
                continue
            if m.get_type() == "MISSION_ITEM_REACHED":
                self.reached.append(int(m.seq))
            else:
                self.texts.append(m.text)

    def close(self) -> None:
        self._stop.set()
        self._t.join(2)
        self.conn.close()


# --- the flight and its checks -------------------------------------------------


@dataclass
class FlownPath:
    """Ground truth sampled while the mission flew (world ENU, m), the largest
    horizontal gap between the stack's estimate and the truth, and whether the
    geofence was ever breached."""

    path: np.ndarray
    nav_err_m: float
    breached: bool


def record_flight(srv, done, timeout_s: float) -> FlownPath:
    """Sample the SITL's truth until ``done()`` (asserted) or ``timeout_s``."""
    path, nav_err, breached = [], 0.0, False
    end = time.monotonic() + timeout_s
    while not done() and time.monotonic() < end:
        p, est = srv.vehicle.sim.plant.p, srv.vehicle.frame.estimate
        path.append(tuple(p))
        nav_err = max(nav_err, math.hypot(est.pos_enu_m[0] - p[0], est.pos_enu_m[1] - p[1]))
        breached |= srv.vehicle.stack.fence_breached
        time.sleep(0.002)
    path.append(tuple(srv.vehicle.sim.plant.p))
    assert done(), "the mission did not complete"
    return FlownPath(np.array(path), nav_err, breached)


def check_flown_path(flown: FlownPath, waypoints, speed_m_s: float) -> dict:
    """Assert the module's path checks; the figures (for ``record_property``).

    ``waypoints``: (seq, ENU (3,), acceptance radius m) in mission order;
    ``speed_m_s``: the plan's largest DO_CHANGE_SPEED.
    """
    assert flown.nav_err_m < 0.1
    path = flown.path
    segs = list(zip(path[:-1], path[1:]))
    t_closest, worst, start = [], -math.inf, 0
    for seq, w, radius in waypoints:
        # the first pass within reach after the previous way-point's (in order; the return
        # flight home may cross earlier way-points again), at its closest
        d = np.array([point_segment_distance(w[:2], a[:2], b[:2]) for a, b in segs[start:]])
        inside = np.flatnonzero(d <= radius + flown.nav_err_m + 1e-3)
        assert inside.size, f"way-point {seq} missed by {d.min():.3f} m (radius {radius} m)"
        k = int(inside[0])
        while k + 1 < len(d) and d[k + 1] < d[k]:
            k += 1
        worst = max(worst, float(d[k]) - radius)
        start += k
        t_closest.append(start)
    radius = max(r for _, _, r in waypoints)
    bound = radius + speed_m_s ** 2 / (2.0 * 9.81 * math.tan(math.radians(TILT_MAX_DEG)))
    legs = [(a[:2], b[:2]) for (_, a, _), (_, b, _) in zip(waypoints[:-1], waypoints[1:])]
    dev = max(min(point_segment_distance(p[:2], a, b) for a, b in legs) for p in path[t_closest[0]:t_closest[-1] + 1])
    assert dev <= bound, f"lateral deviation {dev:.3f} m > {bound:.3f} m"
    return {"nav_err_m": flown.nav_err_m, "worst_waypoint_miss_minus_radius_m": worst,
            "lateral_deviation_m": dev, "lateral_bound_m": bound}
