"""Costs of the persistent obstacle map (issue 15), in CPU time (``time.process_time``:
the benchmark machine is shared and loaded, wall time per frame counts other processes).

Run: ``python benchmarks/bench_obstacle_map.py``

- ``distance``: ``ObstacleMap.distance`` for 100 points within 1 m of a vehicle
  beside a 10 m x 1 m wall and a 0.5 m post (1500 voxels of 0.1 m); median of
  5 x 500 calls.
- per-step: ``bench_replan``'s flights (flat-rectangle, 250 Hz, 41 rangefinders
  at 25 Hz, the cylinder r 0.25 m, 1.8 m tall in the second corridor), each
  frame's ``on_pose`` + ``on_range`` + ``step`` timed in CPU time; medians of the
  clear way, the avoiding frames, and the frames 38.9-45.4 s (avoid and climb in
  both the old and the new replanner: the same work compared).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def distance_cost() -> None:
    from companion.replan.voxmap import ObstacleMap

    om = ObstacleMap(0.1)
    for y in np.arange(0.05, 10, 0.1):
        for z in np.arange(0.05, 1.0, 0.1):
            om.add((5.05, y, z))
    for x in np.arange(7.05, 7.5, 0.1):
        for y in np.arange(4.05, 4.5, 0.1):
            for z in np.arange(0.05, 2.0, 0.1):
                om.add((x, y, z))
    rng = np.random.default_rng(1)
    runs = []
    for _ in range(5):
        near = np.array([4.0, 5.0, 1.5]) + rng.uniform(-1, 1, (100, 3))
        om.distance(near)
        t = time.process_time()
        for _ in range(500):
            om.distance(near)
        runs.append((time.process_time() - t) / 500 * 1e3)
    print(f"distance: {len(om)} voxels, 100 points: median {np.median(runs):.3f} ms CPU per call")


def step_cost() -> None:
    import bench_replan as B
    from mavcore.mission.sim import ObstacleConfig

    B.time.perf_counter = time.process_time          # the benchmark's per-frame timer, CPU time instead
    m, plan, known, gplan = B.setup("flat-rectangle")
    _, _, _, clear = B.fly(m, plan, known, gplan, (), 0.004, 10, 1e9, timed=True)
    obstacle = ObstacleConfig(type="cylinder", x=11.0, y=6.25, height=1.8, radius=0.25)
    rp, _, modes, costs = B.fly(m, plan, known, gplan, (obstacle,), 0.004, 10, 1e9, timed=True)
    busy = np.array([md in ("avoid", "climb", "stop") for md in modes])
    t = 0.004 * np.arange(len(costs))
    same = (t >= 38.9) & (t <= 45.4)
    for name, x in (("clear way", np.asarray(clear)), ("avoiding (avoid/climb/stop)", costs[busy]),
                    ("avoid + climb, 38.9-45.4 s", costs[same])):
        print(f"{name:30s} median {np.median(x) * 1e6:7.1f} us  p90 {np.percentile(x, 90) * 1e6:7.1f} us"
              f"  ({len(x)} frames)")
    print("events:", [(round(e.t_s, 2), e.action) for e in rp.stats.event_list])


if __name__ == "__main__":
    distance_cost()
    step_cost()
