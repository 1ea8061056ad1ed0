"""Figures of a flown mission, in the style of the paper's Figs. 14-18
(needs the ``plot`` extra; matplotlib's object API on the Agg canvas).

From a ``companion.runner.FlightLog``:

- ``path3d.png``      3D reference and flown path (Fig. 14)
- ``position.png``    x, y, z: reference and true (Fig. 15)
- ``attitude.png``    roll, pitch, yaw (Z-Y-X of R in ENU/FLU): desired R_d and true R (Fig. 16)
- ``errors.png``      position error components and norm (Fig. 17)
- ``directions.png``  pointing direction s vs the body axis b2 = R e2, and the
                      desired thrust direction b3d vs b3 = R e3 (Fig. 18)
"""

from __future__ import annotations

import multiprocessing
import os
from pathlib import Path

import numpy as np

from .frames import rotmat2euler_zyx


def _euler_deg(R: np.ndarray) -> np.ndarray:
    out = np.full((R.shape[0], 3), np.nan)
    ok = np.all(np.isfinite(R.reshape(-1, 9)), axis=1)
    for i in np.flatnonzero(ok):
        out[i] = rotmat2euler_zyx(R[i])
    return np.degrees(np.unwrap(out, axis=0)) if ok.any() else out


def _plan_points(plan):
    """(way-points (N, 3), pointing target (3,)) of a ``Plan``, a ``FlightPlan``
    (``companion.commands.fly``) or None (a replay without a mission: neither)."""
    if plan is None:
        return None, None
    w = getattr(plan, "waypoints", None)
    wps = w.p_enu_m if w is not None else getattr(plan, "waypoints_p_enu_m", None)
    return wps, getattr(plan, "target_enu_m", None)


