"""Figure of a plan (needs the ``plot`` extra, matplotlib; Agg backend, no display).

Left: top view (ENU map frame) of the occupancy grid (vines black, free
white, unknown grey), the eroded free space (light green), the sorties (a
wide band each, in its own colour: ``map_layers.sortie_colour``), the
coverage path, the way-points (corners as squares; up to ``MAX_MARKERS`` of
them), the LQR trajectory, the pointing target and the sorties' launch point;
the title gives the lines' direction as a compass bearing (degrees clockwise
from north, in [0, 180): ``(90 - orientation_deg) mod 180``). Right: altitude of the
trajectory and of the terrain under it against time.
"""

from __future__ import annotations

import io

import numpy as np

from mavcore.errors import InputError

#: Largest image side drawn; bigger grids are strided (display only).
MAX_IMAGE_PX = 1500
#: Most way-points drawn as markers on the map (the title gives their number).
MAX_MARKERS = 2000


def require_matplotlib(option: str = "--plot"):
    """Import matplotlib's object API or raise a one-line InputError."""
    try:
        # The object API with the Agg canvas: no pyplot global state, no display.
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise InputError(option, "needs matplotlib: install the plot extra (pip install 'vineyard-gnc[plot]')") from None
    return Figure, FigureCanvasAgg


def supported_formats() -> set[str]:
    Figure, FigureCanvasAgg = require_matplotlib()
    return set(FigureCanvasAgg(Figure()).get_supported_filetypes())


def _map_image(grid, free_eroded):
    """RGB image (row 0 south) of the grid, strided to at most MAX_IMAGE_PX per side."""
    step = max(1, int(np.ceil(max(grid.shape) / MAX_IMAGE_PX)))
    sl = (slice(None, None, step), slice(None, None, step))
    free = grid.free[sl]
    img = np.full(free.shape + (3,), 0.6)
    img[free] = 1.0
    if free_eroded is not None and np.shape(free_eroded) == grid.shape:
        img[np.asarray(free_eroded, dtype=bool)[sl]] = (0.85, 0.95, 0.85)
    img[grid.occupied[sl]] = 0.0
    return img, step


def render_plan(plan, fmt: str = "png", title: str = "", sample_hz: float = 10.0) -> bytes:
    """Render ``plan`` (companion.planner.Plan) to image bytes in format ``fmt``.

    Pure apart from matplotlib: nothing is written to disk.
    """
    buf = io.BytesIO()
    plan_figure(plan, title, sample_hz).savefig(buf, format=fmt, dpi=110)
    return buf.getvalue()


def plan_figure(plan, title: str = "", sample_hz: float = 10.0):
    """The figure of ``plan`` (module doc): a matplotlib ``Figure`` on the Agg canvas."""
    from .map_layers import sortie_colour, sortie_legend

    Figure, FigureCanvasAgg = require_matplotlib()
    grid = plan.grid
    fig = Figure(figsize=(13, 6), layout="constrained")
    FigureCanvasAgg(fig)
    ax, axz = fig.subplots(1, 2, width_ratios=[2.2, 1])

    img, step = _map_image(grid, getattr(plan.coverage, "free_eroded", None))
    r = grid.resolution_m
    h, w = grid.shape
    if grid.origin_yaw_rad == 0.0:
        x0, y0 = grid.origin_xy_m
        hh, ww = img.shape[0] * step * r, img.shape[1] * step * r
        ax.imshow(img, origin="lower", extent=(x0, x0 + ww, y0, y0 + hh), interpolation="nearest")
    else:
        rows = np.arange(0, h + 1, step)
        cols = np.arange(0, w + 1, step)
        C, R = np.meshgrid(cols - 0.5, rows - 0.5)
        X, Y = grid.cell_to_world(R, C)
        ax.pcolormesh(X, Y, img[: len(rows) - 1, : len(cols) - 1], shading="flat")

    # A big plan's lanes are a pixel apart: thin lines, so the sorties' colours show.
    dense = len(plan.waypoints.t_s) > MAX_MARKERS
    sp = plan.sorties
    sorties = sp.sorties if sp is not None else ()
    named = {i for i, _ in sortie_legend([so.index for so in sorties]) if i}
    rest = [lab for i, lab in sortie_legend([so.index for so in sorties]) if not i]
    for so in sorties:
        sw = np.asarray(so.waypoints.p_enu_m)
        if so.index in named:
            label = f"sortie {so.index}: {so.energy.energy_wh:.0f} Wh, {so.energy.duration_s / 60:.1f} min"
        else:
            label, rest = (rest[0], []) if rest else (None, [])
        ax.plot(sw[:, 0], sw[:, 1], "-", color=sortie_colour(so.index), lw=1.0 if dense else 5,
                alpha=1.0 if dense else 0.55, solid_capstyle="round",
                label=label)
    path = np.asarray(plan.coverage.path_xy_m)
    ax.plot(path[:, 0], path[:, 1], "-", color="tab:blue", lw=0.2 if dense else 1.0, label="coverage path")
    traj = plan.trajectory
    n = max(2, int(traj.duration_s * sample_hz) + 1)
    t = np.linspace(traj.t0, traj.tf, n)
    s = traj.sample(t)
    ax.plot(s.p[:, 0], s.p[:, 1], "-", color="tab:red", lw=0.2 if dense else 1.2, label="LQR trajectory")
    wp = np.asarray(plan.waypoints.p_enu_m)
    corner = np.asarray(plan.waypoints.corner, dtype=bool)
    if len(wp) <= MAX_MARKERS:     # more would hide the sorties and the path under them
        ax.plot(wp[~corner, 0], wp[~corner, 1], "o", ms=3.5, color="tab:orange", label="way-points")
        ax.plot(wp[corner, 0], wp[corner, 1], "s", ms=5, mfc="none", color="tab:purple", label="corners")
    tgt = plan.target_enu_m
    ax.plot(tgt[0], tgt[1], "*", ms=12, color="gold", mec="k", label="pointing target")
    if sp is not None:
        ax.plot(sp.launch_xy_m[0], sp.launch_xy_m[1], "^", ms=11, color="magenta", mec="k", zorder=6,
                label="launch point")
    ax.set_aspect("equal")
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=4, fontsize=8, frameon=False)
    st = plan.stats
    ax.set_title((f"{title}: " if title else "") + (f"{len(wp)} way-points, path {st.path_length_m:.1f} m, "
                           f"{st.duration_s:.1f} s, coverage {100 * st.coverage_fraction:.1f} %, "
                           f"lines at compass bearing {(90.0 - st.orientation_deg) % 180.0:.1f} deg"), fontsize=10)

    covered = plan.dem.covers(s.p[:, 0], s.p[:, 1])
    ground = np.full(len(t), np.nan)
    if covered.any():
        ground[covered] = plan.dem.height_at(s.p[covered, 0], s.p[covered, 1])
    axz.plot(t, s.p[:, 2], color="tab:red", label="trajectory z")
    axz.plot(t, ground, color="tab:brown", label="terrain under it")
    if len(wp) <= MAX_MARKERS:
        axz.plot(plan.waypoints.t_s, wp[:, 2], "o", ms=3, color="tab:orange", label="way-points")
    axz.set_xlabel("t (s)")
    axz.set_ylabel("z up (m)")
    axz.legend(fontsize=8, loc="upper right")
    axz.grid(alpha=0.3)
    return fig
