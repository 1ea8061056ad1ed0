#!/usr/bin/env python3
"""The SITL's world of a mission: peak memory, build time, and the hits of seeded rays.

Usage::

    python benchmarks/bench_sitl_world.py MISSION.yaml [--rays 20000] [--seed 18] [--save HITS.npy]

Builds ``sitl.world.load_world(mission)`` in this process (run it in a fresh
one: the peak RSS is the process's, ``ru_maxrss``), then casts ``--rays``
seeded random rays of 12 m from points above the field (CPU times from
``time.process_time``). Prints the peak RSS, the CPU times, the number of
hits and the sum of the finite hit distances; ``--save`` writes every hit
distance (inf: none) so that two builds can be compared ray by ray
(``--compare OTHER.npy``: how many differ, and by how much at most).
"""

from __future__ import annotations

import argparse
import math
import resource
import time

import numpy as np


def rays(world, n: int, seed: int) -> np.ndarray:
    """Hit distances (m, inf: none) of ``n`` seeded rays of 12 m over the grid's extent."""
    grid = world.grid
    rng = np.random.default_rng(seed)
    h, (rows, cols) = grid.resolution_m, grid.shape
    out = np.empty(n)
    for k in range(n):
        gx, gy = rng.uniform(0, cols * h), rng.uniform(0, rows * h)
        c, s = math.cos(grid.origin_yaw_rad), math.sin(grid.origin_yaw_rad)
        x = float(grid.origin_xy_m[0]) + c * gx - s * gy
        y = float(grid.origin_xy_m[1]) + s * gx + c * gy
        z = world.ground_height(x, y) + rng.uniform(0.3, 4.0)
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        out[k] = world.raycast(x, y, z, float(d[0]), float(d[1]), float(d[2]), 12.0)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mission")
    ap.add_argument("--rays", type=int, default=20_000)
    ap.add_argument("--seed", type=int, default=18)
    ap.add_argument("--save", help="write the hit distances (.npy)")
    ap.add_argument("--compare", help="hit distances of another build (.npy) to compare with")
    args = ap.parse_args(argv)
    from mavcore.mission import load_mission
    from sitl.world import load_world

    mission = load_mission(args.mission)
    t0 = time.process_time()
    world = load_world(mission)
    t1 = time.process_time()
    hits = rays(world, args.rays, args.seed)
    t2 = time.process_time()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    fin = np.isfinite(hits)
    print(f"world build {t1 - t0:.2f} s CPU, {args.rays} rays {t2 - t1:.2f} s CPU, peak RSS {peak:.0f} MB, "
          f"{int(fin.sum())} hits, sum of the hit distances {float(hits[fin].sum())!r} m")
    if args.save:
        np.save(args.save, hits)
    if args.compare:
        other = np.load(args.compare)
        same_fin = np.isfinite(other) == fin
        diff = np.abs(hits[fin & same_fin] - other[fin & same_fin])
        print(f"against {args.compare}: {int((~same_fin).sum())} rays hit in one build only, "
              f"{int(np.count_nonzero(diff))} hits differ, by at most {float(diff.max(initial=0.0)):.3g} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
