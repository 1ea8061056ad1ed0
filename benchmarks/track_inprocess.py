"""Track a bundled mission's planned trajectory in-process (no MAVLink).

Usage::

    python benchmarks/track_inprocess.py                       # both missions, both controllers
    python benchmarks/track_inprocess.py --mission flat-rectangle --control companion
    python benchmarks/track_inprocess.py --cut 30 --no-noise

The SITL core (``sitl.sim.Simulation``: plant, sensors with the mission's
noise, world) is stepped frame by frame at its sensor rate (250 Hz) with the
motor commands held over each frame (sample and hold). The vehicle starts in
hover at the trajectory's first point, at rest, on the desired attitude of
the first reference sample (heading of ``companion.runner.setpoint_yaw_enu``).

``--control companion``: every frame is answered by
``GeometricController.update`` with exactly what ``companion/runner.py``
gives it: ``Measurements`` from HIGHRES_IMU (float32 fields, FLU) and
LOCAL_POSITION_NED (float32, ENU, stamped with ``time_boot_ms``, sent
before the HIGHRES_IMU of the same frame), and ``Reference(p, v, a, jerk,
snap, target=None)`` (the controller's target = the plan's S_p), the
trajectory sampled at the frame's time. ``--control vehicle``: the SITL's
cascaded onboard controller (``sim.onboard`` on the true state, as the
server flies OFFBOARD) on the setpoints the runner streams: position,
velocity, acceleration and yaw (``setpoint_yaw_enu`` of the pointing)
refreshed at 50 Hz of vehicle time and held in between.

Errors: |true position - reference position| at every frame, statistics
after ``--settle`` seconds (max, RMS), as ``companion.report.tracking_stats``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for _p in (str(ROOT), str(Path(__file__).resolve().parent)):
    if _p not in sys.path:
        sys.path.insert(0, _p)

from companion.control import GeometricController, Measurements, Reference  # noqa: E402
from mavcore.mission.control import ControlConfig  # noqa: E402
from mavcore.mission import load_mission  # noqa: E402
from companion.planner import plan_mission  # noqa: E402
from companion.runner import setpoint_yaw_enu  # noqa: E402
from sensor_models import SensorModels, SensorSpec  # noqa: E402
from sitl.sim import Setpoint, Simulation  # noqa: E402
from sitl.world import load_world  # noqa: E402

MISSIONS = ("flat-rectangle", "tilted-hexagon")


def _f32(x) -> tuple:
    """A MAVLink float field round trip."""
    return tuple(float(v) for v in np.asarray(x, dtype=np.float32))


@dataclass
class TrackResult:
    """One in-process flight: per-frame time (s from the trajectory start),
    position error (m), and the figures after settling (m)."""

    t_s: np.ndarray
    err_m: np.ndarray
    max_m: float
    rms_m: float
    extra: dict


def fly(mission_path, control: str = "companion", cfg: ControlConfig | None = None, *,
        seed: int | None = None, noise: bool = True, cut_s: float | None = None,
        settle_s: float = 5.0, plan=None, mission=None, record: bool = False,
        sensors: SensorSpec | None = None, noise_overrides: dict | None = None,
        abort_m: float | None = None) -> TrackResult:
    """Fly the mission's planned trajectory in-process; see the module docstring.

    Parameters
    ----------
    mission_path : str or Path
        mission.yaml.
    control : "companion" or "vehicle"
    cfg : ControlConfig, optional
        Controller settings (default: the mission's ``control`` section).
    seed : int, optional
        Noise seed (default: the mission's ``sim.seed``).
    noise : bool
        False: the mission's sensor noise set to zero.
    cut_s : float, optional
        Fly only the first ``cut_s`` seconds of the trajectory.
    record : bool
        Keep per-frame attitude / yaw diagnostics in ``extra``.
    sensors : SensorSpec, optional
        What the companion is given instead of the SITL's own sensors
        (``sensor_models``: the paper's vectors, an IMU, a disturbed
        magnetometer, late GNSS fixes); seeded from the same seed.
    noise_overrides : dict, optional
        Fields of the mission's ``sim.noise`` to replace (e.g.
        ``velocity_std_m_s``, ``gyro_bias_rad_s``).
    abort_m : float, optional
        Stop the flight when the error exceeds this (diverged:
        ``extra["diverged"]``, the figures cover the frames flown).
    """
    import dataclasses

    mission = mission or load_mission(Path(mission_path))
    if not noise:
        sim_cfg = mission.sim
        nz = dataclasses.replace(sim_cfg.noise, vector_variance=0.0, gyro_variance=0.0)
        mission = dataclasses.replace(mission, sim=dataclasses.replace(sim_cfg, noise=nz))
    if noise_overrides:
        sim_cfg = mission.sim
        nz = dataclasses.replace(sim_cfg.noise, **noise_overrides)
        mission = dataclasses.replace(mission, sim=dataclasses.replace(sim_cfg, noise=nz))
    plan = plan or plan_mission(mission)
    traj = plan.trajectory
    target = tuple(float(x) for x in plan.target_enu_m)
    cfg = cfg or mission.control
    seed_ = mission.sim.seed if seed is None else seed
    rng = np.random.default_rng(seed_)
    sim = Simulation(mission, rng, world=load_world(mission))
    dt = sim.dt_frame_s
    models = None
    if sensors is not None:
        models = SensorModels(sensors, np.random.default_rng([seed_, 7]), sim.params.plant.gravity_m_s2,
                              mission.sim.magnetic_field_enu_gauss, dt)
    t0, tf = float(traj.t0), float(traj.tf)
    if cut_s is not None:
        tf = min(tf, t0 + cut_s)
    n = int(math.floor((tf - t0) / dt + 1e-9)) + 1
    smp = traj.sample(t0 + dt * np.arange(n))
    P, V, A, Jk, S = smp.p, smp.v, smp.a, smp.jerk, smp.snap
    s_dir = smp.pointing

    # Start: hover at the first point, at rest, on the first desired attitude.
    veh = mission.vehicle
    g = sim.params.plant.gravity_m_s2
    yaw0 = setpoint_yaw_enu(tuple(s_dir[0]), tuple(A[0]), g)
    ctrl = None
    if control == "companion":
        ctrl = GeometricController(veh, cfg, target)
        ref0 = Reference(tuple(P[0]), tuple(V[0]), tuple(A[0]), tuple(Jk[0]), tuple(S[0]))
        probe = GeometricController(veh, cfg, target).update(
            0.0, Measurements((0, 0, 0), (0, 0, g), (0, 1, 0), tuple(P[0]), tuple(V[0])), ref0)
        R0 = np.array(probe.R_d)
    else:
        c, s_ = math.cos(yaw0), math.sin(yaw0)
        R0 = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
    hover = veh.mass_kg * g / 4.0
    sim.plant.set_state(P[0], V[0], R=R0, f=(hover,) * 4, landed=False)
    sim.onboard.reset()
    gnss = getattr(sim.sensors, "gnss", None)     # a SITL with a GNSS receiver: its first fix is here
    if gnss is not None:
        gnss.reset(tuple(P[0]), tuple(V[0]))
    frame = sim.step_frame((hover / veh.max_thrust_per_rotor_n,) * 4)
    t_base_us = frame.time_us

    errs = np.empty(n)
    diag = ({"yaw_err": [], "tilt_err": [], "sat": [], "yaw": [], "att_err": [], "pos_est_err": [], "e_x": []}
            if record else None)
    sp = None
    next_sp = -1
    sp_every = int(round(1.0 / (50.0 * dt)))     # runner: setpoints at 50 Hz of vehicle time
    diverged = False
    for k in range(n):
        tr = frame.truth
        errs[k] = math.dist(tr.pos_enu_m, P[k])
        if abort_m is not None and not errs[k] < abort_m:
            diverged, n = True, k + 1
            errs = errs[:n]
            break
        t_s = frame.time_us * 1e-6
        if control == "companion":
            if models is not None:
                meas = Measurements(*models.measure(frame))
            else:
                pos, vel = _f32(frame.pos_enu_m), _f32(frame.vel_enu_m_s)
                # LOCAL_POSITION_NED's time_boot_ms: the fix's measurement time (where the SITL has one)
                t_fix_us = getattr(frame, "pos_time_us", frame.time_us)
                meas = Measurements(_f32(frame.gyro_flu_rad_s), _f32(frame.accel_flu_m_s2),
                                    _f32(frame.mag_flu_gauss), pos, vel, (t_fix_us // 1000) * 1e-3)
            ref = Reference(tuple(P[k]), tuple(V[k]), tuple(A[k]), tuple(Jk[k]), tuple(S[k]))
            out = ctrl.update(t_s, meas, ref)
            cmd = out.motor_cmd
            if record:
                Rd = np.array(out.R_d)
                R = tr.R
                diag["tilt_err"].append(math.degrees(math.acos(min(1.0, float(Rd[:, 2] @ R[:, 2])))))
                yd = math.atan2(Rd[1, 0], Rd[0, 0])
                y = math.atan2(R[1, 0], R[0, 0])
                diag["yaw_err"].append(math.degrees((y - yd + math.pi) % (2 * math.pi) - math.pi))
                diag["yaw"].append(math.degrees(yd))
                diag["sat"].append(out.saturated)
                est = ctrl.attitude_estimate()
                E = R.T @ np.array(est.R_enu_flu).reshape(3, 3)
                diag["att_err"].append(0.5 * np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]]))
                diag["pos_est_err"].append(np.array(est.pos_enu_m) - tr.pos_enu_m)
                diag["e_x"].append(np.array(out.e_x))
        else:
            if k >= next_sp:
                next_sp = k + sp_every
                sp = Setpoint(tuple(P[k]), tuple(V[k]), tuple(A[k]),
                              setpoint_yaw_enu(tuple(s_dir[k]), tuple(A[k]), g), None)
            cmd = sim.onboard.update(tr, sp, dt)
        frame = sim.step_frame(cmd)
    t = np.arange(n) * dt
    after = errs[t >= settle_s] if t[-1] >= settle_s else errs
    extra = {k: np.array(v) for k, v in diag.items()} if record else {}
    extra["t_base_us"] = t_base_us
    extra["diverged"] = diverged
    return TrackResult(t, errs, float(after.max()), float(math.sqrt(np.mean(after ** 2))), extra)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mission", choices=MISSIONS, action="append")
    ap.add_argument("--control", choices=("companion", "vehicle"), action="append")
    ap.add_argument("--cut", type=float, default=None, help="fly only the first S seconds")
    ap.add_argument("--no-noise", action="store_true")
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--spikes", action="store_true", help="list the error peaks > 2 mm")
    args = ap.parse_args(argv)
    missions = args.mission or list(MISSIONS)
    controls = args.control or ["companion", "vehicle"]
    print(f"{'mission':16s} {'controller':10s} {'max (mm)':>9s} {'rms (mm)':>9s} {'wall (s)':>8s}")
    for name in missions:
        path = ROOT / "missions" / name / "mission.yaml"
        mission = load_mission(path)
        plan = plan_mission(mission)
        for control in controls:
            w0 = time.perf_counter()
            r = fly(path, control, seed=args.seed, noise=not args.no_noise, cut_s=args.cut,
                    plan=plan if not args.no_noise else None)
            wall = time.perf_counter() - w0
            label = "geometric" if control == "companion" else "cascaded"
            print(f"{name:16s} {label:10s} {1e3 * r.max_m:9.2f} {1e3 * r.rms_m:9.3f} {wall:8.1f}")
            if args.spikes:
                big = np.flatnonzero(r.err_m > 2e-3)
                if big.size:
                    groups = np.split(big, np.flatnonzero(np.diff(big) > 25) + 1)
                    for gidx in groups:
                        i = gidx[np.argmax(r.err_m[gidx])]
                        print(f"    peak {1e3 * r.err_m[i]:8.2f} mm at t = {r.t_s[i]:6.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
