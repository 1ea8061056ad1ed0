"""Cost of the stopping point of the avoiding reference (issue 15, docs/replan.md "The
stopping point"), in CPU time (``time.process_time``: the machine is shared).

Run: ``python benchmarks/bench_stopping_point.py [--runs 3]``

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1)
    args = ap.parse_args()
    for _ in range(args.runs):
        r = run()
        c, b = r["clear"], r["busy"]
        print(f"clear way median {np.median(c) * 1e6:7.1f} us p90 {np.percentile(c, 90) * 1e6:7.1f} us | "
              f"avoiding median {np.median(b) * 1e6:7.1f} us p90 {np.percentile(b, 90) * 1e6:7.1f} us "
              f"({len(b)} frames) | _shape {r['shape_us']:.1f} us x {r['n_shape']}, limited {r['limited']}")
        print("events:", r["events"])


if __name__ == "__main__":
    main()
