"""CPU per call of the companion's per-reading map queries, this tree against another.

Usage::

    python benchmarks/bench_known_parts.py [--tree DIR] [--repeat 3]

Runs the same micro-benchmarks in a fresh process per tree (default: this
checkout; ``--tree`` adds another, e.g. a worktree of main), interleaved
``--repeat`` times, and prints the minimum CPU time (``time.process_time``)
per call over the repeats, with a checksum of the answers (the trees must
agree):

- ``KnownMap.explains`` of rangefinder returns in tilted-hexagon's corridors
  (every reading's fan rays ask it: a profile of an obstacle flight gave
  ~10 calls a frame);
- ``KnownMap.cell_of`` of points over the field;
- the guard's distance to a re-route's added cells (``known_obstacle_distance``
  with an empty memory: two points, ~320 cells over a 2 m x 1.6 m box, one top
  per cell as a re-route leaves them).
"""

from __future__ import annotations

import hashlib
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

    from companion.replan.knownmap import KnownMap
    from companion.safety import known_obstacle_distance
    from mavcore.maps.field import load_mission_maps
    from mavcore.mission.loader import load_mission

    out, check = {}, hashlib.sha256()

    def per_call(f, n):
        t = time.process_time()
        for _ in range(n):
            f()
        return (time.process_time() - t) / n * 1e6

    mission = load_mission(ROOT / "missions" / "tilted-hexagon" / "mission.yaml")
    grid, dem = load_mission_maps(mission)
    known = KnownMap.from_mission(mission, grid, dem)
    rng = np.random.default_rng(1)
    x0, x1, y0, y1 = dem.extent_m
    rays = []
    for _ in range(20000):
        o = (rng.uniform(x0 + 2, x1 - 2), rng.uniform(y0 + 2, y1 - 2), known.ground_z(0.0, 0.0) + rng.uniform(1.0, 3.0))
        a, e = rng.uniform(0, 2 * math.pi), rng.uniform(-0.3, 0.1)
        d = (math.cos(a) * math.cos(e), math.sin(a) * math.cos(e), math.sin(e))
        rays.append((o, d, rng.uniform(0.3, 6.0)))
    it = iter(rays)
    res = []
    out["explains, one return"] = per_call(lambda: res.append(known.explains(*next(it))), len(rays))
    check.update(bytes(res))
    pts = [(float(x), float(y)) for x, y in zip(rng.uniform(x0, x1, 20000), rng.uniform(y0, y1, 20000))]
    it2 = iter(pts)
    cells = []
    out["cell_of, one point"] = per_call(lambda: cells.append(known.cell_of(*next(it2))), len(pts))
    check.update(repr(cells).encode())

    # a re-route's added cells over a box, one top a cell
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    xy = np.column_stack([cx + rng.uniform(-1.0, 1.0, 2000), cy + rng.uniform(-0.8, 0.8, 2000)])
    added = known.with_obstacle(xy, tops_z_m=known.ground_z(cx, cy) + rng.uniform(1.2, 1.7, 2000))

    class _Empty:
        def __len__(self):
            return 0
    od = known_obstacle_distance(_Empty(), lambda: added)
    P = np.array([[cx + 2.0, cy + 1.0, 2.0], [cx + 2.01, cy + 1.0, 2.0]])
    ds = []
    out[f"added cells distance, 2 points, {int(np.count_nonzero(added.added))} cells"] = \
        per_call(lambda: ds.append(od(P)), 3000)
    check.update(np.concatenate(ds).tobytes())
    out["checksum"] = check.hexdigest()[:16]
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(tree_runs.main(__doc__, _child, __file__, ROOT, digits=2))
