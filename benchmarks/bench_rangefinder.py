"""Cost of one rangefinder reading in the SITL (``Rangefinder.true_distance``).

Usage::

    python benchmarks/bench_rangefinder.py [--mission missions/obstacle-tall/mission.yaml] [--reps 3]
        [--fan-only] [--default-suite]

Flies the mission's rangefinder suite (its ``sim.rangefinders``, else the
default four) along a straight, level line through the mission's world,
past its obstacles, and times every sensor's ``true_distance`` at each
pose (0.05 m apart, yaw turning 1 deg per step so that obstacles sweep
through every beam). Prints the median and the 99th percentile of the wall time per reading
(us), and the process CPU time per reading and per 250 Hz sensor frame at
each sensor's own rate (the CPU figure is the one a loaded machine does not
inflate).
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

from mavcore.mission import load_mission
from sitl.sensors import Rangefinder
from sitl.world import load_world


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mission", default="missions/obstacle-tall/mission.yaml")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--fan-only", action="store_true",
                    help="the model before issue 15: the five rays only (no exact field-of-view pass)")
    ap.add_argument("--default-suite", action="store_true", help="the default rangefinders instead of the mission's")
    a = ap.parse_args()
    mission = load_mission(a.mission)
    world = load_world(mission)
    from mavcore.mission.sim import default_rangefinders

    cfgs = default_rangefinders() if a.default_suite else mission.sim.rangefinders_or_default
    rfs = [Rangefinder(c, 0) for c in cfgs]
    if a.fan_only:
        for rf in rfs:
            rf._wide = False
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
    cpu0 = time.process_time()
    for _ in range(a.reps):
        for p, R in poses:
            for rf in rfs:
                t0 = time.perf_counter_ns()
                rf.true_distance(world, p, R)
                per.append((time.perf_counter_ns() - t0) / 1e3)
    cpu_us = (time.process_time() - cpu0) * 1e6 / len(per)
    per.sort()
    med = statistics.median(per)
    p99 = per[int(0.99 * (len(per) - 1))]
    readings_per_s = sum(c.rate_hz for c in cfgs)
    print(f"{a.mission}{' (fan only)' if a.fan_only else ''}: {len(rfs)} rangefinders, {len(obs)} obstacles, {len(per)} readings")
    print(f"per reading: median {med:.1f} us, p99 {p99:.1f} us, mean {statistics.fmean(per):.1f} us")
    print(f"process CPU per reading (timer included, not preempted): {cpu_us:.1f} us; per 250 Hz frame at the "
          f"sensors' rates ({readings_per_s:.0f} readings/s): {cpu_us * readings_per_s / 250.0:.1f} us")


if __name__ == "__main__":
    main()
