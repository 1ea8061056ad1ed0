"""``companion demo`` end to end: wall time, flight wall time, real-time factor.

Usage::

    python benchmarks/bench_demo.py [--runs 3] [--mission flat-rectangle] [--mission tilted-hexagon]

Runs ``companion demo --no-plots --quiet --out TMP [--mission M]`` ``--runs``
times per mission (a fresh process each time: SITL subprocess, planning,
lockstep flight over MAVLink/UDP) and prints the median demo wall time (from
process start to exit), the flight wall time and real-time factor from
report.json, and the tracking figures. Target (issue 4): flat-rectangle
demo <= 10 s wall.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def one_run(mission: str) -> dict:
    with tempfile.TemporaryDirectory(prefix="bench_demo_") as tmp:
        t0 = time.perf_counter()
        r = subprocess.run([sys.executable, "-m", "companion.cli", "demo", "--no-plots", "--quiet", "--out", tmp,
                            "--mission", mission], capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if r.returncode != 0:
            raise SystemExit(f"demo failed ({r.returncode}): {r.stderr.strip()[-500:]}")
        rep = json.loads((Path(tmp) / "report.json").read_text())
    tr = rep["tracking"]
    return {"wall_s": wall, "flight_s": rep["wall_time_s"], "sim_s": rep["sim_time_s"],
            "rtf": rep["sim_time_s"] / rep["wall_time_s"], "max_mm": tr["max_error_m"] * 1e3,
            "rms_mm": tr["rms_error_m"] * 1e3, "frames": rep.get("n_frames")}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--mission", action="append", default=None, help="bundled name or path (repeatable)")
    args = ap.parse_args()
    for mission in args.mission or ["flat-rectangle"]:
        res = []
        for k in range(args.runs):
            r = one_run(mission)
            res.append(r)
            print(f"{mission} run {k + 1}: demo {r['wall_s']:.2f} s, flight {r['flight_s']:.2f} s for "
                  f"{r['sim_s']:.1f} s vehicle ({r['rtf']:.1f}x), max {r['max_mm']:.2f} mm, "
                  f"rms {r['rms_mm']:.2f} mm", flush=True)
        med = {k: statistics.median(r[k] for r in res) for k in ("wall_s", "flight_s", "rtf", "sim_s")}
        print(f"{mission} median of {args.runs}: demo wall {med['wall_s']:.2f} s, flight wall "
              f"{med['flight_s']:.2f} s, {med['sim_s']:.1f} s vehicle time, {med['rtf']:.1f}x real time")
    return 0


if __name__ == "__main__":
    sys.exit(main())
