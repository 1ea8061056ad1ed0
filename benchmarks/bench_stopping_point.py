"""Cost of the stopping point of the avoiding reference (issue 15, docs/replan.md "The
stopping point"), in CPU time (``time.process_time``: the machine is shared).

Run: ``python benchmarks/bench_stopping_point.py [--runs 3] [--micro]``

``--micro``: the cost of one ``_shape`` alone (CPU time, median of 5 x 300 calls) on
flat-rectangle's maps with the guard (a 0.25 m post's voxels in the obstacle map for the second case),
for a reference at 1 m/s along a corridor beside the rows (no obstacle known: one
candidate judged), and at 0.8 m/s toward the post 1.5 m away (the brake reaches its
clearance: every rung of the ladder judged); against ``ReferenceShaper.step`` alone
(what the modes paid before).

``bench_replan``'s avoiding flight (flat-rectangle, 250 Hz, 41 rangefinders at
25 Hz, the cylinder r 0.25 m, 1.8 m tall in the second corridor) with the
mission's guard attached to the replanner, as a flight has it
(``companion.assembly.build_guard``): per-frame CPU time of ``on_pose`` + the
frame's ``on_range`` calls + ``step``, median and p90 over the clear-way frames
and over the avoid/climb/stop frames, and the mean cost of one ``_shape`` (the
shaper's step and, with a guard, the brake predicted and judged). Runs from any
checkout (the branch point has no ``_shape``: its column is empty there).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def run() -> dict:
    import bench_replan as B
    from mavcore.mission.sim import ObstacleConfig
    from companion.safety import Guard, GuardConfig, SafetyScene, known_obstacle_distance

    B.time.perf_counter = time.process_time
    m, plan, known, gplan = B.setup("flat-rectangle")
    base = B.Replanner

    def with_guard(cfg, kn, gp):
        rp = base(cfg, kn, gp)
        rp.guard = Guard(GuardConfig.from_mission(m), SafetyScene.from_known_map(rp.known),
                         known_obstacle_distance(rp.memory, lambda: rp.known))
        return rp
    B.Replanner = with_guard
    shape = getattr(base, "_shape", None)
    spent = [0, 0.0]
    if shape is not None:
        def timed(self, dt, v):
            t0 = time.process_time()
            out = shape(self, dt, v)
            spent[0] += 1
            spent[1] += time.process_time() - t0
            return out
        base._shape = timed
    try:
        _, _, _, clear = B.fly(m, plan, known, gplan, (), 0.004, 10, 1e9, timed=True)
        obstacle = ObstacleConfig(type="cylinder", x=11.0, y=6.25, height=1.8, radius=0.25)
        rp, _, modes, costs = B.fly(m, plan, known, gplan, (obstacle,), 0.004, 10, 1e9, timed=True)
    finally:
        B.Replanner = base
        if shape is not None:
            base._shape = shape
    busy = np.array([md in ("avoid", "climb", "stop") for md in modes])
    return {"clear": np.asarray(clear), "busy": costs[busy], "shape_us": 1e6 * spent[1] / max(spent[0], 1),
            "n_shape": spent[0], "limited": getattr(rp, "n_stop_limited", None),
            "events": [(round(e.t_s, 2), e.action) for e in rp.stats.event_list]}


def micro() -> None:
    import types

    import bench_replan as B
    from companion.replan.replanner import Replanner
    from companion.replan.shaper import ReferenceShaper
    from companion.safety import Guard, GuardConfig, SafetyScene, known_obstacle_distance

    m, plan, known, gplan = B.setup("flat-rectangle")
    rp = Replanner(B.mission_replan_config(m), known, gplan)
    rp.guard = Guard(GuardConfig.from_mission(m), SafetyScene.from_known_map(rp.known),
                     known_obstacle_distance(rp.memory, lambda: rp.known))
    p0 = np.asarray(gplan.trajectory.sample(5.0).p, float)
    v0 = np.asarray(gplan.trajectory.sample(5.0).v, float)
    u = v0 / max(float(np.linalg.norm(v0)), 1e-9)
    post = p0 + 1.5 * u
    cases = {"along the corridor, 1 m/s, no obstacle": (p0, u),
             "toward a post 1.5 m ahead, 0.8 m/s": (p0, 0.8 * u)}
    for name, (p, v) in cases.items():
        if "post" in name:
            for dz in np.arange(-1.0, 0.3, 0.1):
                for a in np.linspace(0, 2 * np.pi, 12, endpoint=False):
                    rp.memory.add(tuple(post + [0.25 * np.cos(a), 0.25 * np.sin(a), dz]))
        for label, fn in (("shaper.step", None), ("_shape", Replanner._shape)):
            runs = []
            for _ in range(5):
                rp.shaper = ReferenceShaper(m.replan.accel_m_s2, m.replan.jerk_m_s3)
                t0 = time.process_time()
                for _ in range(300):
                    rp.shaper.reset(p, v, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
                    if fn is None:
                        rp.shaper.step(0.004, v.tolist())
                    else:
                        fn(rp, 0.004, v.tolist())
                runs.append((time.process_time() - t0) / 300 * 1e6)
            print(f"{name:28s} {label:12s} median of 5 x 300: {np.median(runs):7.1f} us per call")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--micro", action="store_true")
    args = ap.parse_args()
    if args.micro:
        micro()
        return
    for _ in range(args.runs):
        r = run()
        c, b = r["clear"], r["busy"]
        print(f"clear way median {np.median(c) * 1e6:7.1f} us p90 {np.percentile(c, 90) * 1e6:7.1f} us | "
              f"avoiding median {np.median(b) * 1e6:7.1f} us p90 {np.percentile(b, 90) * 1e6:7.1f} us "
              f"({len(b)} frames) | _shape {r['shape_us']:.1f} us x {r['n_shape']}, limited {r['limited']}")
        print("events:", r["events"])


if __name__ == "__main__":
    main()
