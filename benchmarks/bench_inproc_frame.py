"""CPU per lockstep frame of a flight, in process or over UDP, without start-up costs.

Usage::

    python benchmarks/bench_inproc_frame.py [--flights 3] [--cut 20] [--mission flat-rectangle]
        [--transport inproc] [--transport udp] [--profile FILE.pstats]

Plans the mission once, then flies it ``--flights`` times from this process
(as a campaign worker would: imports, planning and, in process, the SITL's
start-up are paid once), with the demo's stream settings and no tlog, over
each ``--transport`` in turn (interleaved): ``inproc`` (``sitl.api.SitlInProcess``:
companion and SITL in this thread) or ``udp`` (``sitl.api.SitlProcess``, as
``companion demo``; the SITL's CPU during the flight is read from /proc).
Prints per flight the CPU time of the flight (this process's
``time.process_time``, plus the SITL process's for udp) per 4 ms frame, the
wall time and the real-time factor, then the medians. ``--profile``:
cProfile the last in-process flight and write its stats (``python -m pstats FILE``).
"""

from __future__ import annotations

import argparse
import cProfile
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from companion.commands.demo import launch_pose
from companion.bundled import resolve_mission  # noqa: E402
from companion.commands.fly import execute
from companion.flight_plan import FlightPlan  # noqa: E402
from mavcore.mission import load_mission  # noqa: E402
from companion.planner import plan_mission  # noqa: E402
from companion.runner import UNUSED_STREAMS  # noqa: E402
from sitl.api import SitlInProcess, SitlProcess  # noqa: E402

ATTITUDE = 30


def _proc_cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` (Linux /proc)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def fly_once(mission_path, mission, plan, cut: float, seed: int, profile: cProfile.Profile | None = None,
             transport: str = "inproc") -> dict:
    pose = launch_pose(plan.trajectory, plan.target_enu_m)
    if transport == "inproc":
        sitl = SitlInProcess(mission_path, seed=seed, start=pose).start()
    else:
        sitl = SitlProcess(mission_path, lockstep=True, speed=1.0, seed=seed, start=pose).start()
    overrides = {"mute_streams": UNUSED_STREAMS + (() if mission.replan.enabled else (ATTITUDE,))}
    try:
        pid = sitl.proc.pid if transport == "udp" else None
        s0 = _proc_cpu_s(pid) if pid else 0.0
        c0, w0 = time.process_time(), time.perf_counter()
        if profile is not None:
            profile.enable()
        res = execute(mission, FlightPlan.from_plan(plan), sitl.url, "companion", None, None, cut, overrides)
        if profile is not None:
            profile.disable()
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        if pid:
            cpu += _proc_cpu_s(pid) - s0
    finally:
        sitl.stop()
    rep = res.report
    return {"cpu_s": cpu, "wall_s": wall, "frames": rep.n_frames, "sim_s": rep.sim_time_s,
            "us_per_frame": cpu / rep.n_frames * 1e6, "rtf": rep.sim_time_s / wall,
            "max_err_m": rep.tracking.max_error_m}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=3)
    ap.add_argument("--cut", type=float, default=20.0)
    ap.add_argument("--mission", default="flat-rectangle")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--transport", action="append", choices=("inproc", "udp"), default=None)
    ap.add_argument("--profile", default=None, metavar="FILE")
    args = ap.parse_args()
    transports = args.transport or ["inproc"]
    path = resolve_mission(args.mission)
    mission = load_mission(path)
    plan = plan_mission(mission)
    res = {t: [] for t in transports}
    for k in range(args.flights):
        for t in transports:
            prof = cProfile.Profile() if args.profile and t == "inproc" and k == args.flights - 1 else None
            load = os.getloadavg()[0]
            r = fly_once(path, mission, plan, args.cut, args.seed, prof, t)
            if prof is not None:
                prof.dump_stats(args.profile)
            else:
                res[t].append(r)
            print(f"flight {k + 1} {t:6s}{' (profiled)' if prof else ''}: load {load:.1f}, {r['frames']} frames, "
                  f"CPU {r['cpu_s']:.2f} s = {r['us_per_frame']:.0f} us/frame, wall {r['wall_s']:.2f} s "
                  f"({r['rtf']:.1f}x real time), max err {r['max_err_m'] * 1e3:.3f} mm", flush=True)
    for t, rs in res.items():
        if rs:
            print(f"median {t:6s} of {len(rs)}: {statistics.median(r['us_per_frame'] for r in rs):.0f} us CPU per "
                  f"frame, wall {statistics.median(r['wall_s'] for r in rs):.2f} s, "
                  f"{statistics.median(r['rtf'] for r in rs):.1f}x real time")
    return 0


if __name__ == "__main__":
    sys.exit(main())
