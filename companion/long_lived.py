"""Keeping a command's long-lived objects out of the garbage collector's passes.

A ``companion plan`` process imports numpy, scipy, pyproj and the project
(~44 000 objects tracked by CPython's cyclic garbage collector) and keeps
them until it exits. Collecting them is wasted work, and it is not small:

* during the imports the collector runs ~100 young and ~9 middle passes,
  finding next to no garbage;
* every full pass during the planning traverses them all (the corpus
  10 ha field triggers two, the 1 ha parcel one);
* the interpreter's finalisation at exit runs full passes over them again.

Together ~0.15 s of CPU on the 1 ha parcel and ~0.3 s on the 10 ha corpus
field (``benchmarks/bench_plan_gc.py``, BENCHMARKS.md "h18-wall").

:func:`imports_kept` pauses the collector while the command imports its
libraries and then moves every object alive to the permanent generation
(``gc.freeze``, CPython >= 3.7), which no pass traverses; the collector then
resumes for the objects made afterwards. Frozen objects are still freed by
reference counting; only a reference cycle among them is never reclaimed.
That suits a process that does one command and exits, and not a library
call inside a long-lived process (a test session), so the commands do it
only when ``main`` runs as the process's own command line.
"""

from __future__ import annotations

import gc
from contextlib import contextmanager


@contextmanager
def imports_kept(enabled: bool):
    """Within: the garbage collector paused (``enabled``); on leaving normally, every
    object alive is frozen (``gc.freeze``). The collector's state is restored either way.
    ``enabled`` False: nothing changes."""
    if not enabled:
        yield
        return
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
        gc.freeze()
    finally:
        if was_enabled:
            gc.enable()
