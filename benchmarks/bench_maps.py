#!/usr/bin/env python3
"""Cost of the map outputs of ``companion plan`` (``--geojson``, ``--kml``,
``--html``, ``--plot``) on a planned field.

Usage::

    python missions/corpus.py --large --out /tmp/large
    OMP_NUM_THREADS=1 python benchmarks/bench_maps.py --mission /tmp/large/mission.yaml [--runs 3]

Plans the mission once, then times each step (``time.process_time``, median
of the runs): the layers (``map_layers.plan_layers``: rows found again in the
grid, the fence), the GeoJSON, the KML, the HTML page and plan.png; prints
the sizes of the outputs.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from companion.geo_export import geojson_text, kml_text  # noqa: E402
from companion.html_map import html_map_text  # noqa: E402
from companion.map_layers import plan_layers, row_lines_xy  # noqa: E402
from mavcore.mission import load_mission  # noqa: E402
from companion.planner import plan_mission  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mission", required=True, help="mission YAML")
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args(argv)
    mission = load_mission(args.mission)
    plan = plan_mission(mission)
    layers = plan_layers(plan, mission)
    print(f"{mission.name}: {len(layers.path_enu_m)} way-points, {len(layers.sorties)} sorties, "
          f"{len(layers.rows_xy_m)} rows, fence {len(layers.fence_xy_m)} vertices")
    steps = {"rows (row_lines_xy)": lambda: row_lines_xy(plan.grid),
             "layers (plan_layers)": lambda: plan_layers(plan, mission),
             "geojson": lambda: geojson_text(layers), "kml": lambda: kml_text(layers),
             "html": lambda: html_map_text(layers)}
    try:
        from companion.plot import render_plan

        steps["plan.png"] = lambda: render_plan(plan)
    except ImportError:
        pass
    for name, f in steps.items():
        times, out = [], None
        for _ in range(args.runs):
            t = time.process_time()
            out = f()
            times.append(time.process_time() - t)
        size = f", {len(out.encode() if isinstance(out, str) else out) / 1e6:.2f} MB" \
            if isinstance(out, (str, bytes)) else ""
        print(f"  {name}: median {statistics.median(times):.3f} s (min {min(times):.3f}, max {max(times):.3f}){size}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
