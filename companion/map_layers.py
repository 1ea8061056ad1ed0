"""What the maps draw: the layers of a plan or a flight, ENU metres (pure).

A :class:`MapLayers` is the one input of the map exports (GeoJSON/KML,
``companion.geo_export``) and of the HTML map (``companion.html_map``); it is
built from the in-memory plan (``plan_layers``) and, for a flight, given the
flown track and the obstacles (``with_flight``). Everything is in the mission's
ENU map frame about ``home``; the conversion to latitude/longitude happens in
the exports, at one boundary.

Rows
    The vine rows are the rows the coverage planner itself finds in the
    occupancy grid (``coverage.rows.detect_rows``): each a centre line from
    the first to the last occupied point along it, taken from the grid frame
    G to ENU (``coverage.freespace.grid_to_world``).
Obstacles
    The mission's ``sim.obstacles`` (unknown to the plan): each footprint as a
    polygon (a cylinder as a 32-gon), with its height.
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass, field, replace

import numpy as np

#: Sortie colours (hex sRGB), shared by plan.png and the HTML map; none of them is
#: a colour of another layer (``LAYER_COLOURS``), and none is blue like the flown
#: track. Beyond ten, further hues are spread by the golden angle.
SORTIE_COLOURS = ("#9467bd", "#8c564b", "#008080", "#bcbd22", "#e377c2", "#7f7f7f",
                  "#4b0082", "#556b2f", "#a0522d", "#2f4f4f")
#: Sorties named one by one in a legend; the rest get one entry together.
LEGEND_SORTIES = 12
#: Colours of the other layers (hex sRGB): the route (a wide band under the sorties),
#: the vine rows, the fence, the launch point, the flown track, the obstacles.
LAYER_COLOURS = {"path": "#ffb000", "rows": "#2ca02c", "fence": "#000000", "launch": "#ff00ff",
                 "flown": "#0077ff", "obstacles": "#d62728"}
#: Vertices of a cylinder's footprint polygon.
CYLINDER_VERTICES = 32


def sortie_legend(indices) -> list[tuple[int, str]]:
    """Legend entries of the sorties: ``(index, label)``; all of them up to
    ``LEGEND_SORTIES``, else the first ``LEGEND_SORTIES - 1`` and one entry
    (index 0) for the rest."""
    idx = list(indices)
    if len(idx) <= LEGEND_SORTIES:
        return [(i, f"sortie {i}") for i in idx]
    k = LEGEND_SORTIES - 1
    return [(i, f"sortie {i}") for i in idx[:k]] + [(0, f"sorties {idx[k]}-{idx[-1]} (a colour each)")]


def sortie_colour(index: int) -> str:
    """Hex colour of the sortie with 1-based ``index``: distinct for every index."""
    i = index - 1
    if i < len(SORTIE_COLOURS):
        return SORTIE_COLOURS[i]
    h = 0.83 * ((0.1 + 0.618033988749895 * (i - len(SORTIE_COLOURS))) % 1.0)
    h = h + 0.17 if h >= 0.53 else h          # no blue (hues 0.53..0.70): that is the flown track's
    r, g, b = colorsys.hsv_to_rgb(h, 0.85, 0.55 + 0.3 * ((i // 7) % 2))
    return "#{:02x}{:02x}{:02x}".format(round(255 * r), round(255 * g), round(255 * b))


@dataclass(frozen=True, eq=False)
class SortieLayer:
    """One sortie: its way-points (ENU m, (K, 3)), energy (Wh) and duration (s)."""

    index: int
    p_enu_m: np.ndarray
    energy_wh: float
    duration_s: float


@dataclass(frozen=True, eq=False)
class ObstacleLayer:
    """An obstacle's footprint (ENU m, (k, 2), counter-clockwise, not closed) and height (m)."""

    ring_xy_m: np.ndarray
    height_m: float
    label: str


@dataclass(frozen=True, eq=False)
class MapLayers:
    """The layers of a map, ENU metres about ``home``.

    Attributes
    ----------
    name : str
    home : (lat_deg, lon_deg, alt_m)
        The map frame's origin (the mission home; ``alt_m`` AMSL).
    path_enu_m : (N, 3)
        The whole route's way-points.
    sorties : tuple of SortieLayer
    launch_enu_m : (3,) or None
        The launch point on the ground (z = the terrain there).
    fence_xy_m : (K, 2)
        The inclusion fence, counter-clockwise, not closed ((0, 2): none).
    rows_xy_m : (R, 2, 2)
        Vine-row centre lines (start, end).
    obstacles : tuple of ObstacleLayer
    flown_enu_m : (M, 3) or None
        The flown (true) track of a flight.
    """

    name: str
    home: tuple[float, float, float]
    path_enu_m: np.ndarray
    sorties: tuple = ()
    launch_enu_m: np.ndarray | None = None
    fence_xy_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    rows_xy_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    obstacles: tuple = ()
    flown_enu_m: np.ndarray | None = None

    def all_xy_m(self) -> np.ndarray:
        """(P, 2) every drawn point (for the map's extent)."""
        parts = [np.asarray(self.path_enu_m, float)[:, :2], np.asarray(self.fence_xy_m, float).reshape(-1, 2),
                 np.asarray(self.rows_xy_m, float).reshape(-1, 2)]
        parts += [np.asarray(s.p_enu_m, float)[:, :2] for s in self.sorties]
        parts += [np.asarray(o.ring_xy_m, float) for o in self.obstacles]
        if self.launch_enu_m is not None:
            parts.append(np.asarray(self.launch_enu_m, float)[None, :2])
        if self.flown_enu_m is not None:
            f = np.asarray(self.flown_enu_m, float)[:, :2]
            parts.append(f[np.all(np.isfinite(f), axis=1)])
        return np.vstack(parts)


