#!/usr/bin/env python3
"""``companion plan`` as a user runs it: wall time, CPU time, peak memory, plan.json size.

Usage::

    python benchmarks/bench_plan_cli.py MISSION.yaml [MISSION.yaml ...] [--runs 3] [--out DIR]

Each run is a fresh process (``python -m companion plan MISSION -o DIR/plan.json``)
with ``OMP_NUM_THREADS=1`` (one core), so the figures include the start-up,
the imports, the planning, the sorties and the writing (issue 18: <= 5 s
wall, plan.json <= 10 MB, peak <= 300 MB for 10 ha). The child's CPU time
(user + sys) and peak RSS come from ``os.wait4``, the wall time from the
parent's clock. Also times ``companion --help`` and, on the plan just
written, loading it and preparing the flight (``companion.commands.fly.prepare``:
plan.json, the map and DEM for the preflight checks, the trajectory), the
first part of what ``companion fly --plan`` does before its first message to the
vehicle (the rest: ``benchmarks/bench_fly_start.py``). Prints
medians (and all runs) per mission. On a loaded machine report the CPU
time beside the wall time: it is the part the program controls.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ENV = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1",
           PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
PREPARE = ("import sys; from mavcore.mission import load_mission; from companion.commands.fly import prepare; "
           "from companion.trajectory.cursor import TrajectoryCursor; "
           "fp = prepare(load_mission(sys.argv[1]), sys.argv[2]); "
           "TrajectoryCursor(fp.trajectory).sample(fp.trajectory.t0)")


def run(argv: list[str], env: dict | None = None, cwd=None) -> tuple[float, float, float]:
    """(wall s, user + sys s, peak RSS MB) of one child process (``env``, ``cwd``: default
    ``ENV`` and the repository)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, env=ENV if env is None else env, cwd=ROOT if cwd is None else cwd,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(argv)}: exit {proc.returncode}\n{err}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0


def report(name: str, rows: list[tuple[float, float, float]]) -> None:
    med = [statistics.median(r[i] for r in rows) for i in range(3)]
    print(f"  {name}: wall {med[0]:.2f} s, cpu {med[1]:.2f} s, peak {med[2]:.0f} MB (median of {len(rows)}; "
          f"wall {', '.join(f'{r[0]:.2f}' for r in rows)}; cpu {', '.join(f'{r[1]:.2f}' for r in rows)})")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("missions", nargs="+", help="mission YAML files")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", help="directory for the plans (default: a temporary one)")
    args = ap.parse_args(argv)
    py = sys.executable
    tmp = None if args.out else tempfile.TemporaryDirectory(prefix="bench-plan-cli-")
    out = Path(args.out or tmp.name)
    out.mkdir(parents=True, exist_ok=True)
    report("companion --help", [run([py, "-m", "companion", "--help"]) for _ in range(args.runs)])
    for mission in args.missions:
        plan = out / f"{Path(mission).resolve().parent.name}.plan.json"
        print(f"{mission}:")
        report("companion plan", [run([py, "-m", "companion", "plan", str(mission), "-o", str(plan)])
                                  for _ in range(args.runs)])
        print(f"  plan.json {plan.stat().st_size / 1e6:.2f} MB")
        report("load the plan and prepare the flight", [run([py, "-c", PREPARE, str(mission), str(plan)])
                                                        for _ in range(args.runs)])
    return 0


if __name__ == "__main__":
    sys.exit(main())
