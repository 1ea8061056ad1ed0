"""CPU per call of the avoiding modes' one exit, ``Replanner._shape``, this tree against another.

Usage::

    python benchmarks/bench_shape.py [--tree DIR] [--repeat 3]

Runs in a fresh process per tree (default: this checkout; ``--tree`` adds another,
e.g. a worktree of an earlier commit), interleaved ``--repeat`` times, and prints
the minimum over the repeats of the median CPU time (``time.process_time``) per
call. The scene is ``tests/test_replan_gate_forecast.py``'s: flat ground, one row,
a thin post 3 m tall; R 0.4 m, clearances 0.5 m, braking at 1 m/s^2 after 0.5 s.
A mode asks for 0.9 m/s along +y:

- ``near``: the pass by the post, 1.0 m from its surface (every frame within 3 m
  of it: the stopping point and the forecast both work);
- ``far``: the same command 6 m from the post and the row (the forecast's speed
  bound passes every point without the finite differences).

The answers differ between trees by design (the forecast slows the pass), so no
checksum is compared.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import tree_runs  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _child() -> int:
    import time
    import types

    import numpy as np

    from mavcore.maps.grid import ElevationModel, OccupancyGrid
    from mavcore.mission.replan import ReplanConfig
    from companion.replan.replanner import Replanner
    from companion.replan.shaper import ReferenceShaper
    from companion.safety import Guard, GuardConfig, SafetyScene

    post, r_post = (2.0, 8.0), 0.05

    def dist(points):
        p = np.asarray(points, float).reshape(-1, 3)
        radial = np.maximum(np.hypot(p[:, 0] - post[0], p[:, 1] - post[1]) - r_post, 0.0)
        return np.hypot(radial, np.maximum(p[:, 2] - 3.0, 0.0))

    occ = np.zeros((200, 200), bool)
    occ[0:50, 50:52] = True
    grid = OccupancyGrid(occ, ~occ, 0.1)
    dem = ElevationModel(np.zeros((21, 21)), 0.0, 0.0, 1.0)
    cfg = GuardConfig(airframe_radius_m=0.4, terrain_clearance_m=0.5, row_clearance_m=0.5,
                      obstacle_clearance_m=0.5, accel_m_s2=1.0, delay_s=0.5)
    guard = Guard(cfg, SafetyScene.from_maps(grid, dem, 2.0), dist)
    out = {}
    for name, x0 in (("near", post[0] + r_post + 1.0), ("far", 9.0)):
        rp = types.SimpleNamespace(guard=guard, shaper=ReferenceShaper(1.0, 2.0), n_stop_limited=0, _brake=0.5,
                                   cfg=ReplanConfig(accel_m_s2=1.0, jerk_m_s3=2.0), emergency=False,
                                   n_emergency_brakes=0, _evading=False, _emergency_why="", _gate_since=None, _brake_stepped=False,
                                   _t_s=0.0)
        for m in ("_shape", "_least_room", "_set_emergency", "_calm"):
            setattr(rp, m, types.MethodType(getattr(Replanner, m), rp))
        rp.shaper.reset((x0, 5.5, 1.5), (0.0, 0.9, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        times = []
        for k in range(1500):                              # 6 s of 4 ms frames
            rp._t_s = 0.004 * (k + 1)
            c0 = time.process_time()
            st = rp._shape(0.004, (0.0, 0.9, 0.0))
            times.append(time.process_time() - c0)
            if name == "near" and np.hypot(st.p[0] - post[0], st.p[1] - post[1]) > 3.0 and st.p[1] > post[1]:
                break
        out[name] = 1e6 * float(np.median(times))
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(tree_runs.main(__doc__, _child, __file__, ROOT))
