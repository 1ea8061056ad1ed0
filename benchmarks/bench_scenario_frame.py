"""CPU per lockstep frame of campaign scenarios flown in process, one tree against another.

Usage::

    python benchmarks/bench_scenario_frame.py SCENARIO.yaml [SCENARIO.yaml ...] [--runs 3]
        [--tree DIR] [--tree DIR] [--json FILE]

Flies each scenario file (``companion demo --scenario FILE --transport inproc
--no-plots -q``, as a campaign worker does, in a fresh process per flight)
``--runs`` times with the code of each ``--tree`` (default: this checkout),
interleaved: run 1 of every scenario on every tree, then run 2, ...
(``--parallel``: the trees' flights of a scenario at the same time, so that
on a shared machine they see the same load) Each
flight reports the CPU time (``time.process_time`` of the child, not wall
time) of the whole demo (planning, SITL start-up, flight, report, map) and of
the flight alone (``companion.commands.fly.execute``), the frames flown, the
peak RSS (``getrusage``), and the flight's outcome and figures, which must be
the same on every tree (the check that a speed-up did not change the flight).
Prints per flight and the medians per scenario and tree.
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

#: report.json figures that must agree between trees (the flight's outcome).
OUTCOME_KEYS = ("completed", "n_frames", "sim_time_s", "min_clearance_m", "max_error_m", "events")


def _child(scenario: str) -> int:
    """Fly ``scenario`` once in this process; print one JSON line."""
    import companion.commands.fly as fly
    from companion.cli import build_parser

    flight = {}
    execute = fly.execute

    def timed(*a, **k):
        c0 = time.process_time()
        try:
            return execute(*a, **k)
        finally:
            flight["cpu_s"] = time.process_time() - c0

    fly.execute = timed
    with tempfile.TemporaryDirectory(prefix="bench-scenario-") as tmp:
        argv = ["demo", "--scenario", scenario, "--transport", "inproc", "--out", tmp, "--no-plots", "-q"]
        args = build_parser().parse_args(argv)
        c0, w0 = time.process_time(), time.perf_counter()
        import contextlib
        import io

        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            try:
                args._run(args)
            except SystemExit:
                pass
        demo_cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        rep = json.loads((Path(tmp) / "report.json").read_text(encoding="utf-8"))
    rp = rep.get("replanning") or {}
    out = {"demo_cpu_s": demo_cpu, "flight_cpu_s": flight.get("cpu_s"), "wall_s": wall,
           "completed": rep.get("completed"), "n_frames": rep.get("n_frames"), "sim_time_s": rep.get("sim_time_s"),
           "min_clearance_m": rp.get("min_clearance_m"), "max_error_m": (rep.get("tracking") or {}).get("max_error_m"),
           "events": rp.get("events"), "max_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}
    print(json.dumps(out))
    return 0


def start(tree: Path, scenario: str) -> subprocess.Popen:
    """One flight in a fresh process running ``tree``'s code."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", str(Path(scenario).resolve())]
    return subprocess.Popen(cmd, cwd=tree, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def result(p: subprocess.Popen, tree: Path, scenario: str) -> dict:
    out, err = p.communicate()
    if p.returncode != 0:
        raise RuntimeError(f"{tree}: {scenario}: exit {p.returncode}: {err.strip()[-500:]}")
    r = json.loads(out.strip().splitlines()[-1])
    r["tree"], r["scenario"] = str(tree), Path(scenario).name
    return r


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="*")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--tree", action="append", default=None, help="a checkout whose code to fly (repeatable)")
    ap.add_argument("--parallel", action="store_true",
                    help="fly each scenario on every tree at the same time (a shared, loaded machine: the trees "
                         "then see the same load) instead of one after the other")
    ap.add_argument("--json", default=None, metavar="FILE", help="also write every flight's record here")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return _child(args.child)
    trees = [Path(t).resolve() for t in (args.tree or [str(ROOT)])]
    rows = []
    for k in range(args.runs):
        for sc in args.scenarios:
            load = os.getloadavg()[0]
            if args.parallel:       # one flight per tree at once: the same load on both
                procs = [(tree, start(tree, sc)) for tree in trees]
                done = [result(p, tree, sc) for tree, p in procs]
            else:
                done = [result(start(tree, sc), tree, sc) for tree in trees]
            for tree, r in zip(trees, done):
                r["load"] = load
                rows.append(r)
                us = r["flight_cpu_s"] / r["n_frames"] * 1e6
                print(f"run {k + 1} {r['scenario']} {tree.name}: load {load:.1f}, {r['n_frames']} frames, flight CPU "
                      f"{r['flight_cpu_s']:.2f} s = {us:.0f} us/frame, demo CPU {r['demo_cpu_s']:.2f} s, wall "
                      f"{r['wall_s']:.1f} s, completed {r['completed']}, clearance {r['min_clearance_m']}, "
                      f"events {r['events']}", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1), encoding="utf-8")
    same = True
    for sc in args.scenarios:
        name = Path(sc).name
        outcomes = set()
        for tree in trees:
            rs = [r for r in rows if r["scenario"] == name and r["tree"] == str(tree)]
            outcomes |= {tuple(r[key] for key in OUTCOME_KEYS) for r in rs}
            print(f"median {name} {tree.name} of {len(rs)}: "
                  f"flight {statistics.median(r['flight_cpu_s'] / r['n_frames'] * 1e6 for r in rs):.0f} us CPU/frame, "
                  f"flight CPU {statistics.median(r['flight_cpu_s'] for r in rs):.2f} s, "
                  f"demo CPU {statistics.median(r['demo_cpu_s'] for r in rs):.2f} s")
        if len(outcomes) != 1:
            same = False
            print(f"{name}: OUTCOMES DIFFER: {sorted(outcomes, key=str)}")
    print("outcomes identical on every tree and run" if same else "outcomes differ")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
