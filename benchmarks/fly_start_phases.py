#!/usr/bin/env python3
"""``companion fly --plan`` up to its first message, phase by phase (CPU s, one fresh process).

Usage (the tree to measure on ``PYTHONPATH``)::

    PYTHONPATH=TREE python benchmarks/fly_start_phases.py MISSION.yaml --plan P [--sortie N] \\
        --connect udpout:127.0.0.1:14999 --tlog /tmp/x.tlog --report /tmp/x.json -q

Imports the flight's modules first (as ``companion fly`` does, timed as one
phase), wraps the functions ``companion fly`` calls before the runner
(``load_mission``, ``load_plan``, ``load_mission_maps``, ``check_plan``,
``prepare``, ``check_flight_plan``, ``sensor_coverage_gate``, ``flight_setup``,
``build_flight_core``, ``release_freed_memory``, ...) with
``time.process_time``, and stops where ``MissionRunner.run`` would send the
first message. Prints each phase's own CPU time and the process's CPU and
wall clock when it ended (BENCHMARKS.md "h18-start").
"""

import sys
import time

T = time.process_time
t0, w0 = T(), time.perf_counter()
marks = []


def mark(name):
    marks.append((name, T() - t0, time.perf_counter() - w0))


import numpy  # noqa: E402,F401

mark("import numpy")
from companion.cli import main  # noqa: E402

mark("import companion.cli")
import companion.commands.fly as fly  # noqa: E402
from companion import assembly, plan_io, preflight, runner  # noqa: E402,F401
from companion.flight import environment  # noqa: E402,F401
from companion.replan import coverage_check  # noqa: E402,F401
from companion.trajectory import extrema  # noqa: E402,F401
import companion.link  # noqa: E402,F401
import companion.memory as memory  # noqa: E402
import companion.progress  # noqa: E402,F401
import mavcore.maps.field as field  # noqa: E402
import mavcore.mission as mission_pkg  # noqa: E402

mark("import the flight's modules")


def wrap(mod, name):
    f = getattr(mod, name)

    def timed(*a, **k):
        s = T()
        r = f(*a, **k)
        marks.append((name, T() - t0, time.perf_counter() - w0, T() - s))
        return r
    setattr(mod, name, timed)


for n in ("prepare", "open_link", "sensor_coverage_gate", "build_flight_core", "flight_setup", "check_free_space",
          "check_writable"):
    wrap(fly, n)
wrap(preflight, "check_flight_plan")
wrap(preflight, "check_plan")
wrap(mission_pkg, "load_mission")
wrap(memory, "release_freed_memory")
wrap(plan_io, "load_plan")
wrap(field, "load_mission_maps")


class _FirstMessage(BaseException):
    pass


def _run(self):
    mark("runner.run (first message)")
    raise _FirstMessage


runner.MissionRunner.run = _run
sys.argv = ["companion", "fly"] + sys.argv[1:]
try:
    main()
except _FirstMessage:
    pass
for m in marks:
    print(f"{m[0]:32s} " + (f"self {m[3]:.3f} s  " if len(m) > 3 else " " * 14) + f"(CPU {m[1]:.3f} s, wall {m[2]:.3f} s)")
