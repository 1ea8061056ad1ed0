#!/usr/bin/env python3
"""The garbage collector's passes during ``companion plan``, and the interpreter's exit.

Usage::

    python benchmarks/bench_plan_gc.py MISSION.yaml [--runs 3]

Runs ``companion plan MISSION -o TMP`` in fresh processes (``OMP_NUM_THREADS=1``),
once as the process's own command line (``main()`` reading ``sys.argv``: the
imports kept out of the collector, :mod:`companion.long_lived`) and once as a
call ``main(argv)`` (nothing frozen: what every process did before), alternating.
Reports, per mode, the collector's passes by generation and their total time
(``gc.callbacks``, from the first import of the companion to the end of
``main``), and the time from the end of ``main`` to the parent seeing the child
exit (the interpreter's finalisation), with the child's CPU time (user + sys,
``os.wait4``). Medians over the runs; on a loaded machine the wall figures
stretch with the load, the CPU figures less.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CHILD = """
import gc, json, sys, time, contextlib, io
stats = {}
t0 = [0.0]
def cb(phase, info):
    if phase == "start":
        t0[0] = time.perf_counter()
    else:
        n, t = stats.get(info["generation"], (0, 0.0))
        stats[info["generation"]] = (n + 1, t + time.perf_counter() - t0[0])
gc.callbacks.append(cb)
from companion.cli import main
mission, out, as_process = sys.argv[1], sys.argv[2], sys.argv[3] == "1"
sys.argv = ["companion", "plan", mission, "-o", out]
with contextlib.redirect_stdout(io.StringIO()):
    rc = main() if as_process else main(sys.argv[1:])
gc.callbacks.remove(cb)
print(json.dumps({"rc": rc, "gc": stats, "end": time.time()}), flush=True)
"""


def one(mission: str, out: str, as_process: bool) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1",
               PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-c", CHILD, mission, out, "1" if as_process else "0"],
                            env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    text = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    t_exit = time.time()
    proc.stdout.close()
    res = json.loads(text.strip().splitlines()[-1])
    if os.waitstatus_to_exitcode(status) != 0 or res["rc"] != 0:
        raise SystemExit(f"{mission}: companion plan failed")
    return {"gc": {int(g): v for g, v in res["gc"].items()}, "exit_s": t_exit - res["end"],
            "cpu_s": usage.ru_utime + usage.ru_stime}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mission")
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args(argv)
    res: dict = {True: [], False: []}
    with tempfile.TemporaryDirectory(prefix="bench-plan-gc-") as tmp:
        for _ in range(args.runs):
            for as_process in (False, True):
                res[as_process].append(one(os.path.abspath(args.mission), str(Path(tmp) / "plan.json"), as_process))
    for as_process, label in ((False, "main(argv), nothing frozen"), (True, "main() as the command line, imports frozen")):
        rows = res[as_process]
        exits = ", ".join(f"{r['exit_s']:.3f}" for r in rows)
        cpus = ", ".join(f"{r['cpu_s']:.2f}" for r in rows)
        gens = sorted({g for r in rows for g in r["gc"]})
        passes = ", ".join(
            f"gen {g}: {statistics.median(r['gc'].get(g, (0, 0.0))[0] for r in rows):.0f} passes "
            f"{statistics.median(r['gc'].get(g, (0, 0.0))[1] for r in rows):.3f} s" for g in gens)
        print(f"{label}: {passes}; exit {statistics.median(r['exit_s'] for r in rows):.3f} s "
              f"({exits}); process CPU "
              f"{statistics.median(r['cpu_s'] for r in rows):.2f} s ({cpus})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
