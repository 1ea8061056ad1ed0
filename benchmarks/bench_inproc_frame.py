"""CPU per lockstep frame of an in-process flight (companion + SITL in one thread).

Usage::

    python benchmarks/bench_inproc_frame.py [--flights 3] [--cut 20] [--mission flat-rectangle]
        [--profile FILE.pstats]

Plans the mission once, then flies it ``--flights`` times in this process
over the in-process transport (``sitl.api.SitlInProcess``, as ``companion
demo --transport inproc`` and a campaign worker do, with the demo's stream
settings; no tlog), and prints per flight the CPU time (``time.process_time``)
per 4 ms frame, the wall time and the real-time factor, then the medians.
Both loops share one thread, so CPU per frame is the whole flight path's
cost: companion (flight core, controller, link) plus SITL (simulation,
sensors, estimator, telemetry). ``--profile``: cProfile the last flight and
write its stats (``python -m pstats FILE``).
"""

from __future__ import annotations

import argparse
import cProfile
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from companion.commands.demo import launch_pose, resolve_mission  # noqa: E402
from companion.commands.fly import FlightPlan, execute  # noqa: E402
from companion.mission import load_mission  # noqa: E402
from companion.planner import plan_mission  # noqa: E402
from companion.runner import UNUSED_STREAMS  # noqa: E402
from sitl.api import SitlInProcess  # noqa: E402

ATTITUDE = 30


def fly_once(mission_path, mission, plan, cut: float, seed: int, profile: cProfile.Profile | None = None) -> dict:
    sitl = SitlInProcess(mission_path, seed=seed, start=launch_pose(plan.trajectory, plan.target_enu_m)).start()
    overrides = {"mute_streams": UNUSED_STREAMS + (() if mission.replan.enabled else (ATTITUDE,))}
    try:
        c0, w0 = time.process_time(), time.perf_counter()
        if profile is not None:
            profile.enable()
        res = execute(mission, FlightPlan.from_plan(plan), sitl.url, "companion", None, None, cut, overrides)
        if profile is not None:
            profile.disable()
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
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
    ap.add_argument("--profile", default=None, metavar="FILE")
    args = ap.parse_args()
    path = resolve_mission(args.mission)
    mission = load_mission(path)
    plan = plan_mission(mission)
    res = []
    for k in range(args.flights):
        prof = cProfile.Profile() if args.profile and k == args.flights - 1 else None
        r = fly_once(path, mission, plan, args.cut, args.seed, prof)
        if prof is not None:
            prof.dump_stats(args.profile)
        res.append(r)
        print(f"flight {k + 1}{' (profiled)' if prof else ''}: {r['frames']} frames, CPU {r['cpu_s']:.2f} s = "
              f"{r['us_per_frame']:.0f} us/frame, wall {r['wall_s']:.2f} s ({r['rtf']:.1f}x real time), "
              f"max err {r['max_err_m'] * 1e3:.3f} mm", flush=True)
    plain = [r for r in res[:len(res) - (1 if args.profile else 0)]] or res
    print(f"median of {len(plain)}: {statistics.median(r['us_per_frame'] for r in plain):.0f} us CPU per frame, "
          f"{statistics.median(r['rtf'] for r in plain):.1f}x real time")
    return 0


if __name__ == "__main__":
    sys.exit(main())
