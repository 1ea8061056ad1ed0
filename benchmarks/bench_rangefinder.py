"""Cost of one rangefinder reading in the SITL (``Rangefinder.true_distance``).

Usage::

    python benchmarks/bench_rangefinder.py [--mission missions/obstacle-tall/mission.yaml] [--reps 3]

Flies the mission's rangefinder suite (its ``sim.rangefinders``, else the
default four) along a straight, level line through the mission's world,
past its obstacles, and times every sensor's ``true_distance`` at each
pose (0.05 m apart, yaw turning 1 deg per step so that obstacles sweep
through every beam). Prints the median and the 99th percentile per reading
(us), and the same per 250 Hz sensor frame at each sensor's own rate.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

from companion.mission import load_mission
from sitl.sensors import Rangefinder
from sitl.world import load_world


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mission", default="missions/obstacle-tall/mission.yaml")
    ap.add_argument("--reps", type=int, default=3)
    a = ap.parse_args()
    mission = load_mission(a.mission)
    world = load_world(mission)
    rfs = [Rangefinder(c, 0) for c in mission.sim.rangefinders_or_default]
    obs = world.obstacles
    # a line at 1.5 m through the first obstacle (or the world's start cell), 12 m long
    if obs:
        cx, cy = obs[0].x, obs[0].y
    else:
        cx, cy = world.start_cell_enu() or (0.0, 0.0)
    poses = []
    for k in range(240):
        x = cx - 6.0 + 0.05 * k
        yaw = math.radians(k)
        c, s = math.cos(yaw), math.sin(yaw)
        poses.append(((x, cy + 0.6, world.ground_height(x, cy) + 1.5), (c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)))
    per = []
    for _ in range(a.reps):
        for p, R in poses:
            for rf in rfs:
                t0 = time.perf_counter_ns()
                rf.true_distance(world, p, R)
                per.append((time.perf_counter_ns() - t0) / 1e3)
    per.sort()
    med = statistics.median(per)
    p99 = per[int(0.99 * (len(per) - 1))]
    readings_per_s = sum(c.rate_hz for c in mission.sim.rangefinders_or_default)
    print(f"{a.mission}: {len(rfs)} rangefinders, {len(obs)} obstacles, {len(per)} readings")
    print(f"per reading: median {med:.1f} us, p99 {p99:.1f} us, mean {statistics.fmean(per):.1f} us")
    print(f"per 250 Hz frame at the sensors' rates ({readings_per_s:.0f} readings/s): "
          f"mean {statistics.fmean(per) * readings_per_s / 250.0:.1f} us")


if __name__ == "__main__":
    main()
