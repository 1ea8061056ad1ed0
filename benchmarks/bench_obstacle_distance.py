"""CPU cost of issue 15's speed bound and OBSTACLE_DISTANCE layer (BENCHMARKS.md, h15-sensors).

- the exact largest speed between the coverage check's 10 Hz samples
  (``companion.trajectory.extrema``) and the whole pre-flight check;
- packing one OBSTACLE_DISTANCE from a 16-beam ring (``pack_sectors``);
- one step of the SITL's collision prevention (``CollisionPrevention.limit``).

Process CPU time (``time.process_time``): the machine may be shared.

    python benchmarks/bench_obstacle_distance.py
"""

from __future__ import annotations

import math
import statistics
import time

import numpy as np

from mavcore.frames import euler_zyx2rotmat
from mavcore.codec import Range
from companion.link.obstacle_distance import pack_sectors, sector_beam
from mavcore.mission import load_mission
from companion.planner import plan_mission
from companion.replan.coverage_check import mission_coverage, sample_times
from companion.trajectory.extrema import max_speed_on_intervals
from mavcore.codec import ObstacleSectors
from sitl.collision_prevention import CollisionPrevention, CollisionPreventionConfig


def _cpu(fn, n: int) -> float:
    c0 = time.process_time()
    for _ in range(n):
        fn()
    return (time.process_time() - c0) / n


def main() -> None:
    for name in ("flat-rectangle", "obstacle-tall"):
        m = load_mission(f"missions/{name}/mission.yaml")
        tr = plan_mission(m).trajectory
        t = sample_times(tr.t0, tr.tf)
        ex = statistics.median(_cpu(lambda: max_speed_on_intervals(tr, t), 1) for _ in range(5))
        cov = statistics.median(_cpu(lambda: mission_coverage(m, tr, 0.442), 1) for _ in range(5))
        print(f"{name}: {tr.knot_times_s.size - 1} pieces, {t.size} samples: extrema {1e3 * ex:.1f} ms CPU, "
              f"whole coverage check {1e3 * cov:.1f} ms CPU")
    beams = []
    for k in range(16):
        R = tuple(np.asarray(euler_zyx2rotmat(0.0, 0.0, math.radians(22.5 * k))).ravel().tolist())
        beams.append(sector_beam(Range(0, k, 3.0, 0.1, 6.0, 100, math.radians(24.0), math.radians(10.0),
                                       math.nan, False, R)))
    print(f"pack_sectors, 16 beams: {1e6 * _cpu(lambda: pack_sectors(beams), 2000):.1f} us CPU")
    cp = CollisionPrevention(CollisionPreventionConfig(0.7))
    d = np.full(72, math.inf)
    d[:10] = 2.0
    cp.on_sectors(ObstacleSectors(-np.radians(np.arange(72) * 5.0), math.radians(2.5), d))
    print(f"CollisionPrevention.limit, 10 obstacle sectors: "
          f"{1e6 * _cpu(lambda: cp.limit(1.0, 0.2, 0.1, 0.0), 20000):.1f} us CPU")


if __name__ == "__main__":
    main()
