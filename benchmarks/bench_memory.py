"""Companion memory over a long flight: RSS before planning, at arming, and its growth per hour.

Usage::

    python benchmarks/bench_memory.py [--field large] [--cut 3600] [--control companion]
    python benchmarks/bench_memory.py --mission flat-rectangle

Plans the mission in this process (``--field large`` first generates the
10 ha field with ``missions/generate.py large`` into a temporary directory),
starts the bundled SITL (subprocess, lockstep) and flies the first ``--cut``
seconds of the trajectory with ``companion.runner`` exactly as ``companion
fly`` does, while a thread samples this process's resident set size
(``/proc/self/status`` VmRSS) four times a wall second together with the
flight phase and the vehicle time. Prints RSS before planning, after
planning, at arming (first sample in ``takeoff``), at the end of the
trajectory phase, and the least-squares slope of RSS against vehicle time
over the trajectory phase (MB per hour of flight). Targets (issue 11): RSS at
arming <= 200 MB; growth < 20 MB per hour of flight.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _t_s(core) -> float:
    """The flight core's vehicle time (s; NaN before the first frame or the core)."""
    t = None if core is None else (core.view if hasattr(core, "view") else core).t_s
    return float("nan") if t is None else t


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError("no VmRSS")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--field", choices=("large",), default=None, help="generate and fly the 10 ha field")
    ap.add_argument("--mission", default="flat-rectangle", help="bundled mission name or path (without --field)")
    ap.add_argument("--cut", type=float, default=3600.0, help="seconds of trajectory to fly (default 1 h)")
    ap.add_argument("--control", choices=("companion", "vehicle"), default="companion")
    a = ap.parse_args()

    rss0 = rss_mb()
    from companion.bundled import resolve_mission
    from companion.commands.fly import execute
    from companion.flight_plan import FlightPlan
    from mavcore.mission import load_mission
    from companion.planner import plan_mission
    from companion.runner import UNUSED_STREAMS
    from sitl.api import SitlProcess

    with tempfile.TemporaryDirectory(prefix="bench_memory_") as tmp:
        if a.field == "large":
            subprocess.run([sys.executable, str(ROOT / "missions" / "generate.py"), "large", "--out",
                            f"{tmp}/large"], check=True, capture_output=True)
            path = Path(tmp) / "large" / "mission.yaml"
        else:
            path = resolve_mission(a.mission)
        mission = load_mission(path)
        rss_import = rss_mb()
        t0 = time.perf_counter()
        plan = plan_mission(mission)
        t_plan = time.perf_counter() - t0
        fp = FlightPlan.from_plan(plan)
        del plan
        rss_planned = rss_mb()

        samples = []
        holder = {}
        stop = threading.Event()

        def sample():
            while not stop.is_set():
                core = holder.get("core")
                samples.append((time.monotonic(), rss_mb(), core.phase if core else "init",
                                _t_s(core)))
                time.sleep(0.25)

        # Let the sampler see the core: wrap the runner class the command builds.
        import companion.runner as runner_mod

        orig = runner_mod.MissionRunner.__init__

        def init(self, conn, core, progress=None):
            holder["core"] = core
            orig(self, conn, core, progress)

        runner_mod.MissionRunner.__init__ = init
        th = threading.Thread(target=sample, daemon=True)
        th.start()
        with SitlProcess(path, lockstep=True) as sitl:
            res = execute(mission, fp, sitl.url, a.control, f"{tmp}/flight.tlog", None, a.cut,
                          {"mute_streams": UNUSED_STREAMS})
        stop.set()
        th.join()
        tlog_mb = Path(f"{tmp}/flight.tlog").stat().st_size / 1e6
    rep = res.report
    arr = [(w, r, p, t) for w, r, p, t in samples]
    at_arm = next((r for _, r, p, _ in arr if p in ("takeoff", "hold", "trajectory")), float("nan"))
    traj = np.array([(t, r) for _, r, p, t in arr if p == "trajectory" and np.isfinite(t)])
    slope = float("nan")
    if len(traj) > 10:
        slope = np.polyfit(traj[:, 0], traj[:, 1], 1)[0] * 3600.0
    end = traj[-1, 1] if len(traj) else float("nan")
    print(f"mission {mission.name}: {rep.trajectory_duration_s:.0f} s trajectory flown "
          f"({rep.sim_time_s:.0f} s of vehicle time in {rep.wall_time_s:.0f} s wall), completed {rep.completed}, "
          f"tlog {tlog_mb:.0f} MB on disk; planning {t_plan:.2f} s")
    print("| moment | RSS (MB) |")
    print("|---|---|")
    print(f"| start of the script | {rss0:.0f} |")
    print(f"| imports and mission loaded | {rss_import:.0f} |")
    print(f"| plan built | {rss_planned:.0f} |")
    print(f"| at arming | {at_arm:.0f} |")
    print(f"| end of the trajectory phase | {end:.0f} |")
    print(f"| growth over the trajectory phase (least squares) | {slope:+.1f} MB/h |")
    return 0 if rep.completed else 3


if __name__ == "__main__":
    raise SystemExit(main())
