"""CPU per call of the per-frame pieces that h16-speed3 changed, this tree against another.

Usage::

    python benchmarks/bench_speed3_parts.py [--tree DIR] [--repeat 3]

Runs the same micro-benchmarks in a fresh process per tree (default: this
checkout; ``--tree`` adds another, e.g. a worktree of main), interleaved
``--repeat`` times, and prints the minimum CPU time (``time.process_time``)
per call over the repeats:

- ``ObstacleMap.distance`` of the guard's two points against n voxels on a
  post's surface (n = 10, 50, 200);
- ``ObstacleMap.clear_beam`` of 1 m beams across a map of three posts, the map
  growing by one voxel before each beam (the voxels a wide beam's edges add);
- the scene's scalar terrain height (``scene_from_maps(...).height``, the
  movers' truth clearance) on tilted-hexagon's DEM.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import tree_runs  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _child() -> int:
    import math
    import time

    import numpy as np

    from companion.replan.perception import BeamEvidence
    from companion.replan.voxmap import ObstacleMap
    from mavcore.geometry import scene_from_maps
    from mavcore.maps import load_dem

    out = {}

    def per_call(f, n):
        t = time.process_time()
        for _ in range(n):
            f()
        return (time.process_time() - t) / n * 1e6

    rng = np.random.default_rng(1)
    P = np.array([[8.0, 4.0, 1.5], [8.01, 4.0, 1.5]])
    for n in (10, 50, 200):
        m = ObstacleMap(0.1)
        while len(m) < n:
            a, z = rng.uniform(0.0, 2.0 * math.pi), rng.uniform(0.0, 2.0)
            m.add((10.0 + 0.3 * math.cos(a), 5.0 + 0.3 * math.sin(a), z))
        m.distance(P)
        out[f"distance, 2 points, {n} voxels"] = per_call(lambda: m.distance(P), 3000)

    m = ObstacleMap(0.1)
    for cx, cy in ((2.0, 2.0), (9.0, 2.5), (5.5, 8.0)):
        for _ in range(60):
            m.add((cx + rng.uniform(-0.3, 0.3), cy + rng.uniform(-0.3, 0.3), rng.uniform(0.5, 2.0)))
    beams = []
    for _ in range(2000):
        o = (rng.uniform(0.0, 11.0), rng.uniform(0.0, 10.0), 1.5)
        beams.append(BeamEvidence(o, (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), 0.2, 0.2, 1.0, None,
                                  float("nan")))
    adds = [(2.0 + rng.uniform(-0.3, 0.3), 2.0 + rng.uniform(-0.3, 0.3), rng.uniform(0.5, 2.0)) for _ in beams]
    it = iter(zip(beams, adds))

    def beam():
        ev, q = next(it)
        m.add(q)
        m.clear_beam(ev)
    out["clear_beam, 3 posts, map growing"] = per_call(beam, len(beams))

    dem = load_dem(str(ROOT / "missions" / "tilted-hexagon" / "dem.asc"))
    height = scene_from_maps(None, dem, (), 1.8).height
    x0, x1, y0, y1 = dem.extent_m
    pts = [(float(x), float(y)) for x, y in zip(rng.uniform(x0, x1, 5000), rng.uniform(y0, y1, 5000))]
    it2 = iter(pts)
    out["scene height, one point"] = per_call(lambda: height(*next(it2)), len(pts))
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(tree_runs.main(__doc__, _child, __file__, ROOT, digits=1))
