#!/usr/bin/env python3
"""``companion campaign`` wall time on 1 and on N workers: the scaling efficiency.

Usage::

    python benchmarks/bench_campaign_scaling.py campaigns/noise.yaml --flights 12 --cut 30 \\
        --workers 1 2 --rounds 2 [--out /tmp/bench-scaling]

Each round runs the same campaign (the spec, ``--flights``, ``--cut``) once for
each worker count, into a fresh output directory, interleaved (1, 2, 1, 2, ...),
and times the whole command from the parent (``time.perf_counter``): the
LocalCluster's start, the flights, the summary and the figures, as a user
waits for them. The efficiency of N workers against one is
``T_1 / (N * T_N)`` with the medians over the rounds. Every run's results
table must equal the first run's, row by row, in every column but the wall
times (the scenarios and the flights do not depend on how many workers fly
them); the script says so, or fails.
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

#: Columns that depend on the machine's timing, not on the flight.
TIMING_COLUMNS = {"wall_s"}


def _table(out: Path) -> list[dict]:
    with open(out / "results.csv", newline="") as f:
        rows = [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in csv.DictReader(f)]
    return sorted(rows, key=lambda r: int(r["scenario"]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("spec")
    ap.add_argument("--flights", type=int, default=12)
    ap.add_argument("--cut", type=float, default=30.0)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", default="/tmp/bench-campaign-scaling")
    args = ap.parse_args(argv)
    base = Path(args.out)
    walls: dict[int, list[float]] = {w: [] for w in args.workers}
    first = None
    print(f"cores {os.cpu_count()}, load average before {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for r in range(args.rounds):
        for w in args.workers:
            out = base / f"r{r}-w{w}"
            shutil.rmtree(out, ignore_errors=True)
            base.mkdir(parents=True, exist_ok=True)
            cmd = [sys.executable, "-m", "companion", "campaign", args.spec, "--out", str(out), "--flights",
                   str(args.flights), "--cut", str(args.cut), "--workers", str(w), "-q"]
            t = time.perf_counter()
            subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            walls[w].append(time.perf_counter() - t)
            table = _table(out)
            if first is None:
                first = table
            elif table != first:
                print(f"round {r}, {w} workers: the results table differs from the first run's")
                return 1
            print(f"round {r}, {w} worker(s): {walls[w][-1]:.1f} s wall, {len(table)} flights")
    print(f"load average after {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    t1 = statistics.median(walls[args.workers[0]])
    for w in args.workers:
        tw = statistics.median(walls[w])
        eff = t1 * args.workers[0] / (w * tw)
        print(f"{w} worker(s): median {tw:.1f} s ({', '.join(f'{x:.1f}' for x in walls[w])}), "
              f"speed-up {t1 / tw:.2f}, efficiency {eff:.0%}")
    print("every run's results table equal to the first's (all columns but wall_s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
