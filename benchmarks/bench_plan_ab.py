#!/usr/bin/env python3
"""``companion plan`` in fresh processes, two source trees interleaved: CPU, wall, peak memory.

Usage::

    python benchmarks/bench_plan_ab.py --tree base=/tmp/base --tree new=. \\
        MISSION.yaml [MISSION.yaml ...] [--runs 3] [--out DIR] [--cache both|none|warm]

Each round runs every mission with every tree, in that order, as a fresh
``python -m companion plan MISSION -o DIR/NAME-FIELD.json`` (``OMP_NUM_THREADS=1``:
one core; the child's CPU time (user + sys) and peak RSS from ``os.wait4``, the
wall time from the parent's clock: start-up, imports, planning, writing and the
interpreter's exit). Without a bytecode cache (``PYTHONDONTWRITEBYTECODE=1``, every
module compiled) and/or with a warm one (``PYTHONPYCACHEPREFIX=DIR/pyc-NAME``, warmed
by one run first, what an installed package has). Prints the load averages before
and after each mode, the medians (and every run), and whether each tree's plan.json
equals the first tree's (``compare_plans.differences``: every key but ``timings_s``,
floats exactly). The machine's load shows in the wall times: report both.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_plan_cli import run  # noqa: E402
from bench_prepare_ab import _env  # noqa: E402
from compare_plans import differences  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("missions", nargs="+")
    ap.add_argument("--tree", action="append", required=True, metavar="NAME=DIR")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", default="/tmp/bench-plan-ab")
    ap.add_argument("--cache", choices=("both", "none", "warm"), default="both")
    args = ap.parse_args(argv)
    py = sys.executable
    trees = [(s.split("=", 1)[0], os.path.abspath(s.split("=", 1)[1])) for s in args.tree]
    missions = [os.path.abspath(m) for m in args.missions]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    modes = {"both": (False, True), "none": (False,), "warm": (True,)}[args.cache]
    for warm in modes:
        caches = {name: (str(out / f"pyc-{name}") if warm else None) for name, _ in trees}
        plan = {(name, m): str(out / f"{name}-{Path(m).parent.name}.json") for name, _ in trees for m in missions}
        if warm:
            for name, tree in trees:
                run([py, "-m", "companion", "plan", missions[0], "-o", plan[(name, missions[0])]],
                    _env(tree, caches[name]), tree)
        label = "warm bytecode cache" if warm else "no bytecode cache"
        print(f"{label}: load average before {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
        res: dict = {}
        for _ in range(args.runs):
            for m in missions:
                for name, tree in trees:
                    res.setdefault((m, name), []).append(
                        run([py, "-m", "companion", "plan", m, "-o", plan[(name, m)]], _env(tree, caches[name]), tree))
        print(f"{label}: load average after {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
        for m in missions:
            first = None
            for name, _ in trees:
                rows = res[(m, name)]
                doc = json.loads(Path(plan[(name, m)]).read_text())
                if first is None:
                    first, same = doc, "reference"
                else:
                    diff = differences(first, doc)
                    same = "plan equal" if not diff else f"plan DIFFERS: {diff[:3]}"
                print(f"{label}, {Path(m).parent.name}, {name}: CPU median {statistics.median(r[1] for r in rows):.3f} s "
                      f"({', '.join(f'{r[1]:.2f}' for r in rows)}), wall median "
                      f"{statistics.median(r[0] for r in rows):.2f} s ({', '.join(f'{r[0]:.2f}' for r in rows)}), "
                      f"peak {statistics.median(r[2] for r in rows):.0f} MB; {same}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
