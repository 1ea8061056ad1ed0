#!/usr/bin/env python3
"""``companion fly --plan P --sortie N --cut S`` against the bundled SITL, two source trees interleaved.

Usage::

    python benchmarks/bench_fly_sortie.py MISSION.yaml --start X,Y \\
        --tree base=/tmp/base PLAN_BASE.json --tree new=. PLAN_NEW.json [--runs 3] [--sortie 1] [--cut 40]

Each run: the SITL (``sitl MISSION --lockstep --start X,Y --listen udpin:...``,
the sortie's launch point) waits for its world to be built (its ready line),
then the companion flies over UDP in a fresh process. Reports the companion's
peak RSS and CPU time (user + sys, ``os.wait4``), the SITL's peak RSS, and the
flight report's tracking figures (which must not change between the trees).
Every process gets ``OMP_NUM_THREADS=1``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time


def fly_once(py: str, tree: str, mission: str, plan: str, start: str, port: int, sortie: int, cut: float,
             report: str) -> dict:
    env = dict(os.environ, PYTHONPATH=tree, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    sitl = subprocess.Popen([py, "-m", "sitl", mission, "--lockstep", "--start", start,
                             "--listen", f"udpin:127.0.0.1:{port}"], env=env, cwd=tree,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    for line in sitl.stdout:                  # the SITL prints its ready line once its world is built
        if line.startswith("sitl: ready"):
            break
    threading.Thread(target=sitl.stdout.read, daemon=True).start()
    t0 = time.perf_counter()
    fly = subprocess.Popen([py, "-m", "companion", "fly", mission, "--plan", plan, "--sortie", str(sortie),
                            "--cut", str(cut), "--connect", f"udpout:127.0.0.1:{port}", "--report", report,
                            "--quiet"], env=env, cwd=tree, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    _, status, usage = os.wait4(fly.pid, 0)
    wall = time.perf_counter() - t0
    out = fly.stdout.read().decode(errors="replace")
    fly.stdout.close()
    sitl.terminate()
    _, _, sitl_usage = os.wait4(sitl.pid, 0)
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        raise SystemExit(f"companion fly ({tree}): exit {code}\n{out[-2000:]}")
    rep = json.load(open(report))
    return {"peak_mb": usage.ru_maxrss / 1024, "cpu_s": usage.ru_utime + usage.ru_stime, "wall_s": wall,
            "sitl_peak_mb": sitl_usage.ru_maxrss / 1024, "tracking_max_m": rep["tracking"]["max_error_m"],
            "tracking_rms_m": rep["tracking"]["rms_error_m"], "flown_s": rep["sim_time_s"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mission")
    ap.add_argument("--start", required=True, help="X,Y: the sortie's launch point (ENU m)")
    ap.add_argument("--tree", nargs=2, action="append", required=True, metavar=("NAME=DIR", "PLAN"),
                    help="a source tree and the plan it flies (repeatable; run in turn)")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--sortie", type=int, default=1)
    ap.add_argument("--cut", type=float, default=40.0)
    ap.add_argument("--port", type=int, default=15600)
    args = ap.parse_args(argv)
    trees = [(spec.split("=", 1)[0], os.path.abspath(spec.split("=", 1)[1]), os.path.abspath(plan))
             for spec, plan in args.tree]
    mission = os.path.abspath(args.mission)
    rows: dict[str, list[dict]] = {name: [] for name, _, _ in trees}
    port = args.port
    with tempfile.TemporaryDirectory(prefix="bench-fly-") as tmp:
        for i in range(args.runs):
            for name, tree, plan in trees:
                port += 1
                r = fly_once(sys.executable, tree, mission, plan, args.start, port, args.sortie, args.cut,
                             os.path.join(tmp, f"{name}-{i}.json"))
                rows[name].append(r)
                print(f"{name} run {i}: companion peak {r['peak_mb']:.1f} MB, cpu {r['cpu_s']:.2f} s, "
                      f"wall {r['wall_s']:.1f} s; SITL peak {r['sitl_peak_mb']:.1f} MB; tracking max "
                      f"{r['tracking_max_m']!r} m, rms {r['tracking_rms_m']!r} m; {r['flown_s']:.2f} s flown",
                      flush=True)
    for name, rs in rows.items():
        med = {k: statistics.median(r[k] for r in rs) for k in ("peak_mb", "cpu_s", "sitl_peak_mb")}
        print(f"{name}: median companion peak {med['peak_mb']:.1f} MB, cpu {med['cpu_s']:.2f} s, "
              f"SITL peak {med['sitl_peak_mb']:.1f} MB (of {len(rs)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
