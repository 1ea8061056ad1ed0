#!/usr/bin/env python3
"""``companion fly --plan`` up to its first message to the vehicle, two source trees interleaved.

Usage::

    python benchmarks/bench_fly_start.py --tree base=/tmp/base --tree new=. \\
        MISSION.yaml [MISSION.yaml ...] [--sortie N] [--runs 5] [--plans DIR]

What the user waits for between typing ``companion fly MISSION --plan P`` and
the companion starting to fly: the command line, loading the mission and the
plan, the preflight of the plan and of what is flown
(``check_plan``/``check_flight_plan``), a sortie's trajectory re-solved
(``--sortie``), the sensor-coverage gate, the flight core built
(``build_flight_core``: the replanner's known map, the guard), the link
opened. ``PREPARE`` (``bench_plan_cli.py``, ``bench_prepare_ab.py``) is only
the first part of this.

Each run is a fresh ``python -c START MISSION --plan P ...`` with
``OMP_NUM_THREADS=1`` and a warm bytecode cache (``PYTHONPYCACHEPREFIX``, as
an installed package): ``START`` runs ``companion fly`` with
``MissionRunner.run`` (the flight itself: heartbeat, arming, the setpoints)
replaced by an immediate ``os._exit(0)`` when ``companion fly`` imports it (``--connect udpout:127.0.0.1:PORT``: nothing
listens, nothing is awaited). CPU time (user + sys) and peak RSS from
``os.wait4``, wall time from the parent's clock. Each tree flies the plan it
wrote (``companion plan`` into ``--plans``, kept between runs). Prints the
load averages and, per mission and tree, the medians and every run.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_plan_cli import run  # noqa: E402
from bench_prepare_ab import _env  # noqa: E402

START = """
import importlib.machinery, os, sys
class Stop(importlib.machinery.PathFinder):
    # companion.runner, once loaded where companion fly loads it: MissionRunner.run exits at once
    @classmethod
    def find_spec(cls, name, path=None, target=None):
        if name != "companion.runner":
            return None
        spec = importlib.machinery.PathFinder.find_spec(name, path, target)
        run_module = spec.loader.exec_module
        def exec_module(module):
            run_module(module)
            module.MissionRunner.run = lambda self: os._exit(0)
        spec.loader.exec_module = exec_module
        return spec
sys.meta_path.insert(0, Stop)
from companion.cli import main
sys.argv = ["companion", "fly"] + sys.argv[1:]
sys.exit(main())
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("missions", nargs="+")
    ap.add_argument("--tree", action="append", required=True, metavar="NAME=DIR")
    ap.add_argument("--sortie", type=int, default=None, help="fly this sortie (default: the whole plan)")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--plans", default="/tmp/bench-fly-start")
    args = ap.parse_args(argv)
    py = sys.executable
    trees = [(s.split("=", 1)[0], os.path.abspath(s.split("=", 1)[1])) for s in args.tree]
    missions = [os.path.abspath(m) for m in args.missions]
    out = Path(args.plans)
    out.mkdir(parents=True, exist_ok=True)
    plans = {}
    for m in missions:
        for name, tree in trees:
            plan = out / f"{name}-{Path(m).parent.name}.json"
            if not plan.exists():
                run([py, "-m", "companion", "plan", m, "-o", str(plan)], _env(tree, None), tree)
            plans[(name, m)] = str(plan)
    caches = {name: str(out / f"pyc-{name}") for name, _ in trees}

    def fly(name, tree, m):
        argv = [py, "-c", START, m, "--plan", plans[(name, m)], "--connect", "udpout:127.0.0.1:14999",
                "--tlog", str(out / f"{name}.tlog"), "--report", str(out / f"{name}-report.json"), "-q"]
        if args.sortie is not None:
            argv += ["--sortie", str(args.sortie)]
        return run(argv, _env(tree, caches[name]), tree)

    for name, tree in trees:          # warm each tree's bytecode cache
        fly(name, tree, missions[0])
    print(f"load average before {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    res: dict = {}
    for _ in range(args.runs):
        for m in missions:
            for name, tree in trees:
                res.setdefault((m, name), []).append(fly(name, tree, m))
    print(f"load average after {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    what = "whole plan" if args.sortie is None else f"sortie {args.sortie}"
    for m in missions:
        for name, _ in trees:
            rows = res[(m, name)]
            print(f"{Path(m).parent.name}, {what}, {name}: CPU median {statistics.median(r[1] for r in rows):.3f} s "
                  f"({', '.join(f'{r[1]:.2f}' for r in rows)}), wall median {statistics.median(r[0] for r in rows):.3f} s "
                  f"({', '.join(f'{r[0]:.2f}' for r in rows)}), peak {statistics.median(r[2] for r in rows):.0f} MB",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
