"""Benchmark of the replanner (issue 8): the per-step cost, and kinematic
closed-loop flights over randomized obstacle placements.

Run: ``python benchmarks/bench_replan.py [--mission flat-rectangle] [--placements 0] [--seed 1]``

Per-step cost (wall time of one frame: ``on_pose``, the frame's
``on_range`` calls, ``step``; readings in, setpoint out), median / p90 / p99
over a whole flight of the mission at 250 Hz, ray cast by the SITL's
``World`` against the mission's rows and terrain (the casting itself is not
timed), with a ring of 16 horizontal rangefinders (22.5 deg wide,
MAV_SENSOR_ROTATION_CUSTOM), a ring of 16 pitched 20 deg down (22.5 deg wide),
a ring of 8 pitched 45 deg down (45 deg wide) and one looking down, each at 25 Hz (a reading: the nearest of five rays
across the field of view):

- ``clear way``: no obstacle (the replanner follows the plan);
- ``bare cursor``: the same frames evaluating only the trajectory with
  ``TrajectoryCursor`` (what following costs at the least);
- ``Trajectory.sample``: one vectorised-API call per frame;
- ``avoiding``: frames in the avoid/climb/stop modes, with a cylinder
  (r 0.25 m, 1.8 m tall) in the second corridor.

Issue 8's target: one replanning step <= 1 ms median.

``--placements N``: N flights of the same kinematic loop (the reference
flown exactly, level attitude, body y toward the pointing direction) at
50 Hz with sensors at 12.5 Hz, each with 0-3 random obstacles (cylinders
r 0.15-0.4 m and boxes 0.3-1.0 m, heights 0.8-4 m, in the corridors and
the headlands, centres at least 2.5 m from the flight's start). Per flight: the
outcome (finished / hold / timeout), the events, the true clearance of the
body (the reference's distance to the obstacles' surfaces minus the body
radius, from ``mission.vehicle``: arm + 10-inch propeller) and the statistics.
Accuracy figures only: these are deterministic for a seed.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

from mavcore import frames
from mavcore import codec
from mavcore.mission import load_mission
from mavcore.mission.sim import ObstacleConfig
from companion.planner import plan_mission
from companion.replan import GlobalPlan, KnownMap, Replanner
from companion.replan.replanner import mission_replan_config
from companion.trajectory.cursor import TrajectoryCursor
from sitl.world import World

ROOT = Path(__file__).resolve().parents[1]
N_RING = 16
RING_FOV = math.radians(360.0 / N_RING)
#: a second ring looking 20 deg down sees obstacles whose top is just below the flight height
N_LOW = 16
LOW_FOV = math.radians(360.0 / N_LOW)
LOW_PITCH_DEG = -20.0
#: and a ring of 8 pitched 45 deg down: the band between the two rings and the
#: horizontal, near and below the vehicle, is otherwise blind (a low crate met
#: while descending after a climb is seen only when it is under the vehicle)
N_STEEP = 8
STEEP_FOV = math.radians(360.0 / N_STEEP)
STEEP_PITCH_DEG = -45.0


def _custom(yaw_deg: float, pitch_deg: float) -> tuple:
    """Sensor rotation (body FLU, row-major) of a CUSTOM sensor: FRD yaw, then pitch (negative: down)."""
    R_frd = frames.euler_zyx2rotmat(0.0, math.radians(pitch_deg), math.radians(yaw_deg))
    return codec.sensor_rotation_flu(codec.MAV_SENSOR_ROTATION_CUSTOM, frames.rotmat2quat_wxyz(R_frd))


def _sensors():
    out = [(k, codec.MAV_SENSOR_ROTATION_CUSTOM, _custom(k * 360.0 / N_RING, 0.0), RING_FOV) for k in range(N_RING)]
    out += [(N_RING + k, codec.MAV_SENSOR_ROTATION_CUSTOM, _custom(k * 360.0 / N_LOW, LOW_PITCH_DEG), LOW_FOV)
            for k in range(N_LOW)]
    n = N_RING + N_LOW
    out += [(n + k, codec.MAV_SENSOR_ROTATION_CUSTOM, _custom(k * 360.0 / N_STEEP, STEEP_PITCH_DEG), STEEP_FOV)
            for k in range(N_STEEP)]
    out.append((n + N_STEEP, 25, codec.sensor_rotation_flu(25), 0.0))
    fans = []
    for _, _, R, h in out:
        S = np.array(R).reshape(3, 3)
        # five rays across the horizontal field of view (a real sensor sees all of it)
        rays = [(1.0, math.tan(f * h / 2), 0.0) for f in (0.0, 0.5, -0.5, 1.0, -1.0)] if h else [(1.0, 0.0, 0.0)]
        fans.append([tuple(S @ (np.array(r) / np.linalg.norm(r))) for r in rays])
    return out, fans


SENSORS, FANS = _sensors()


def setup(mission_name: str):
    m = load_mission(ROOT / "missions" / mission_name / "mission.yaml")
    plan = plan_mission(m)
    known = KnownMap.from_mission(m, plan.grid, plan.dem, plan.coverage.free_eroded)
    return m, plan, known, GlobalPlan.from_plan(plan, m)


def attitude(s):
    n = math.hypot(s[0], s[1])
    bx, by = s[0] / n, s[1] / n
    return ((by, bx, 0.0), (-bx, by, 0.0), (0.0, 0.0, 1.0))


def readings(world, t, p, R, due=None):
    """The readings of the sensors ``due`` (indices; all when None) at pose (p, R)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R
    out = []
    for k, ((sid, orient, Rs, h), fan) in enumerate(zip(SENSORS, FANS)):
        if due is not None and k not in due:
            continue
        best = math.inf
        for x, y, z in fan:
            best = min(best, world.raycast(p[0], p[1], p[2], r00 * x + r01 * y + r02 * z,
                                           r10 * x + r11 * y + r12 * z, r20 * x + r21 * y + r22 * z, 10.0))
        none = not best <= 10.0
        out.append(codec.Range(int(round(t * 1000)), sid, math.nan if none else best, 0.1, 10.0, orient,
                               h, 0.0, math.nan, none, Rs))
    return out


