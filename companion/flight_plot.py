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


def write_avoidance_figure(log, plan, obstacles, events, out_dir, grid=None) -> str | None:
    """``avoidance.png`` in the style of the paper's Fig. 19: top view of the
    planned path, the reference the replanner flew and the true path, with the
    vine rows (``grid``), the obstacles (``sim.obstacles``, drawn from the
    mission: the companion did not know them) and the replanning events; below,
    the side view of the height along the flight (the climb over an obstacle).

    ``plan``: anything with a ``trajectory`` (the planned one); ``events``: the
    report's ``replanning.event_list`` dicts. Returns the path, or None when
    the log holds no trajectory phase.

    Raises
    ------
    ImportError
        matplotlib is not installed.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Polygon

    from .runner import FlightLog, _PHASE_CODE

    a = log.array()
    if a.shape[0] == 0:
        return None
    col = {n: i for i, n in enumerate(FlightLog.COLUMNS)}
    traj = a[:, col["phase"]] == _PHASE_CODE["trajectory"]
    if not traj.any():
        return None
    a = a[traj]
    t = a[:, 0] - a[0, 0]
    ref = a[:, [col["ref_x"], col["ref_y"], col["ref_z"]]]
    tru = a[:, [col["true_x"], col["true_y"], col["true_z"]]]
    tr = plan.trajectory
    planned = tr.sample(np.linspace(tr.t0, tr.tf, 2000)).p

    fig = Figure(figsize=(10, 8))
    ax = fig.add_subplot(2, 1, 1)
    if grid is not None:
        occ = np.asarray(grid.occupied, dtype=float)
        rows_, cols_ = occ.shape
        x0, y0 = grid.origin_xy_m[0], grid.origin_xy_m[1]
        h = grid.resolution_m
        if abs(getattr(grid, "origin_yaw_rad", 0.0)) < 1e-12:
            ax.imshow(occ, origin="lower", cmap="Greens", alpha=0.5, vmin=0, vmax=1.5,
                      extent=(x0, x0 + cols_ * h, y0, y0 + rows_ * h))
    ax.plot(planned[:, 0], planned[:, 1], "k--", lw=0.8, label="planned path")
    ax.plot(ref[:, 0], ref[:, 1], "C1", lw=1.2, label="replanned reference")
    ax.plot(tru[:, 0], tru[:, 1], "C0", lw=0.8, label="flown (truth)")
    for k, ob in enumerate(obstacles or ()):
        if ob.type == "cylinder":
            ax.add_patch(Circle((ob.x, ob.y), ob.radius, color="C3", alpha=0.8))
        else:
            c, s = np.cos(np.radians(ob.yaw_deg)), np.sin(np.radians(ob.yaw_deg))
            hx, hy = 0.5 * ob.size_x, 0.5 * ob.size_y
            corners = [(ob.x + c * u - s * v, ob.y + s * u + c * v) for u, v in
                       ((hx, hy), (-hx, hy), (-hx, -hy), (hx, -hy))]
            ax.add_patch(Polygon(corners, closed=True, color="C3", alpha=0.8))
        ax.annotate(f"#{k + 1} {ob.height:g} m", (ob.x, ob.y), xytext=(4, 4), textcoords="offset points",
                    fontsize=7, color="C3")
    marks = {"avoid": "o", "climb": "^", "stop": "s", "reroute": "D", "rejoin": "v", "hold": "X"}
    seen = set()
    for e in events or ():
        m = marks.get(e["action"], "o")
        lab = e["action"] if e["action"] not in seen else None
        seen.add(e["action"])
        ax.scatter(e["pos_enu_m"][0], e["pos_enu_m"][1], marker=m, s=30, c="k", zorder=5, label=lab)
    ax.set_aspect("equal")
    ax.set_xlabel("x east [m]")
    ax.set_ylabel("y north [m]")
    ax.set_title("Obstacle avoidance: top view (obstacles unknown to the plan)")
    ax.legend(fontsize=7, loc="upper right", ncol=2)
    ax = fig.add_subplot(2, 1, 2)
    ax.plot(t, ref[:, 2], "C1", lw=1.2, label="replanned reference")
    ax.plot(t, tru[:, 2], "C0", lw=0.8, label="flown (truth)")
    t0 = a[0, 0]
    for e in events or ():
        ax.axvline(e["t_s"] - t0, color="0.6", lw=0.6)
        ax.annotate(e["action"], (e["t_s"] - t0, ax.get_ylim()[1]), fontsize=6, rotation=90, va="top")
    ax.set_xlabel("time since the trajectory started [s]")
    ax.set_ylabel("z up [m]")
    ax.set_title("Side view: height along the flight")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    FigureCanvasAgg(fig)
    p = Path(out_dir) / "avoidance.png"
    fig.savefig(p, dpi=110)
    return str(p)
