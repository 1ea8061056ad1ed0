#!/usr/bin/env python3
"""Loading a plan and preparing the flight (``bench_plan_cli.PREPARE``), two source trees interleaved.

Usage::

    python benchmarks/bench_prepare_ab.py --tree base=/tmp/base --tree new=. \\
        MISSION.yaml [MISSION.yaml ...] [--runs 5] [--plans DIR]

Each tree plans each mission once (``companion plan``, into ``--plans``; kept
between runs), then the PREPARE snippet runs in fresh processes, the trees and
missions interleaved, first without a bytecode cache (``PYTHONDONTWRITEBYTECODE=1``:
every module compiled from source) and then with a warm one
(``PYTHONPYCACHEPREFIX=DIR/pyc-NAME``, warmed by one run first). CPU time (user +
sys) and peak RSS from ``os.wait4``, wall from the parent's clock; medians.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_plan_cli import PREPARE, run  # noqa: E402


def _env(tree: str, cache_dir: str | None) -> dict:
    env = dict(os.environ, PYTHONPATH=tree, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    if cache_dir:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = cache_dir
    else:
        env["PYTHONDONTWRITEBYTECODE"] = "1"
        env.pop("PYTHONPYCACHEPREFIX", None)
    return env


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("missions", nargs="+")
    ap.add_argument("--tree", action="append", required=True, metavar="NAME=DIR")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--plans", default="/tmp/bench-prepare-ab")
    args = ap.parse_args(argv)
    py = sys.executable
    trees = [(s.split("=", 1)[0], os.path.abspath(s.split("=", 1)[1])) for s in args.tree]
    missions = [os.path.abspath(m) for m in args.missions]
    out = Path(args.plans)
    out.mkdir(parents=True, exist_ok=True)
    plans = {}
    for m in missions:
        field = Path(m).parent.name
        for name, tree in trees:
            plan = out / f"{name}-{field}.json"
            if not plan.exists():
                run([py, "-m", "companion", "plan", m, "-o", str(plan)], _env(tree, None), tree)
            twin = Path(str(plan) + ".npz")
            print(f"{name} {field}: plan.json {plan.stat().st_size / 1e6:.2f} MB"
                  + (f", twin {twin.stat().st_size / 1e6:.2f} MB" if twin.exists() else ", no twin"))
            plans[(name, m)] = str(plan)
    for warm in (False, True):
        caches = {name: (str(out / f"pyc-{name}") if warm else None) for name, _ in trees}
        if warm:
            for name, tree in trees:
                run([py, "-c", PREPARE, missions[0], plans[(name, missions[0])]], _env(tree, caches[name]), tree)
        res: dict = {}
        for _ in range(args.runs):
            for m in missions:
                for name, tree in trees:
                    res.setdefault((m, name), []).append(
                        run([py, "-c", PREPARE, m, plans[(name, m)]], _env(tree, caches[name]), tree))
        label = "warm bytecode cache" if warm else "no bytecode cache"
        for m in missions:
            for name, _ in trees:
                rows = res[(m, name)]
                print(f"{label}, {Path(m).parent.name}, {name}: CPU median {statistics.median(r[1] for r in rows):.3f} s "
                      f"({', '.join(f'{r[1]:.2f}' for r in rows)}), wall median "
                      f"{statistics.median(r[0] for r in rows):.2f} s, peak {statistics.median(r[2] for r in rows):.0f} MB",
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
