"""Figures of a flown mission, in the style of the paper's Figs. 14-18
(needs the ``plot`` extra; matplotlib's object API on the Agg canvas).

From a ``companion.runner.FlightLog``:

- ``path3d.png``      3D reference and flown path over the vine rows and the
                      obstacles (drawn on the terrain), and the same seen from
                      above, with the take-off point (Fig. 14)
- ``position.png``    x, y and the height above the ground: reference and true (Fig. 15)
- ``attitude.png``    roll, pitch (Z-Y-X of R in ENU/FLU) and the compass heading:
                      desired R_d and true R (Fig. 16)
- ``errors.png``      position error components and norm (Fig. 17)
- ``directions.png``  pointing direction s vs the body axis b2 = R e2, and the
                      desired thrust direction b3d vs b3 = R e3 (Fig. 18)

Heights are above the ground, ``z - dem(x, y)`` with the plan's DEM (z above
home only where there is no DEM, and the axis says so). Headings are compass
headings: degrees clockwise from north, ``(90 - yaw_ENU) mod 360``
(``frames.yaw_enu2ned``). Every axis is labelled.
"""

from __future__ import annotations

import multiprocessing
import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from mavcore.frames import rotmat2euler_zyx, yaw_enu2ned

FIGURE_NAMES = ("path3d", "position", "attitude", "errors", "directions")
#: Points drawn along each vine row in 3D (it follows the terrain).
ROW_SAMPLES = 24


def _euler_deg(R: np.ndarray) -> np.ndarray:
    out = np.full((R.shape[0], 3), np.nan)
    ok = np.all(np.isfinite(R.reshape(-1, 9)), axis=1)
    for i in np.flatnonzero(ok):
        out[i] = rotmat2euler_zyx(R[i])
    return np.degrees(np.unwrap(out, axis=0)) if ok.any() else out


def compass_heading_deg(yaw_enu_rad) -> np.ndarray:
    """Compass heading (deg, clockwise from north, in [0, 360)) of an ENU yaw
    (rad, counter-clockwise from east): ``(90 - yaw) mod 360``."""
    return np.degrees(yaw_enu2ned(np.asarray(yaw_enu_rad, dtype=float))) % 360.0


def _heading_deg(R: np.ndarray) -> np.ndarray:
    """Compass heading (deg) of the body x axis of each R (N, 3, 3); NaN where R is unknown."""
    R = np.asarray(R, dtype=float)
    yaw = np.arctan2(R[:, 1, 0], R[:, 0, 0])
    out = compass_heading_deg(yaw)
    out[~np.all(np.isfinite(R.reshape(-1, 9)), axis=1)] = np.nan
    return out


def _break_wraps(t: np.ndarray, deg: np.ndarray, jump: float = 180.0):
    """(t, deg) with a NaN inserted between samples that jump by more than ``jump``
    degrees (a heading crossing north), so the line is not drawn across the figure."""
    i = np.flatnonzero(np.abs(np.diff(deg)) > jump) + 1
    return np.insert(np.asarray(t, float), i, np.nan), np.insert(np.asarray(deg, float), i, np.nan)


def height_above_ground_m(p_enu_m: np.ndarray, dem) -> np.ndarray:
    """z - dem(x, y) (m) of (N, 3) ENU points; NaN where the DEM does not cover them."""
    p = np.asarray(p_enu_m, dtype=float)
    ok = np.all(np.isfinite(p), axis=1)
    ok[ok] = dem.covers(p[ok, 0], p[ok, 1])
    out = np.full(len(p), np.nan)
    if ok.any():
        out[ok] = p[ok, 2] - dem.height_at(p[ok, 0], p[ok, 1])
    return out


def _plan_points(plan):
    """(way-points (N, 3), pointing target (3,)) of a ``Plan``, a ``FlightPlan``
    (``companion.commands.fly``) or None (a replay without a mission: neither)."""
    if plan is None:
        return None, None
    w = getattr(plan, "waypoints", None)
    wps = w.p_enu_m if w is not None else getattr(plan, "waypoints_p_enu_m", None)
    return wps, getattr(plan, "target_enu_m", None)


