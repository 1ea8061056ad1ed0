#!/usr/bin/env python3
"""Benchmark the whole ``plan`` pipeline on a ~10 ha field at 0.1 m per cell.

Usage::

    python benchmarks/bench_plan.py [--mission MISSION.yaml] [--runs 3] [--hectares 10]

Without ``--mission`` it uses ``missions/large-10ha/mission.yaml`` if present
and otherwise generates the field (``missions/generate.py large``) into a
temporary directory. Prints the median (and min/max) of each phase of
``plan_mission`` (load, coverage incl. way-points, trajectory incl. stats,
total) over the runs, and the plan's size. Target (issue 2): total <= 5 s on
one core.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "missions"))

import generate  # noqa: E402  (missions/generate.py)

from mavcore.mission import load_mission  # noqa: E402
from companion.planner import plan_mission  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mission", help="mission YAML (default: the generated large field)")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--hectares", type=float, default=10.0)
    ap.add_argument("--resolution", type=float, default=0.1)
    args = ap.parse_args(argv)

    tmp = None
    if args.mission:
        mission_path = Path(args.mission)
    else:
        spec = generate.large_field(args.hectares, args.resolution)
        cached = ROOT / "missions" / spec.name / "mission.yaml"
        if cached.exists() and args.resolution == 0.1:
            mission_path = cached
        else:
            tmp = tempfile.TemporaryDirectory(prefix="bench-plan-")
            t = time.perf_counter()
            generate.write_mission(spec, tmp.name)
            print(f"generated {spec.name} in {tmp.name} ({time.perf_counter() - t:.2f} s)")
            mission_path = Path(tmp.name) / "mission.yaml"

    try:
        mission = load_mission(mission_path)
        rows = []
        plan = None
        for _ in range(args.runs):
            plan = plan_mission(mission)
            rows.append(plan.timings_s)
        g = plan.grid
        st = plan.stats
        print(f"mission {mission.name}: map {g.shape[1]} x {g.shape[0]} cells at {g.resolution_m} m "
              f"({g.shape[0] * g.shape[1] / 1e6:.1f} Mcells), {st.n_waypoints} way-points, "
              f"path {st.path_length_m:.0f} m, duration {st.duration_s:.0f} s, "
              f"coverage {100 * st.coverage_fraction:.2f} %, residual {100 * st.waypoint_residual_m:.2f} cm")
        print(f"python {sys.version.split()[0]}, {os.cpu_count()} cpu(s), {args.runs} run(s)")
        print(f"{'phase':<12}{'median s':>10}{'min s':>10}{'max s':>10}")
        for phase in ("load", "coverage", "trajectory", "total"):
            vals = [getattr(r, phase) for r in rows]
            print(f"{phase:<12}{statistics.median(vals):>10.3f}{min(vals):>10.3f}{max(vals):>10.3f}")
    finally:
        if tmp is not None:
            tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
