"""Wall-clock time since this process started (for ``timings_s.wall`` of plan.json).

The one place the companion reads the wall clock for a figure it reports
about itself: ``companion plan``'s own duration, start-up and imports
included. Linux gives the process start in ``/proc/self/stat`` (clock
ticks since boot, field 22) and the time since boot in ``/proc/uptime``
(10 ms resolution); elsewhere the figure counts from the first import of
this module (done by ``companion.cli``, so only the interpreter's own
start-up is missed).
"""

from __future__ import annotations

import os
import time

_IMPORTED = time.perf_counter()


def _from_proc() -> float | None:
    try:
        with open("/proc/self/stat", "rb") as f:
            stat = f.read()
        with open("/proc/uptime", "rb") as f:
            uptime_s = float(f.read().split()[0])
        # the command name (field 2) may hold spaces: count fields after its ')'
        start_ticks = int(stat[stat.rindex(b")") + 2:].split()[19])
        return uptime_s - start_ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


def process_wall_s() -> float:
    """Seconds of wall-clock time since the process started (>= 0)."""
    since_import = time.perf_counter() - _IMPORTED
    from_proc = _from_proc()
    if from_proc is None:
        return since_import
    return max(from_proc, since_import)