def _scene(plan, obstacles, dem, grid):
    """What the figures draw under the path: DEM, rows (R, 2, 2), obstacle footprints."""
    from .map_layers import obstacle_layers, row_lines_xy

    dem = dem if dem is not None else getattr(plan, "dem", None)
    grid = grid if grid is not None else getattr(plan, "grid", None)
    rows = row_lines_xy(grid) if grid is not None else np.zeros((0, 2, 2))
    return SimpleNamespace(dem=dem, rows=rows, obstacles=obstacle_layers(obstacles or ()))


def _ground(dem, x, y) -> np.ndarray:
    """Terrain height (m) at x, y, NaN where the DEM does not cover them (0 without a DEM)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if dem is None:
        return np.zeros(np.broadcast(x, y).shape)
    out = np.full(np.broadcast(x, y).shape, np.nan)
    ok = dem.covers(x, y)
    if np.any(ok):
        out[ok] = dem.height_at(np.broadcast_to(x, ok.shape)[ok], np.broadcast_to(y, ok.shape)[ok])
    return out


def flight_figures(log, plan, obstacles=(), dem=None, grid=None, names=FIGURE_NAMES, scene=None) -> dict:
    """The flight figures (matplotlib ``Figure`` objects, on the Agg canvas) by name.

    Parameters
    ----------
    log : FlightLog
    plan : Plan, FlightPlan or None
        Adds the way-points and the pointing target; a ``Plan`` also gives the
        DEM (heights above ground) and the grid (the vine rows).
    obstacles : sequence of ``mission.sim.ObstacleConfig``
        Drawn under the path.
    dem, grid : ElevationModel, OccupancyGrid, optional
        Instead of the plan's.
    names : the figures to build (``FIGURE_NAMES``)
    scene : what ``_scene`` made of the three above, if already made

    Raises
    ------
    ImportError
        matplotlib is not installed.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Polygon

    from .runner import FlightLog, _PHASE_CODE

    a = log.array()
    if a.shape[0] == 0:
        return {}
    col = {n: i for i, n in enumerate(FlightLog.COLUMNS)}
    sel = a[:, col["phase"]] >= _PHASE_CODE["takeoff"]
    a = a[sel]
    if a.shape[0] == 0:
        return {}
    sc = scene if scene is not None else _scene(plan, obstacles, dem, grid)
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
    T_LABEL = "time since takeoff [s]"
    first = tru[np.all(np.isfinite(tru), axis=1)][:1]

    def new_figure(**kw):
        fig = Figure(**kw)
        FigureCanvasAgg(fig)
        return fig

    def draw_obstacles_top(ax):
        for o in sc.obstacles:
            ax.add_patch(Polygon(o.ring_xy_m, closed=True, color="C3", alpha=0.7))
            c = o.ring_xy_m.mean(axis=0)
            ax.annotate(o.label, c, xytext=(4, 4), textcoords="offset points", fontsize=7, color="C3")

    def fig_path3d():
        fig = new_figure(figsize=(13, 6), layout="constrained")
        ax = fig.add_subplot(1, 2, 1, projection="3d")
        top = fig.add_subplot(1, 2, 2)
        for i, row in enumerate(sc.rows):
            u = np.linspace(0.0, 1.0, ROW_SAMPLES)[:, None]
            pts = row[0] + u * (row[1] - row[0])
            lab = "vine rows" if i == 0 else None
            ax.plot(pts[:, 0], pts[:, 1], _ground(sc.dem, pts[:, 0], pts[:, 1]), color="tab:green", lw=1.5, label=lab)
            top.plot(row[:, 0], row[:, 1], color="tab:green", lw=1.5, label=lab)
        for i, o in enumerate(sc.obstacles):
            ring = np.vstack([o.ring_xy_m, o.ring_xy_m[:1]])
            z0 = np.nanmin(_ground(sc.dem, ring[:, 0], ring[:, 1]))
            z0 = 0.0 if not np.isfinite(z0) else z0
            lab = "obstacles" if i == 0 else None
            ax.plot(ring[:, 0], ring[:, 1], np.full(len(ring), z0), color="C3", lw=1, label=lab)
            ax.plot(ring[:, 0], ring[:, 1], np.full(len(ring), z0 + o.height_m), color="C3", lw=1)
            for x, y in o.ring_xy_m[:: max(1, len(o.ring_xy_m) // 8)]:
                ax.plot([x, x], [y, y], [z0, z0 + o.height_m], color="C3", lw=1)
        draw_obstacles_top(top)
        for axis in (ax, top):
            axis.plot(*(ref[k].T if axis is ax else ref[k, :2].T), "k--", lw=1, label="reference")
            axis.plot(*(tru[k].T if axis is ax else tru[k, :2].T), "C0", lw=1, label="flown")
        wps, target = _plan_points(plan)
        if wps is not None and len(wps):
            w = np.asarray(wps, dtype=float)
            ax.scatter(*w.T, s=8, c="C1", label="way-points")
            top.scatter(w[:, 0], w[:, 1], s=8, c="C1", label="way-points")
        if target is not None:
            ax.scatter(*np.asarray(target, dtype=float), marker="*", s=60, c="C2", label="pointing target")
        if len(first):
            ax.scatter(*first[0], marker="^", s=60, c="m", label="take-off")
            top.scatter(first[0, 0], first[0, 1], marker="^", s=60, c="m", label="take-off", zorder=5)
        ax.set_xlabel("x east [m]")
        ax.set_ylabel("y north [m]")
        ax.set_zlabel("z up [m]")
        ax.legend(loc="upper left", fontsize=8)
        ax.set_title("3D path")
        top.set_aspect("equal")
        top.set_xlabel("x east [m]")
        top.set_ylabel("y north [m]")
        top.set_title("Top view")
        top.legend(fontsize=7, loc="best")
        top.grid(alpha=0.3)
        return fig

    def fig_position():
        fig = new_figure(figsize=(9, 7), layout="constrained")
        for i, c in enumerate("xy"):
            ax = fig.add_subplot(3, 1, i + 1)
            ax.plot(t[k], ref[k, i], "k--", lw=1, label="reference")
            ax.plot(t[k], tru[k, i], "C0", lw=1, label="true")
            ax.set_ylabel(f"{c} {'east' if c == 'x' else 'north'} [m]")
            ax.set_xlabel(T_LABEL)
            ax.grid(alpha=0.3)
        ax = fig.add_subplot(3, 1, 3)
        if sc.dem is not None:
            ax.plot(t[k], height_above_ground_m(ref[k], sc.dem), "k--", lw=1, label="reference")
            ax.plot(t[k], height_above_ground_m(tru[k], sc.dem), "C0", lw=1, label="true")
            ax.set_ylabel("height above ground [m]")
        else:
            ax.plot(t[k], ref[k, 2], "k--", lw=1, label="reference")
            ax.plot(t[k], tru[k, 2], "C0", lw=1, label="true")
            ax.set_ylabel("z above home [m] (no DEM)")
        ax.set_xlabel(T_LABEL)
        ax.grid(alpha=0.3)
        fig.axes[0].legend(fontsize=8)
        fig.axes[0].set_title("Position tracking")
        return fig

    def fig_attitude():
        fig = new_figure(figsize=(9, 7), layout="constrained")
        eu, eud = _euler_deg(R[k]), _euler_deg(Rd[k])
        for i, name in enumerate(("roll", "pitch")):
            ax = fig.add_subplot(3, 1, i + 1)
            ax.plot(t[k], eud[:, i], "k--", lw=1, label="desired R_d")
            ax.plot(t[k], eu[:, i], "C1", lw=1, label="true R")
            ax.set_ylabel(f"{name} [deg]")
            ax.set_xlabel(T_LABEL)
            ax.grid(alpha=0.3)
        ax = fig.add_subplot(3, 1, 3)
        ax.plot(*_break_wraps(t[k], _heading_deg(Rd[k])), "k--", lw=1, label="desired R_d")
        ax.plot(*_break_wraps(t[k], _heading_deg(R[k])), "C1", lw=1, label="true R")
        ax.set_ylim(0, 360)
        ax.set_yticks([0, 90, 180, 270, 360])
        ax.set_ylabel("heading [deg, clockwise from north]")
        ax.set_xlabel(T_LABEL)
        ax.grid(alpha=0.3)
        fig.axes[0].legend(fontsize=8)
        fig.axes[0].set_title("Attitude tracking (roll, pitch: Z-Y-X angles of R, ENU/FLU; compass heading)")
        return fig

    def fig_errors():
        fig = new_figure(figsize=(9, 6), layout="constrained")
        e = tru - ref
        ax = fig.add_subplot(2, 1, 1)
        for i, c in enumerate("xyz"):
            ax.plot(t[traj], 1000 * e[traj, i], lw=1, label=f"e_{c}")
        ax.set_ylabel("error [mm]")
        ax.set_xlabel(T_LABEL)
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        ax.set_title("Position error over the trajectory")
        ax = fig.add_subplot(2, 1, 2)
        ax.plot(t[traj], 1000 * np.linalg.norm(e[traj], axis=1), "C3", lw=1)
        ax.set_ylabel("|e_x| [mm]")
        ax.set_xlabel(T_LABEL)
        ax.grid(alpha=0.3)
        return fig

    def fig_directions():
        fig = new_figure(figsize=(9, 7), layout="constrained")
        b2, b3 = R[:, :, 1], R[:, :, 2]
        names = {"x": "east", "y": "north", "z": "up"}
        for i, c in enumerate("xyz"):
            ax = fig.add_subplot(3, 2, 2 * i + 1)
            ax.plot(t[k], s[k, i], "k--", lw=1, label="s (pointing)")
            ax.plot(t[k], b2[k, i], "C2", lw=1, label="b2 = R e2")
            ax.set_ylabel(f"{c} ({names[c]}) component [-]")
            ax.set_xlabel(T_LABEL)
            ax.grid(alpha=0.3)
            ax = fig.add_subplot(3, 2, 2 * i + 2)
            ax.plot(t[k], Rd[k, i, 2], "k--", lw=1, label="b3d")
            ax.plot(t[k], b3[k, i], "C4", lw=1, label="b3 = R e3")
            ax.set_ylabel(f"{c} ({names[c]}) component [-]")
            ax.set_xlabel(T_LABEL)
            ax.grid(alpha=0.3)
        fig.axes[0].set_title("Pointing direction")
        fig.axes[1].set_title("Thrust direction")
        fig.axes[0].legend(fontsize=7)
        fig.axes[1].legend(fontsize=7)
        return fig

    builders = {"path3d": fig_path3d, "position": fig_position, "attitude": fig_attitude,
                "errors": fig_errors, "directions": fig_directions}
    return {n: builders[n]() for n in names}


def write_flight_figures(log, plan, out_dir, obstacles=(), dem=None, grid=None) -> list[str]:
    """Write the five figures (``flight_figures``) into ``out_dir``; returns their paths.

    Raises
    ------
    ImportError
        matplotlib is not installed.
    """
    import matplotlib  # noqa: F401  (ImportError here, not in a forked child)

    out = Path(out_dir)
    if log.array().shape[0] == 0:
        return []
    scene = _scene(plan, obstacles, dem, grid)      # once, before the fork

    def job(name):
        def run():
            figs = flight_figures(log, plan, names=(name,), scene=scene)
            if name in figs:
                figs[name].savefig(out / f"{name}.png", dpi=110)
        return run

    _run_parallel([job(n) for n in FIGURE_NAMES])
    return [str(out / f"{n}.png") for n in FIGURE_NAMES if (out / f"{n}.png").exists()]


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
        else:
            from .map_layers import row_lines_xy

            for i, row in enumerate(row_lines_xy(grid)):
                ax.plot(row[:, 0], row[:, 1], color="tab:green", lw=1.5, label="vine rows" if i == 0 else None)
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
    dem = getattr(plan, "dem", None)
    if dem is not None:
        ax.plot(t, height_above_ground_m(ref, dem), "C1", lw=1.2, label="replanned reference")
        ax.plot(t, height_above_ground_m(tru, dem), "C0", lw=0.8, label="flown (truth)")
        ax.set_ylabel("height above ground [m]")
    else:
        ax.plot(t, ref[:, 2], "C1", lw=1.2, label="replanned reference")
        ax.plot(t, tru[:, 2], "C0", lw=0.8, label="flown (truth)")
        ax.set_ylabel("z above home [m] (no DEM)")
    t0 = a[0, 0]
    for e in events or ():
        ax.axvline(e["t_s"] - t0, color="0.6", lw=0.6)
        ax.annotate(e["action"], (e["t_s"] - t0, ax.get_ylim()[1]), fontsize=6, rotation=90, va="top")
    ax.set_xlabel("time since the trajectory started [s]")
    ax.set_title("Side view: height along the flight")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    FigureCanvasAgg(fig)
    p = Path(out_dir) / "avoidance.png"
    fig.savefig(p, dpi=110)
    return str(p)