def fly(m, plan, known, gplan, obstacles, dt_s, sensor_every, t_max_s, timed=False):
    """One kinematic flight; returns (replanner, refs (n, 3), modes, per-frame seconds, per-frame modes)."""
    world = World.build(plan.grid, plan.dem, tuple(obstacles), m.replan.canopy_height_m)
    rp = Replanner(mission_replan_config(m), known, gplan)
    rp.start(0.0)
    p = tuple(gplan.trajectory.sample(0.0).p)
    s = (0.0, 1.0, 0.0)
    refs, modes, costs = [], [], []
    k, t = 0, 0.0
    while t <= t_max_s:
        R = attitude(s)
        # each sensor at 1 / sensor_every of the frames, staggered over the period as the SITL does
        due = {i for i in range(len(SENSORS)) if (k + i) % sensor_every == 0}
        rs = readings(world, t, p, R, due) if due else ()
        c0 = time.perf_counter()
        rp.on_pose(t, p, R)
        for r in rs:
            rp.on_range(t, r)
        st = rp.step(t, p, (0.0, 0.0, 0.0))
        if timed:
            costs.append(time.perf_counter() - c0)
        refs.append(st.ref.p)
        modes.append(st.mode)
        p, s = st.ref.p, st.ref.s
        if st.finished or st.hold:
            break
        k += 1
        t = k * dt_s
    return rp, np.array(refs), modes, np.array(costs)


def _pct(x, q):
    return 1e6 * float(np.percentile(x, q))


def per_step(mission_name: str) -> None:
    m, plan, known, gplan = setup(mission_name)
    dt = 0.004
    _, _, _, clear = fly(m, plan, known, gplan, (), dt, 10, 1e9, timed=True)
    cur = TrajectoryCursor(gplan.trajectory)
    times = np.arange(gplan.trajectory.t0, gplan.trajectory.tf, dt)
    bare = []
    for t in times:
        c0 = time.perf_counter()
        cur.sample(float(t))
        bare.append(time.perf_counter() - c0)
    vec = []
    for t in times[::10]:
        c0 = time.perf_counter()
        gplan.trajectory.sample(float(t))
        vec.append(time.perf_counter() - c0)
    obstacle = ObstacleConfig(type="cylinder", x=11.0, y=6.25, height=1.8, radius=0.25)
    _, _, modes, avoid = fly(m, plan, known, gplan, (obstacle,), dt, 10, 1e9, timed=True)
    busy = np.array([md in ("avoid", "climb", "stop") for md in modes])
    print(f"per-step cost, {mission_name}, {len(clear)} frames at 250 Hz, {len(SENSORS)} rangefinders at 25 Hz "
          "(microseconds: median / p90 / p99 / max)")
    for name, x in (("clear way (readings in, setpoint out)", np.array(clear)), ("bare cursor", np.array(bare)),
                    ("Trajectory.sample (scalar call)", np.array(vec)), ("avoiding (avoid/climb/stop frames)",
                                                                        avoid[busy])):
        print(f"  {name:40s} {_pct(x, 50):8.1f} {_pct(x, 90):8.1f} {_pct(x, 99):8.1f} {1e6 * x.max():9.1f}"
              f"   ({len(x)} frames)")