def row_lines_xy(grid) -> np.ndarray:
    """(R, 2, 2) ENU centre lines of the vine rows of ``grid`` (module doc); (0, 2, 2) if none."""
    from .coverage.freespace import grid_to_world
    from .coverage.rows import detect_rows

    rows = detect_rows(grid)
    if rows is None or len(rows.offsets_m) == 0:
        return np.zeros((0, 2, 2))
    a = rows.angle_g_rad
    u = np.array([np.cos(a), np.sin(a)])
    n = np.array([-np.sin(a), np.cos(a)])
    d = np.asarray(rows.offsets_m, float)[:, None, None]
    t = np.asarray(rows.spans_m, float)[:, :, None]
    return grid_to_world(grid, t * u + d * n)


def obstacle_ring_xy(ob) -> np.ndarray:
    """(k, 2) counter-clockwise footprint (ENU m) of a ``mission.sim.ObstacleConfig``."""
    if ob.type == "cylinder":
        th = 2 * np.pi * np.arange(CYLINDER_VERTICES) / CYLINDER_VERTICES
        return np.column_stack([ob.x + ob.radius * np.cos(th), ob.y + ob.radius * np.sin(th)])
    c, s = np.cos(np.radians(ob.yaw_deg)), np.sin(np.radians(ob.yaw_deg))
    hx, hy = 0.5 * ob.size_x, 0.5 * ob.size_y
    uv = np.array([(hx, -hy), (hx, hy), (-hx, hy), (-hx, -hy)])
    return np.column_stack([ob.x + c * uv[:, 0] - s * uv[:, 1], ob.y + s * uv[:, 0] + c * uv[:, 1]])


def obstacle_layers(obstacles) -> tuple:
    """``ObstacleLayer`` of each ``mission.sim.ObstacleConfig``."""
    return tuple(ObstacleLayer(obstacle_ring_xy(ob), float(ob.height), f"#{k + 1} {ob.type} {ob.height:g} m")
                 for k, ob in enumerate(obstacles))


def plan_layers(plan, mission, fence_xy_m: np.ndarray | None = None) -> MapLayers:
    """The layers of an in-memory plan (``companion.planner.Plan``) of ``mission``.

    The fence is the exports' (``plan_io.field_fence``; ``fence_xy_m`` when the
    caller has it already), the rows those of ``row_lines_xy``; the mission's
    ``sim.obstacles`` are not part of a plan.
    """
    from .plan_io import field_fence

    h = mission.home
    sp = plan.sorties
    sorties, launch = (), None
    if sp is not None:
        sorties = tuple(SortieLayer(int(s.index), np.asarray(s.waypoints.p_enu_m, float),
                                    float(s.energy.energy_wh), float(s.energy.duration_s)) for s in sp.sorties)
        lx, ly = (float(c) for c in sp.launch_xy_m)
        lz = float(plan.dem.height_at(lx, ly)) if bool(plan.dem.covers(lx, ly)) else 0.0
        launch = np.array([lx, ly, lz])
    return MapLayers(name=mission.name, home=(float(h.lat), float(h.lon), float(h.alt_m)),
                     path_enu_m=np.asarray(plan.waypoints.p_enu_m, float), sorties=sorties, launch_enu_m=launch,
                     fence_xy_m=np.asarray(field_fence(plan, mission) if fence_xy_m is None else fence_xy_m,
                                           float).reshape(-1, 2),
                     rows_xy_m=row_lines_xy(plan.grid))


def with_flight(layers: MapLayers, flown_enu_m: np.ndarray, obstacles=()) -> MapLayers:
    """``layers`` plus a flown track ((M, 3) ENU m) and the obstacles (``ObstacleConfig``)."""
    return replace(layers, flown_enu_m=np.asarray(flown_enu_m, float).reshape(-1, 3),
                   obstacles=obstacle_layers(obstacles))


def flown_track(log) -> np.ndarray:
    """(M, 3) true positions (ENU m) of a ``FlightLog`` from take-off on, NaN rows dropped."""
    from .runner import FlightLog, _PHASE_CODE

    a = log.array()
    col = {n: i for i, n in enumerate(FlightLog.COLUMNS)}
    if a.shape[0] == 0:
        return np.zeros((0, 3))
    a = a[a[:, col["phase"]] >= _PHASE_CODE["takeoff"]]
    p = a[:, [col["true_x"], col["true_y"], col["true_z"]]]
    return p[np.all(np.isfinite(p), axis=1)]