def write_flight_figures(log, plan, out_dir) -> list[str]:
    """Write the five figures into ``out_dir``; returns their paths.

    ``plan`` (a ``Plan``, a ``FlightPlan`` or None) only adds the way-points
    and the pointing target to the 3D path.

    Raises
    ------
    ImportError
        matplotlib is not installed.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from .runner import FlightLog, _PHASE_CODE

    a = log.array()
    out = Path(out_dir)
    if a.shape[0] == 0:
        return []
    col = {n: i for i, n in enumerate(FlightLog.COLUMNS)}
    sel = a[:, col["phase"]] >= _PHASE_CODE["takeoff"]
    a = a[sel]
    t = a[:, 0] - a[0, 0]
    ref = a[:, [col["ref_x"], col["ref_y"], col["ref_z"]]]
    tru = a[:, [col["true_x"], col["true_y"], col["true_z"]]]
    R = a[:, [col[f"R{i}{j}"] for i in range(3) for j in range(3)]].reshape(-1, 3, 3)
    Bd = a[:, [col[f"{b}_{c}"] for b in ("b1d", "b2d", "b3d") for c in "xyz"]].reshape(-1, 3, 3)
    Rd = np.transpose(Bd, (0, 2, 1))          # columns b1d, b2d, b3d
    s = a[:, [col["s_x"], col["s_y"], col["s_z"]]]
    traj = a[:, col["phase"]] == _PHASE_CODE["trajectory"]
    # Traces that are smooth at the figure's resolution are drawn from every
    # k-th sample (at most ~4000 points a line: the figures look the same and
    # take a fraction of the time); the error traces keep every sample so
    # that no peak is lost.
    k = slice(None, None, max(1, len(t) // 4000))

    def save(fig, name):
        p = out / name
        FigureCanvasAgg(fig)
        fig.savefig(p, dpi=110)

    def fig_path3d():
        fig = Figure(figsize=(8, 6))
        ax = fig.add_subplot(projection="3d")
        ax.plot(*ref[k].T, "k--", lw=1, label="reference")
        ax.plot(*tru[k].T, "C0", lw=1, label="flown")
        wps, target = _plan_points(plan)
        if wps is not None and len(wps):
            ax.scatter(*np.asarray(wps, dtype=float).T, s=8, c="C3", label="way-points")
        if target is not None:
            ax.scatter(*np.asarray(target, dtype=float), marker="*", s=60, c="C2", label="pointing target")
        ax.set_xlabel("x east [m]")
        ax.set_ylabel("y north [m]")
        ax.set_zlabel("z up [m]")
        ax.legend(loc="upper left", fontsize=8)
        ax.set_title("3D path")
        save(fig, "path3d.png")

    def fig_position():
        fig = Figure(figsize=(9, 7))
        for i, c in enumerate("xyz"):
            ax = fig.add_subplot(3, 1, i + 1)
            ax.plot(t[k], ref[k, i], "k--", lw=1, label="reference")
            ax.plot(t[k], tru[k, i], "C0", lw=1, label="true")
            ax.set_ylabel(f"{c} [m]")
            ax.grid(alpha=0.3)
        ax.set_xlabel("time since takeoff [s]")
        fig.axes[0].legend(fontsize=8)
        fig.axes[0].set_title("Position tracking")
        save(fig, "position.png")

    def fig_attitude():
        fig = Figure(figsize=(9, 7))
        eu, eud = _euler_deg(R[k]), _euler_deg(Rd[k])
        for i, name in enumerate(("roll", "pitch", "yaw")):
            ax = fig.add_subplot(3, 1, i + 1)
            ax.plot(t[k], eud[:, i], "k--", lw=1, label="desired R_d")
            ax.plot(t[k], eu[:, i], "C1", lw=1, label="true R")
            ax.set_ylabel(f"{name} [deg]")
            ax.grid(alpha=0.3)
        ax.set_xlabel("time since takeoff [s]")
        fig.axes[0].legend(fontsize=8)
        fig.axes[0].set_title("Attitude tracking (Z-Y-X angles of R, ENU/FLU)")
        save(fig, "attitude.png")

    def fig_errors():
        fig = Figure(figsize=(9, 6))
        e = tru - ref
        ax = fig.add_subplot(2, 1, 1)
        for i, c in enumerate("xyz"):
            ax.plot(t[traj], 1000 * e[traj, i], lw=1, label=f"e_{c}")
        ax.set_ylabel("error [mm]")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        ax.set_title("Position error over the trajectory")
        ax = fig.add_subplot(2, 1, 2)
        ax.plot(t[traj], 1000 * np.linalg.norm(e[traj], axis=1), "C3", lw=1)
        ax.set_ylabel("|e_x| [mm]")
        ax.set_xlabel("time since takeoff [s]")
        ax.grid(alpha=0.3)
        save(fig, "errors.png")

    def fig_directions():
        fig = Figure(figsize=(9, 7))
        b2, b3 = R[:, :, 1], R[:, :, 2]
        for i, c in enumerate("xyz"):
            ax = fig.add_subplot(3, 2, 2 * i + 1)
            ax.plot(t[k], s[k, i], "k--", lw=1, label="s (pointing)")
            ax.plot(t[k], b2[k, i], "C2", lw=1, label="b2 = R e2")
            ax.set_ylabel(c)
            ax.grid(alpha=0.3)
            ax = fig.add_subplot(3, 2, 2 * i + 2)
            ax.plot(t[k], Rd[k, i, 2], "k--", lw=1, label="b3d")
            ax.plot(t[k], b3[k, i], "C4", lw=1, label="b3 = R e3")
            ax.grid(alpha=0.3)
        fig.axes[0].set_title("Pointing direction")
        fig.axes[1].set_title("Thrust direction")
        fig.axes[0].legend(fontsize=7)
        fig.axes[1].legend(fontsize=7)
        save(fig, "directions.png")

    jobs = [fig_path3d, fig_position, fig_attitude, fig_errors, fig_directions]
    _run_parallel(jobs)
    return [str(out / f"{n}.png") for n in ("path3d", "position", "attitude", "errors", "directions")]


def _run_parallel(jobs) -> None:
    """Run the figure jobs on two cores (a forked child takes every other
    one); serially where fork is unavailable or the child fails."""
    if len(jobs) < 2 or (os.cpu_count() or 1) < 2 or "fork" not in multiprocessing.get_all_start_methods():
        for job in jobs:
            job()
        return
    child = multiprocessing.get_context("fork").Process(target=lambda: [job() for job in jobs[::2]])
    child.start()
    for job in jobs[1::2]:
        job()
    child.join()
    if child.exitcode != 0:
        for job in jobs[::2]:
            job()