def random_obstacles(rng, gplan, known, n):
    """n obstacles in the corridors and headlands, their centre at least 2.5 m from the
    start (the vehicle takes off there: nothing may stand within its clearance)."""
    free = known.free
    start = gplan.trajectory.sample(0.0).p[:2]
    out = []
    path = gplan.p_enu_m[:, :2]
    while len(out) < n:
        # near the planned path (corridors and headlands), up to 0.8 m off it
        i = rng.integers(0, len(path) - 1)
        q = path[i] + rng.uniform() * (path[i + 1] - path[i]) + rng.uniform(-0.8, 0.8, 2)
        if np.hypot(*(q - start)) < 2.5 or known.cell_of(float(q[0]), float(q[1])) is None:
            continue
        if known.grid.occupied[known.cell_of(float(q[0]), float(q[1]))]:
            continue
        h = float(rng.uniform(0.8, 4.0))
        if rng.uniform() < 0.5:
            out.append(ObstacleConfig(type="cylinder", x=float(q[0]), y=float(q[1]), height=h,
                                      radius=float(rng.uniform(0.15, 0.4))))
        else:
            out.append(ObstacleConfig(type="box", x=float(q[0]), y=float(q[1]), height=h,
                                      size_x=float(rng.uniform(0.3, 1.0)), size_y=float(rng.uniform(0.3, 1.0)),
                                      yaw_deg=float(rng.uniform(0, 90))))
    del free
    return out


def true_clearance(refs: np.ndarray, obstacles, ground) -> float:
    best = math.inf
    for o in obstacles:
        base = ground(o.x, o.y)
        top = base + o.height
        d = refs[:, :2] - (o.x, o.y)
        if o.type == "cylinder":
            dh = np.maximum(np.hypot(d[:, 0], d[:, 1]) - o.radius, 0.0)
        else:
            c, s = math.cos(math.radians(o.yaw_deg)), math.sin(math.radians(o.yaw_deg))
            lx, ly = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
            dh = np.hypot(np.maximum(np.abs(lx) - o.size_x / 2, 0.0), np.maximum(np.abs(ly) - o.size_y / 2, 0.0))
        dz = np.maximum(refs[:, 2] - top, 0.0)
        best = min(best, float(np.min(np.hypot(dh, dz))))
    return best


def placements(mission_name: str, n: int, seed: int) -> None:
    m, plan, known, gplan = setup(mission_name)
    body = mission_replan_config(m).body_radius_m
    rng = np.random.default_rng(seed)
    t_max = 3.0 * gplan.trajectory.duration_s + 60.0
    rows = []
    for i in range(n):
        obs = random_obstacles(rng, gplan, known, int(rng.integers(0, 4)))
        rp, refs, modes, _ = fly(m, plan, known, gplan, obs, 0.02, 4, t_max)
        st = rp.stats
        outcome = "finished" if modes[-1] == "done" else ("hold" if modes[-1] == "hold" else "timeout")
        clear = true_clearance(refs, obs, known.ground_z) if obs else math.inf
        acts = [e.action for e in st.event_list]
        rows.append((outcome, clear, st.max_lateral_deviation_m, st.max_climb_m, st.extra_path_m, acts, obs))
        print(f"{i:3d} {len(obs)} obstacles  {outcome:8s} body clearance {clear - body:6.2f} m  "
              f"lateral {st.max_lateral_deviation_m:.2f} m"
              f"  climb {st.max_climb_m:.2f} m  extra {st.extra_path_m:6.1f} m  events {' '.join(acts)}", flush=True)
    outcomes = [r[0] for r in rows]
    clears = np.array([r[1] for r in rows if math.isfinite(r[1])])
    body_clear = clears - body
    print(f"\n{n} flights ({mission_name}, seed {seed}, body radius {body:.3f} m): "
          f"finished {outcomes.count('finished')}, hold {outcomes.count('hold')}, "
          f"timeout {outcomes.count('timeout')}; min body clearance "
          f"{body_clear.min() if len(body_clear) else float('nan'):.2f} m (centre {clears.min() if len(clears) else float('nan'):.2f} m); "
          f"below 0.5 m: {int(np.sum(body_clear < 0.5))}; max lateral {max(r[2] for r in rows):.2f} m; "
          f"max climb {max(r[3] for r in rows):.2f} m")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mission", default="flat-rectangle")
    ap.add_argument("--placements", type=int, default=0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-timing", action="store_true")
    a = ap.parse_args()
    if not a.no_timing:
        per_step(a.mission)
    if a.placements:
        placements(a.mission, a.placements, a.seed)


if __name__ == "__main__":
    main()
