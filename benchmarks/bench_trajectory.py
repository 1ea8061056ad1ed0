"""Benchmark of the LQR trajectory (issue 2, item 9).

Run: ``python benchmarks/bench_trajectory.py [--repeat 15]``

Prints median (and best) wall times for
- generation with 100 and 1000 way-points (default weights, boustrophedon
  way-points 4 m / 4 s apart, corners at rest, 2.5 m row spacing),
- sampling the 1000-way-point trajectory at 100 Hz (p, v, a, jerk, snap),
- a naive baseline on the 100-way-point case: fixed-step (5 ms) explicit
  Euler sweep of the paper's Riccati/eta equations (8)-(9) backward and of
  the state (10) forward, in numpy, per axis; with its error against the
  exact solution and the speed ratio. (At 10 ms the Euler sweep diverges
  with the default S: P jumps by 2 S at every way-point and the sweep's
  stiffness grows with it; its error shrinks only linearly with the step.)
Targets (issue 2): 1000 way-points generated in <= 20 ms, sampled at
100 Hz in <= 100 ms.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from companion.trajectory import generate_trajectory
from mavcore.mission.trajectory import TrajectoryConfig


def boustrophedon(n_points: int, row_length_m: float = 160.0, spacing_m: float = 2.5,
                  speed_m_s: float = 1.0, interval_s: float = 4.0, height_m: float = 1.5):
    """First ``n_points`` way-points of a vineyard sweep (rows along x, corners at rest)."""
    times, pos, vel = [], [], []
    t = 0.0
    r = 0
    while len(times) < n_points:
        xs = np.append(np.arange(0.0, row_length_m, speed_m_s * interval_s), row_length_m)
        direction = 1.0
        if r % 2:
            xs, direction = row_length_m - xs, -1.0
        for k, x in enumerate(xs):
            p = np.array([x, r * spacing_m, height_m])
            if pos:
                t += np.linalg.norm(p - pos[-1]) / speed_m_s
            times.append(t)
            pos.append(p)
            corner = k in (0, len(xs) - 1)
            vel.append(np.zeros(3) if corner else np.array([direction * speed_m_s, 0.0, 0.0]))
        r += 1
    return np.array(times[:n_points]), np.array(pos[:n_points]), np.array(vel[:n_points])


def euler_baseline(times, pos, vel, cfg: TrajectoryConfig, step_s: float = 0.005):
    """Fixed-step Euler sweep of eqs. (8)-(11), the straightforward way (per axis in one go).

    Returns the sample times and positions (n, 3) of the forward pass.
    """
    A = np.diag(np.ones(3), 1)
    B = np.array([0.0, 0.0, 0.0, 1.0])
    Q = np.diag(cfg.q_diag)
    CtSC = np.diag([*cfg.s_diag, 0.0])
    y = np.zeros((len(times), 4, 3))
    y[:, 0], y[:, 1] = pos, vel
    CtSy = np.einsum("ij,njd->nid", CtSC, y)
    grid = np.arange(times[0], times[-1] + 0.5 * step_s, step_s)
    wp_step = np.rint((times - times[0]) / step_s).astype(int)
    is_wp = np.full(grid.size, -1)
    is_wp[wp_step] = np.arange(len(times))
    Ps = np.empty((grid.size, 4, 4))
    etas = np.empty((grid.size, 4, 3))
    P = 2 * CtSC
    eta = -2 * CtSy[-1]
    for k in range(grid.size - 1, -1, -1):
        if k < grid.size - 1 and is_wp[k] > 0:
            P = P + 2 * CtSC
            eta = eta - 2 * CtSy[is_wp[k]]
        Ps[k], etas[k] = P, eta
        PB = P @ B
        dP = -(P @ A + A.T @ P + Q - np.outer(PB, PB) / cfg.r_snap)
        deta = -(A - np.outer(B, PB) / cfg.r_snap).T @ eta
        P = P - step_s * dP
        eta = eta - step_s * deta
    x = np.zeros((4, 3))
    x[0] = pos[0]
    out = np.empty((grid.size, 3))
    for k in range(grid.size):
        out[k] = x[0]
        u = -(B @ (Ps[k] @ x + etas[k])) / cfg.r_snap
        x = x + step_s * (A @ x + np.outer(B, u))
    return grid, out


def timed(fn, repeat: int):
    samples = []
    result = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        samples.append(time.perf_counter() - t0)
    return float(np.median(samples)), float(np.min(samples)), result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=15)
    args = parser.parse_args()
    cfg = TrajectoryConfig()
    print(f"weights: {cfg}")
    generate_trajectory(*boustrophedon(10), config=cfg)          # warm the expm cache / imports

    for n in (100, 1000):
        t, p, v = boustrophedon(n)
        med, best, traj = timed(lambda: generate_trajectory(t, p, v, config=cfg), args.repeat)
        print(f"generate {n:5d} way-points ({traj.duration_s:7.1f} s): median {med * 1e3:7.2f} ms"
              f"  best {best * 1e3:7.2f} ms   max way-point residual "
              f"{traj.waypoint_residual_m.max() * 100:.2f} cm")
        ts = np.arange(traj.t0, traj.tf, 0.01)
        med, best, _ = timed(lambda: traj.sample(ts), max(3, args.repeat // 3))
        print(f"sample   {n:5d} way-points at 100 Hz ({ts.size} samples): median {med * 1e3:7.2f} ms"
              f"  best {best * 1e3:7.2f} ms")

    # baseline on the 100-way-point case: generation + 100 Hz samples
    t, p, v = boustrophedon(100)

    def exact():
        traj = generate_trajectory(t, p, v, config=cfg)
        return traj.sample(np.arange(traj.t0, traj.tf + 0.005, 0.01))

    med_exact, _, smp = timed(exact, args.repeat)
    med_euler, _, (grid, p_euler) = timed(lambda: euler_baseline(t, p, v, cfg), 1)
    err = np.max(np.linalg.norm(p_euler - generate_trajectory(t, p, v, config=cfg).sample(grid).p, axis=1))
    print(f"baseline (100 way-points, Euler 5 ms sweep + forward): {med_euler * 1e3:8.1f} ms, "
          f"max position error vs exact {err:.3g} m")
    print(f"exact (100 way-points, generate + sample 100 Hz):      {med_exact * 1e3:8.2f} ms, "
          f"speed-up x{med_euler / med_exact:.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
