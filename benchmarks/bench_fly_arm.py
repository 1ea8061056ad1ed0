#!/usr/bin/env python3
"""``companion fly --plan`` against the bundled SITL: time to its first message and to the ARM command, two trees interleaved.

Usage::

    python benchmarks/bench_fly_arm.py --tree base=/tmp/base --tree new=. \\
        MISSION.yaml [--sortie N] [--start X,Y] [--runs 5] [--plans DIR]

Each run starts ``sitl MISSION --lockstep [--start X,Y] --listen udpin:127.0.0.1:PORT``
(fresh, not timed: the companion starts once the SITL prints its ready line),
then a fresh ``python -c ARM MISSION --plan P [--sortie N] --connect
udpout:127.0.0.1:PORT`` with ``OMP_NUM_THREADS=1`` and a warm bytecode cache
(``bench_prepare_ab._env``). ``ARM`` runs ``companion fly`` with
``Connection.send``/``send_actuators`` wrapped to note (``time.monotonic``, the
same clock as the parent's) the first message sent to the vehicle and the
``MAV_CMD_COMPONENT_ARM_DISARM`` (param1 = 1) command, and ends the process
(``os._exit``) right after the ARM command is sent: nothing is flown. The
first message is the figure of ``bench_fly_start.py`` (which stops where the
runner starts, before it); the ARM command follows the vehicle's handshake
(streams, parameters, mission upload) and ``RunnerConfig.preflight_s`` of
vehicle time, so it depends on the SITL as well. Prints per tree the medians
of both and the companion's CPU time (user + sys, ``os.wait4``) up to the ARM.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_plan_cli import run  # noqa: E402
from bench_prepare_ab import _env  # noqa: E402

ARM = """
import os, sys, time
out = os.environ["BENCH_ARM_OUT"]
from companion.link import connection
seen = {}
def note(what):
    if what not in seen:
        seen[what] = time.monotonic()
send, send_actuators = connection.Connection.send, connection.Connection.send_actuators
def send_noted(self, msg):
    note("first")
    send(self, msg)
    if msg.get_type() == "COMMAND_LONG" and msg.command == 400 and msg.param1 == 1:
        note("arm")
        with open(out, "w") as f:
            f.write(f"{seen['first']!r} {seen['arm']!r}")
        os._exit(0)
def send_actuators_noted(self, *a, **k):
    note("first")
    return send_actuators(self, *a, **k)
connection.Connection.send, connection.Connection.send_actuators = send_noted, send_actuators_noted
from companion.cli import main
sys.argv = ["companion", "fly"] + sys.argv[1:]
sys.exit(main())
"""


def arm_once(py: str, name: str, tree: str, mission: str, plan: str, sortie: int | None, start: str | None,
             port: int, cache: str, work: Path) -> tuple[float, float, float]:
    """(first message s, ARM command s, CPU s up to the ARM) of one fresh companion."""
    env = _env(tree, cache)
    cmd = [py, "-m", "sitl", mission, "--lockstep", "--listen", f"udpin:127.0.0.1:{port}", "-q"]
    if start:
        cmd += ["--start", start]
    sitl = subprocess.Popen(cmd, env=env, cwd=tree, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    for line in sitl.stdout:                  # the SITL prints its ready line once its world is built
        if line.startswith("sitl: ready"):
            break
    threading.Thread(target=sitl.stdout.read, daemon=True).start()
    out = work / f"arm-{name}.txt"
    out.unlink(missing_ok=True)
    argv = [py, "-c", ARM, mission, "--plan", plan, "--connect", f"udpout:127.0.0.1:{port}",
            "--tlog", str(work / f"{name}.tlog"), "--report", str(work / f"{name}-report.json"), "-q"]
    if sortie is not None:
        argv += ["--sortie", str(sortie)]
    t0 = time.monotonic()
    fly = subprocess.Popen(argv, env=dict(env, BENCH_ARM_OUT=str(out)), cwd=tree,
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(fly.pid, 0)
    err = fly.stderr.read().decode(errors="replace")
    fly.stderr.close()
    sitl.terminate()
    sitl.wait()
    if os.waitstatus_to_exitcode(status) != 0 or not out.exists():
        raise SystemExit(f"companion fly ({tree}) ended before its ARM command:\n{err[-2000:]}")
    first, arm = (float(x) for x in out.read_text().split())
    return first - t0, arm - t0, usage.ru_utime + usage.ru_stime


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mission")
    ap.add_argument("--tree", action="append", required=True, metavar="NAME=DIR")
    ap.add_argument("--sortie", type=int, default=None, help="fly this sortie (default: the whole plan)")
    ap.add_argument("--start", default=None, metavar="X,Y", help="the SITL's start (sitl --start)")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--port", type=int, default=14671)
    ap.add_argument("--plans", default="/tmp/bench-fly-start")
    args = ap.parse_args(argv)
    py = sys.executable
    trees = [(s.split("=", 1)[0], os.path.abspath(s.split("=", 1)[1])) for s in args.tree]
    mission = os.path.abspath(args.mission)
    out = Path(args.plans)
    out.mkdir(parents=True, exist_ok=True)
    plans = {}
    for name, tree in trees:
        plan = out / f"{name}-{Path(mission).parent.name}.json"
        if not plan.exists():
            run([py, "-m", "companion", "plan", mission, "-o", str(plan)], _env(tree, None), tree)
        plans[name] = str(plan)
    caches = {name: str(out / f"pyc-{name}") for name, _ in trees}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for name, tree in trees:          # warm each tree's bytecode cache
            arm_once(py, name, tree, mission, plans[name], args.sortie, args.start, args.port, caches[name], work)
        print(f"load average before {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
        res: dict = {}
        for _ in range(args.runs):
            for name, tree in trees:
                res.setdefault(name, []).append(arm_once(py, name, tree, mission, plans[name], args.sortie,
                                                         args.start, args.port, caches[name], work))
        print(f"load average after {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    what = "whole plan" if args.sortie is None else f"sortie {args.sortie}"
    for name, _ in trees:
        rows = res[name]
        med = [statistics.median(r[i] for r in rows) for i in range(3)]
        print(f"{Path(mission).parent.name}, {what}, {name}: first message {med[0]:.3f} s "
              f"({', '.join(f'{r[0]:.2f}' for r in rows)}), ARM {med[1]:.3f} s "
              f"({', '.join(f'{r[1]:.2f}' for r in rows)}), CPU to ARM {med[2]:.3f} s "
              f"({', '.join(f'{r[2]:.2f}' for r in rows)})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
