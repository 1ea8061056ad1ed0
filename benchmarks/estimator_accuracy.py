"""Accuracy of the SITL's onboard estimator in flight, in-process (no MAVLink).

Usage::

    python benchmarks/estimator_accuracy.py [--mission flat-rectangle] [--profile icm42688p-bmm150-zedf9p]
                                            [--vector-sensors paper] [--cut 40] [--seed N]

The ``sitl.sim.Simulation`` of the mission starts landed under the first
way-point, climbs to it on the onboard controller (6 s ramp, 4 s hold),
then flies the planned trajectory with ``Simulation.step_onboard`` (the
cascaded controller on the estimate, setpoints refreshed at 50 Hz as the
runner streams them). Prints the tracking error (true position minus
reference, after 5 s) and the estimate's errors against the truth at every
frame of the trajectory: attitude (rotation vector of R_est^T R, body
axes), position and velocity (world ENU), RMS and max per axis.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from mavcore.mission import load_mission  # noqa: E402
from companion.planner import plan_mission  # noqa: E402
from companion.runner import setpoint_yaw_enu  # noqa: E402
from sitl.sim import Setpoint, Simulation  # noqa: E402
from sitl.world import load_world  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mission", default="flat-rectangle")
    ap.add_argument("--profile", default=None)
    ap.add_argument("--vector-sensors", default="physical", choices=("physical", "paper"))
    ap.add_argument("--cut", type=float, default=40.0, help="seconds of trajectory")
    ap.add_argument("--seed", type=int, default=None)
    a = ap.parse_args(argv)
    m = load_mission(ROOT / "missions" / a.mission / "mission.yaml")
    m = dataclasses.replace(m, sim=dataclasses.replace(m.sim, sensor_profile=a.profile,
                                                       vector_sensors=a.vector_sensors, onboard_state="estimate"))
    traj = plan_mission(m).trajectory
    rng = np.random.default_rng(m.sim.seed if a.seed is None else a.seed)
    p0 = traj.sample(np.array([traj.t0])).p[0]
    sim = Simulation(m, rng, world=load_world(m), start_enu_m=(p0[0], p0[1]))
    dt, g = sim.dt_frame_s, sim.params.plant.gravity_m_s2
    frame = sim.step_frame((0.05,) * 4)
    z0 = float(frame.truth.pos_enu_m[2])
    for k in range(int(10.0 / dt)):                       # climb and hold under the first way-point
        z = z0 + min(1.0, k * dt / 6.0) * (p0[2] - z0)
        frame = sim.step_onboard(Setpoint((p0[0], p0[1], z), (0.0, 0.0, 0.0), None, None, None))
    n = int(min(traj.tf - traj.t0, a.cut) / dt)
    smp = traj.sample(traj.t0 + dt * np.arange(n))
    track, att, pos, vel = [], [], [], []
    sp = None
    for k in range(n):
        tr, e = frame.truth, frame.estimate
        track.append(math.dist(tr.pos_enu_m, smp.p[k]))
        E = np.array(e.R).reshape(3, 3).T @ tr.R
        att.append(0.5 * np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]]))
        pos.append(np.array(e.pos_enu_m) - tr.pos_enu_m)
        vel.append(np.array(e.vel_enu_m_s) - tr.vel_enu_m_s)
        if k % 5 == 0:                                    # 50 Hz setpoints
            sp = Setpoint(tuple(smp.p[k]), tuple(smp.v[k]), tuple(smp.a[k]),
                          setpoint_yaw_enu(tuple(smp.pointing[k]), tuple(smp.a[k]), g), None)
        frame = sim.step_onboard(sp)
    track = np.array(track)[np.arange(n) * dt >= 5.0]
    print(f"{a.mission}, profile {a.profile}, vector_sensors {a.vector_sensors}, {n * dt:.0f} s")
    print(f"tracking error: max {track.max() * 1e3:.2f} mm, RMS {math.sqrt(np.mean(track ** 2)) * 1e3:.2f} mm")
    for name, x, unit in (("attitude (body x, y, z)", att, "mrad"), ("position (E, N, U)", pos, "mm"),
                          ("velocity (E, N, U)", vel, "mm/s")):
        x = np.array(x) * 1e3
        rms = np.sqrt(np.mean(x ** 2, axis=0))
        mx = np.abs(x).max(axis=0)
        print(f"estimate {name}: RMS {np.round(rms, 2).tolist()} {unit}, max {np.round(mx, 2).tolist()} {unit}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
