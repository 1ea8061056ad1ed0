"""``companion demo`` over UDP against the in-process transport: wall and CPU time per flight.

Usage::

    python benchmarks/bench_transport.py [--runs 3] [--cut 60] [--mission flat-rectangle] [--seed 1]

Runs ``companion demo --cut CUT --no-plots --quiet --seed SEED --transport T``
as a fresh process, alternating ``udp`` and ``inproc`` (interleaved, so both
see the same machine load), ``--runs`` times each, and prints per run and
the medians: the process wall time (start to exit: imports, planning, SITL
start-up, flight), the flight's wall time and real-time factor (report.json),
and the CPU time of the whole run (user + system of the demo and its SITL
subprocess, from ``getrusage(RUSAGE_CHILDREN)``; less sensitive to the load
than wall time). The 1-minute load average is printed before each run. The
flights' tracking figures are compared across transports (they should be
identical: lockstep is deterministic and both carry the same bytes).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def one_run(transport: str, cut: float, mission: str, seed: int) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="bench_transport_") as tmp:
        cmd = [sys.executable, "-m", "companion", "demo", "--cut", repr(cut), "--no-plots", "--quiet",
               "--seed", str(seed), "--mission", mission, "--transport", transport, "--out", tmp]
        ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        r = subprocess.run(cmd, capture_output=True, text=True, env=env)
        wall = time.perf_counter() - t0
        ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        if r.returncode != 0:
            raise SystemExit(f"demo --transport {transport} failed ({r.returncode}): {r.stderr.strip()[-500:]}")
        rep = json.loads((Path(tmp) / "report.json").read_text())
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    tr = rep["tracking"]
    return {"transport": transport, "load1": load, "wall_s": wall, "cpu_s": cpu, "flight_s": rep["wall_time_s"],
            "sim_s": rep["sim_time_s"], "rtf": rep["sim_time_s"] / rep["wall_time_s"],
            "max_err_m": tr["max_error_m"], "rms_err_m": tr["rms_error_m"], "completed": rep["completed"],
            "frames": rep.get("n_frames")}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--cut", type=float, default=60.0)
    ap.add_argument("--mission", default="flat-rectangle")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores; demo --cut {args.cut:g} --mission {args.mission} --seed {args.seed}",
          flush=True)
    res = {"udp": [], "inproc": []}
    for k in range(args.runs):
        for transport in ("udp", "inproc"):
            r = one_run(transport, args.cut, args.mission, args.seed)
            res[transport].append(r)
            print(f"run {k + 1} {transport:6s}: load {r['load1']:.1f}, process wall {r['wall_s']:.1f} s, "
                  f"CPU {r['cpu_s']:.1f} s, flight {r['flight_s']:.1f} s wall for {r['sim_s']:.1f} s vehicle "
                  f"({r['rtf']:.1f}x real time), max err {r['max_err_m'] * 1e3:.3f} mm, "
                  f"rms {r['rms_err_m'] * 1e3:.4f} mm", flush=True)
    med = {t: {k: statistics.median(r[k] for r in rs) for k in ("load1", "wall_s", "cpu_s", "flight_s", "rtf")}
           for t, rs in res.items()}
    for t in ("udp", "inproc"):
        m = med[t]
        print(f"median {t:6s}: process wall {m['wall_s']:.1f} s, CPU {m['cpu_s']:.1f} s, flight wall "
              f"{m['flight_s']:.1f} s ({m['rtf']:.1f}x real time), load {m['load1']:.1f}")
    u, i = med["udp"], med["inproc"]
    print(f"inproc speed-up: process wall {u['wall_s'] / i['wall_s']:.2f}x, flight wall "
          f"{u['flight_s'] / i['flight_s']:.2f}x, CPU {u['cpu_s'] / i['cpu_s']:.2f}x")
    same = all((a["max_err_m"], a["rms_err_m"], a["frames"]) == (b["max_err_m"], b["rms_err_m"], b["frames"])
               for a, b in zip(res["udp"], res["inproc"]))
    print(f"same tracking figures and frames over both transports: {'yes' if same else 'NO'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
