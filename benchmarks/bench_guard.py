"""Benchmark of the guard (issue 15): its cost per 4 ms frame, and of one whole-plan check.

Run: ``python benchmarks/bench_guard.py [--mission flat-rectangle] [--frames 5000]``

Per frame: ``GuardGate.dispose`` on the reference of one frame (the mission's
planned trajectory sampled at 250 Hz, the first ``--frames`` frames of the
trajectory phase): terrain, rows and the known obstacles (``obstacle_distance``
over an ``ObstacleMemory``) at the sample and one finite-difference step
along its velocity. Three worlds:

- ``no obstacle``: the memory empty (a clear flight);
- ``memory 200``: 200 remembered points near the path (an avoidance);
- ``memory 1024 + added``: the memory full (its capacity) and 100 obstacle
  cells added to the map by a re-route.

CPU time of this process (``time.process_time_ns``, not wall time: the
machine is shared), per frame; median / p90 / p99. Issue 15's target: the
guard <= 0.3 ms per frame, median. Also: one whole-plan check
(``Guard.check_trajectory`` of the full plan, as before arming).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from companion.trajectory.reference import RefSample
from mavcore.mission import load_mission
from companion.planner import plan_mission
from companion.replan import KnownMap
from companion.replan.memory import ObstacleMemory
from companion.safety import Guard, GuardConfig, SafetyScene, known_obstacle_distance
from companion.safety.gate import GuardGate

ROOT = Path(__file__).resolve().parents[1]


def _frames(plan, n: int) -> list:
    tr = plan.trajectory
    t = tr.t0 + 0.004 * np.arange(n)
    s = tr.sample(t)
    z = (0.0, 0.0, 0.0)
    return [RefSample(tuple(p), tuple(v), z, z, z, (0.0, 1.0, 0.0)) for p, v in zip(s.p.tolist(), s.v.tolist())]


def _world(mission, plan, n_points: int, n_added: int, rng: np.random.Generator):
    known = KnownMap.from_mission(mission, plan.grid, plan.dem, plan.coverage.free_eroded)
    mem = ObstacleMemory(0.1, 1e9, 1e9, 0.15, capacity=max(n_points, 1))
    path = plan.trajectory.sample(np.linspace(plan.trajectory.t0, plan.trajectory.tf, 500)).p
    for k in range(n_points):
        q = path[rng.integers(len(path))] + rng.uniform(-3.0, 3.0, 3) * (1.0, 1.0, 0.3)
        mem.add(0.0, q)
    if n_added:
        xy = path[rng.integers(len(path), size=n_added), :2] + rng.uniform(-3.0, 3.0, (n_added, 2))
        known = known.with_obstacle(xy)
    return mem, known


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mission", default="flat-rectangle")
    ap.add_argument("--frames", type=int, default=5000)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    mission = load_mission(ROOT / "missions" / args.mission / "mission.yaml")
    plan = plan_mission(mission)
    frames = _frames(plan, args.frames)
    rng = np.random.default_rng(args.seed)
    cfg = GuardConfig.from_mission(mission)
    print(f"mission {args.mission}, {len(frames)} frames; CPU time per frame (ms)")
    print(f"{'world':<22} {'median':>8} {'p90':>8} {'p99':>8}")
    for name, n_pts, n_added in (("no obstacle", 0, 0), ("memory 200", 200, 0), ("memory 1024 + added", 1024, 100)):
        mem, known = _world(mission, plan, n_pts, n_added, rng)
        guard = Guard(cfg, SafetyScene.from_known_map(known), known_obstacle_distance(mem, lambda: known))
        gate = GuardGate(guard, mission.replan.jerk_m_s3)
        cost = np.empty(len(frames))
        for i, ref in enumerate(frames):
            t0 = time.process_time_ns()
            gate.dispose(i * 0.004, ref)
            cost[i] = (time.process_time_ns() - t0) * 1e-6
            if gate.engaged:                    # keep measuring the check, not the brake
                gate = GuardGate(guard, mission.replan.jerk_m_s3)
        print(f"{name:<22} {np.median(cost):8.3f} {np.percentile(cost, 90):8.3f} {np.percentile(cost, 99):8.3f}")
    guard = Guard(cfg, SafetyScene.from_known_map(KnownMap.from_mission(mission, plan.grid, plan.dem,
                                                                        plan.coverage.free_eroded)))
    t0 = time.process_time_ns()
    v = guard.check_trajectory(plan.trajectory)
    dt = (time.process_time_ns() - t0) * 1e-6
    print(f"whole plan ({plan.trajectory.tf - plan.trajectory.t0:.0f} s): {dt:.1f} ms CPU, passed: {v.ok}")


if __name__ == "__main__":
    main()
