#!/usr/bin/env python3
"""CPU time of ``companion plan``'s phases in one process.

Usage::

    python benchmarks/bench_plan_phases.py MISSION.yaml [--reps N]

Imports the planner (timed), then runs ``companion plan MISSION -o TMP`` in
this process ``N`` times, with the planning functions listed in ``PHASES``
wrapped by a ``time.process_time`` accumulator (nested phases are counted in
their callers too; ``xK``: calls). Prints one line per repetition: the
imports, the whole run and each phase. The first repetition is the one a
fresh ``companion plan`` process sees (memory not yet touched); run the
baseline the same way in the same script, interleaved, on a shared machine.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import importlib
import io
import sys
import tempfile
import time
from pathlib import Path

#: module -> functions (attributes of the module; ``Class.method`` for methods)
PHASES = {
    "companion.coverage.rows": ["detect_rows"],
    "companion.coverage.beam": ["isoa_sweep"],
    "companion.coverage.freespace": ["erode_free_space"],
    "companion.coverage.boustrophedon": ["join_segments"],
    "companion.coverage.gridpath": ["aux_paths", "simplify_many", "cell_path", "cell_graph", "mask_graph",
                                    "_graph_of", "dijkstra"],
    "companion.coverage.blockgraph": ["build_block_graph", "BlockGraph.corridor", "BlockGraph.cells_of"],
    "companion.coverage.plan": ["plan_coverage", "reachable_segments"],
    "companion.coverage.transit": ["build_transit_tree", "TransitTree.paths_to"],
    "companion.coverage.waypoints": ["extract_waypoints", "waypoints_along"],
    "companion.coverage.corridors": ["coverage_fraction"],
    "mavcore.maps.grid": ["ElevationModel._interp"],
    "companion.sorties": ["plan_sorties", "central_launch_xy"],
    "companion.planner": ["plan_mission"],
    "companion.trajectory.lqr": ["generate_trajectory"],
}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mission")
    ap.add_argument("--reps", type=int, default=1)
    args = ap.parse_args(argv)
    t_imp = time.process_time()
    import companion.planner  # noqa: F401
    from companion.cli import main as cli_main
    t_imp = time.process_time() - t_imp
    acc: dict[str, float] = collections.defaultdict(float)
    calls: collections.Counter = collections.Counter()

    def wrap(name, f):
        def timed(*a, **k):
            t = time.process_time()
            try:
                return f(*a, **k)
            finally:
                acc[name] += time.process_time() - t
                calls[name] += 1
        return timed

    companions = [m for n, m in sys.modules.items() if n.startswith("companion") and m is not None]
    for mod_name, names in PHASES.items():
        mod = importlib.import_module(mod_name)
        for name in names:
            owner_name, _, attr = name.rpartition(".")
            owner = getattr(mod, owner_name) if owner_name else mod
            f = getattr(owner, attr, None)
            if f is None:
                continue            # not in this version of the planner
            timed = wrap(name if owner_name else attr if attr != "dijkstra" else f"dijkstra({mod_name})", f)
            if owner_name:
                setattr(owner, attr, timed)
            elif attr == "dijkstra":
                setattr(mod, attr, timed)       # only this module's searches
            else:               # every module that imported the function by name
                for m in companions:
                    for k, v in list(vars(m).items()):
                        if v is f:
                            setattr(m, k, timed)
    with tempfile.TemporaryDirectory(prefix="plan-phases-") as tmp:
        for _ in range(args.reps):
            acc.clear()
            calls.clear()
            t = time.process_time()
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                rc = cli_main(["plan", args.mission, "-o", str(Path(tmp) / "plan.json")])
            total = time.process_time() - t
            if rc:
                raise SystemExit(f"{args.mission}: companion plan exit {rc}")
            print(f"imports {t_imp:.2f} run {total:.2f}  " + "  ".join(
                f"{k} {v:.2f}" + (f"x{calls[k]}" if calls[k] > 1 else "") for k, v in acc.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
