"""Unknown obstacles placed on or near the flown path (moved here from
``benchmarks/bench_obstacles_sitl.py``, which imports it).

A centre is placed by one of the placements (``spec.PlacementName``) on the flown
trajectory (cut or whole: the one the flight flies):

- ``path``, ``rows``, ``headlands``, ``entrances``: a point uniform in arc
  length over the allowed part of the path (``path``: all of it; ``rows``:
  its straight runs along the dominant direction, the corridors;
  ``headlands``: the rest; ``entrances``: the first ``entrance_m`` of each
  corridor run the vehicle turns into, ``entrance_mask``), moved up to
  ``offset_m`` across the direction of travel (``ArcSite``);
- ``row_ends``: a point within ``entrance_m`` along the run's direction,
  either side, of an end of a corridor run where the vehicle turns
  (``row_ends``), moved up to ``row_end_across_m`` across it (``EndSite``);
- ``cluster``: a point uniform in the disk of radius ``cluster_m`` about the
  previous obstacle of the flight (``DiskSite``; without one, as ``path``).

A corridor run (``corridor_runs``) is a maximal contiguous run of
``segment_mask(path, "rows")`` segments at least ``CORRIDOR_MIN_M`` long.
Every centre is at least ``keep_out_m`` from the launch point and from the
end of the flown trajectory; the footprint, grown by ``margin_m``, lies in
free cells of the map (no vine row, inside the mapped field).

Every random number comes from a ``draw(lo, hi)`` callable: ``rng.uniform``
for Monte Carlo (rejection sampling: ``random_obstacle``), or the next
coordinate of a point of the unit cube for the falsification search
(``propose_obstacle`` returns None where the point is rejected).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

#: defaults of the obstacle benchmark (issue 8)
KEEP_OUT_M = 2.5
OFFSET_M = 0.8
FOOTPRINT_MARGIN_M = 0.05
#: a straight run within this angle of the dominant direction is a row (deg)
ROW_ANGLE_TOL_DEG = 10.0
#: draws of one obstacle (s, offset, height, kind, then up to three sizes): the search's width per obstacle
DRAWS_PER_OBSTACLE = 7
#: defaults of the placements at corridor entrances, beside row ends, in clusters (m)
ENTRANCE_M = 3.0
ROW_END_ACROSS_M = 1.5
CLUSTER_M = 2.0
#: a run of row segments shorter than this is no corridor (the turns in place at the corners leave runs of mm) (m)
CORRIDOR_MIN_M = 1.0


@dataclass(frozen=True)
class Placement:
    """Ranges of one obstacle's draws (m, deg): see ``companion.campaign.spec.ObstacleSpec``."""

    kinds: tuple[str, ...] = ("cylinder", "box")
    radius_m: tuple[float, float] = (0.15, 0.4)
    side_m: tuple[float, float] = (0.3, 1.0)
    yaw_deg: tuple[float, float] = (0.0, 90.0)
    height_m: tuple[float, float] = (0.8, 4.0)
    offset_m: float = OFFSET_M
    keep_out_m: float = KEEP_OUT_M
    margin_m: float = FOOTPRINT_MARGIN_M
    names: tuple[str, ...] = ("path",)
    entrance_m: float = ENTRANCE_M
    row_end_across_m: float = ROW_END_ACROSS_M
    cluster_m: float = CLUSTER_M


def planned(mission):
    """The base mission planned (the expensive part): (OccupancyGrid, FlightPlan of the whole trajectory)."""
    from ..flight_plan import FlightPlan
    from ..planner import plan_mission

    plan = plan_mission(mission)
    return plan.grid, FlightPlan.from_plan(plan)


def sampled_path(fp, mission, cut_s: float | None, step_s: float = 0.05) -> tuple[np.ndarray, float]:
    """The flown trajectory of the plan ``fp``, cut at ``cut_s`` (None: whole), sampled every ``step_s``:
    ((N, 3) ENU m, duration s)."""
    if cut_s is not None:
        fp = fp.cut(cut_s, mission.trajectory)
    tr = fp.trajectory
    t = np.arange(float(tr.t0), float(tr.t0) + float(tr.duration_s), step_s)
    return np.asarray(tr.sample(t).p, dtype=float), float(tr.duration_s)


def flown_path(mission, cut_s: float | None, step_s: float = 0.05):
    """The base mission's plan, the flown (cut) trajectory sampled every ``step_s``.

    Returns
    -------
    grid : OccupancyGrid
    path : (N, 3) ENU m
    duration_s : float
    """
    grid, fp = planned(mission)
    path, duration_s = sampled_path(fp, mission, cut_s, step_s)
    return grid, path, duration_s


def segment_mask(path: np.ndarray, placement: str) -> np.ndarray:
    """(N-1,) bool: the path segments an obstacle may be placed on."""
    d = np.diff(path[:, :2], axis=0)
    n = len(d)
    if placement == "path":
        return np.ones(n, dtype=bool)
    length = np.hypot(d[:, 0], d[:, 1])
    ang = np.mod(np.degrees(np.arctan2(d[:, 1], d[:, 0])), 180.0)
    hist, edges = np.histogram(ang, bins=36, range=(0.0, 180.0), weights=length)
    k = int(np.argmax(hist))
    dominant = 0.5 * (edges[k] + edges[k + 1])
    diff = np.abs(np.mod(ang - dominant + 90.0, 180.0) - 90.0)
    row = (diff <= ROW_ANGLE_TOL_DEG) & (length > 1e-9)
    if placement == "rows":
        return row
    if placement == "headlands":
        return ~row & (length > 1e-9)
    raise ValueError(f"unknown placement {placement!r}")


def cumulative(path: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """(N,) arc length over the allowed segments (m); a forbidden segment adds nothing."""
    seg = np.hypot(*np.diff(path[:, :2], axis=0).T)
    if mask is not None:
        seg = np.where(mask, seg, 0.0)
    return np.concatenate([[0.0], np.cumsum(seg)])


def arc_point(path: np.ndarray, cum: np.ndarray, s: float):
    """Where arc length ``s`` (over ``cum``) falls on ``path``: (segment i, fraction f along it,
    its (dx, dy), its length), or None on a zero-length segment. The point: ``path[i, :2] + f d``."""
    i = int(min(np.searchsorted(cum, s, side="right") - 1, len(path) - 2))
    d = path[i + 1, :2] - path[i, :2]
    n = float(np.hypot(*d))
    if n < 1e-9:
        return None
    return i, (s - cum[i]) / max(cum[i + 1] - cum[i], 1e-12), d, n


def corridor_runs(path: np.ndarray) -> np.ndarray:
    """(K, 2) int: ``[first segment, last segment + 1)`` of each corridor run, in the order flown:
    a maximal contiguous run of ``segment_mask(path, "rows")`` segments, at least
    ``CORRIDOR_MIN_M`` long. Run k goes from point ``runs[k, 0]`` to point ``runs[k, 1]``."""
    row = segment_mask(path, "rows").astype(np.int8)
    edges = np.diff(np.concatenate([[0], row, [0]]))
    first, stop = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    arc = cumulative(path)
    keep = arc[stop] - arc[first] >= CORRIDOR_MIN_M
    return np.stack([first[keep], stop[keep]], axis=1)


def entrance_mask(path: np.ndarray, entrance_m: float) -> np.ndarray:
    """(N-1,) bool: the segments of each corridor run that end within ``entrance_m`` of arc
    length after the run's start, in the direction flown. A run the trajectory starts in (no
    arc flown before it) has no entrance: the vehicle took off there, it did not turn into it."""
    arc = cumulative(path)
    mask = np.zeros(len(path) - 1, dtype=bool)
    for i0, i1 in corridor_runs(path):
        if arc[i0] <= 1e-9:
            continue
        k = np.arange(i0, i1)
        mask[k] = arc[k + 1] - arc[i0] <= entrance_m
    return mask


def row_ends(path: np.ndarray) -> np.ndarray:
    """(M, 4): x, y (ENU m) and the unit direction of travel (the run's chord, start to end) of
    each end of a corridor run where the vehicle turns, in the order flown: both ends of every
    run, less the trajectory's first and last points (the launch, the end of the flight)."""
    arc = cumulative(path)
    out = []
    for i0, i1 in corridor_runs(path):
        d = path[i1, :2] - path[i0, :2]
        u = d / max(float(np.hypot(*d)), 1e-12)
        for i in (i0, i1):
            if arc[i] > 1e-9 and arc[-1] - arc[i] > 1e-9:
                out.append([path[i, 0], path[i, 1], u[0], u[1]])
    return np.asarray(out, dtype=float).reshape(-1, 4)


@dataclass(frozen=True)
class Sites:
    """The parts of one flown path the placements draw on (``placement_sites``).

    cum : {"rows", "headlands", "entrances"} -> (N,) arc length over that part's segments (m)
    ends : (M, 4) the row ends (``row_ends``)
    """

    cum: dict
    ends: np.ndarray


def placement_sites(path: np.ndarray, entrance_m: float = ENTRANCE_M) -> Sites:
    """Every placement's part of ``path`` (``path`` itself: ``cumulative(path)``)."""
    cum = {name: cumulative(path, segment_mask(path, name)) for name in ("rows", "headlands")}
    cum["entrances"] = cumulative(path, entrance_mask(path, entrance_m))
    return Sites(cum, row_ends(path))


@dataclass(frozen=True)
class ArcSite:
    """``path``, ``rows``, ``headlands``, ``entrances``: draw 0 the arc length over the allowed
    part (``cum``), draw 1 the offset across the direction of travel, up to ``offset_m``."""

    path: np.ndarray
    cum: np.ndarray
    offset_m: float

    def ranges(self):
        if self.cum[-1] <= 0.0:
            return None
        return (0.0, float(self.cum[-1])), (-self.offset_m, self.offset_m)

    def centre(self, s: float, off: float) -> np.ndarray | None:
        at = arc_point(self.path, self.cum, s)
        if at is None:
            return None
        i, f, d, n = at
        return self.path[i, :2] + f * d + off * np.array([-d[1], d[0]]) / n


@dataclass(frozen=True)
class EndSite:
    """``row_ends``: draw 0 picks the row end and the distance along its run's direction
    (the ends laid end to end, ``2 along_m`` each: ``[-along_m, along_m]`` about each),
    draw 1 the distance across it, up to ``across_m`` (left positive)."""

    ends: np.ndarray
    along_m: float
    across_m: float

    def ranges(self):
        if len(self.ends) == 0 or self.along_m <= 0.0:
            return None
        return (0.0, 2.0 * self.along_m * len(self.ends)), (-self.across_m, self.across_m)

    def centre(self, s: float, across: float) -> np.ndarray:
        j = min(int(s // (2.0 * self.along_m)), len(self.ends) - 1)
        along = s - 2.0 * self.along_m * j - self.along_m
        x, y, ux, uy = self.ends[j]
        return np.array([x + along * ux - across * uy, y + along * uy + across * ux])


@dataclass(frozen=True)
class DiskSite:
    """``cluster``: uniform in the disk of ``radius_m`` about ``(x, y)`` (the previous obstacle):
    draw 0 in [0, 1] the squared fraction of the radius, draw 1 the bearing (deg)."""

    x: float
    y: float
    radius_m: float

    def ranges(self):
        return (0.0, 1.0), (0.0, 360.0)

    def centre(self, u: float, bearing_deg: float) -> np.ndarray:
        r = self.radius_m * math.sqrt(u)
        a = math.radians(bearing_deg)
        return np.array([self.x + r * math.cos(a), self.y + r * math.sin(a)])


def pick_placement(draw: Callable[[float, float], float], names: tuple[str, ...]) -> str:
    """One of ``names``, uniformly, from one draw in [0, 1); no draw when there is one name."""
    if len(names) == 1:
        return names[0]
    return names[min(int(draw(0.0, 1.0) * len(names)), len(names) - 1)]


def obstacle_site(name: str, path: np.ndarray, cum: np.ndarray, sites: Sites | None, previous: dict | None,
                  p: Placement = Placement()):
    """Where the placement ``name`` puts an obstacle on ``path`` (``cum``: its arc length,
    the ``path`` placement's part; ``sites``: the others, None: computed here; ``previous``:
    the flight's previous obstacle, None: ``cluster`` places as ``path``)."""
    if name == "cluster" and previous is not None:
        return DiskSite(float(previous["x"]), float(previous["y"]), p.cluster_m)
    if name in ("path", "cluster"):
        return ArcSite(path, cum, p.offset_m)
    sites = sites if sites is not None else placement_sites(path, p.entrance_m)
    if name == "row_ends":
        return EndSite(sites.ends, p.entrance_m, p.row_end_across_m)
    return ArcSite(path, sites.cum[name], p.offset_m)


def _footprint_points(o: dict, margin_m: float = FOOTPRINT_MARGIN_M) -> np.ndarray:
    """Points covering the obstacle's footprint grown by ``margin_m`` (ENU x, y)."""
    g = margin_m
    if o["type"] == "cylinder":
        r = o["radius"] + g
        pts = [(0.0, 0.0)]
        for rr in np.linspace(r / 4, r, 4):
            n = max(8, int(math.ceil(2 * math.pi * rr / 0.04)))
            a = np.linspace(0, 2 * math.pi, n, endpoint=False)
            pts += list(zip(rr * np.cos(a), rr * np.sin(a)))
        pts = np.array(pts)
    else:
        hx, hy = o["size_x"] / 2 + g, o["size_y"] / 2 + g
        u = np.linspace(-hx, hx, max(2, int(math.ceil(2 * hx / 0.04)) + 1))
        v = np.linspace(-hy, hy, max(2, int(math.ceil(2 * hy / 0.04)) + 1))
        uu, vv = np.meshgrid(u, v)
        c, s = math.cos(math.radians(o["yaw_deg"])), math.sin(math.radians(o["yaw_deg"]))
        pts = np.stack([c * uu.ravel() - s * vv.ravel(), s * uu.ravel() + c * vv.ravel()], axis=1)
    return pts + (o["x"], o["y"])


def footprint_free(grid, o: dict, margin_m: float = FOOTPRINT_MARGIN_M) -> bool:
    """The grown footprint lies in free cells of the map (no row, nothing unknown, inside the map)."""
    pts = _footprint_points(o, margin_m)
    r, c = grid.world_to_cell(pts[:, 0], pts[:, 1])
    r, c = np.rint(r).astype(int), np.rint(c).astype(int)
    rows, cols = grid.shape
    if np.any((r < 0) | (r >= rows) | (c < 0) | (c >= cols)):
        return False
    return bool(np.all(grid.free[r, c]))


def propose_obstacle(draw: Callable[[float, float], float], grid, path: np.ndarray, cum: np.ndarray,
                     p: Placement = Placement(), site=None) -> dict | None:
    """One obstacle from the draws, or None where the point is rejected
    (an empty part, a zero-length segment, too near the launch or the end, footprint not free).

    ``site``: where (``obstacle_site``; default ``ArcSite(path, cum, p.offset_m)``, the
    ``path`` placement when ``cum`` is the whole arc length). Draw order
    (``DRAWS_PER_OBSTACLE`` at most): the site's two (arc length and offset; row end and
    along, across; radius and bearing), height, kind, then the radius (cylinder) or side x,
    side y, yaw (box). Values are rounded to the millimetre (0.001 deg) as written to the
    scenario file; the keep-out is measured from ``path``'s first and last points.
    """
    site = ArcSite(path, cum, p.offset_m) if site is None else site
    ranges = site.ranges()
    if ranges is None:
        return None
    start, end = path[0, :2], path[-1, :2]
    a = draw(*ranges[0])
    b = draw(*ranges[1])
    h = float(draw(*p.height_m))
    kind = p.kinds[min(int(draw(0.0, 1.0) * len(p.kinds)), len(p.kinds) - 1)]
    if kind == "cylinder":
        extra = {"radius": float(draw(*p.radius_m))}
    else:
        extra = {"size_x": float(draw(*p.side_m)), "size_y": float(draw(*p.side_m)),
                 "yaw_deg": float(draw(*p.yaw_deg))}
    q = site.centre(a, b)
    if q is None:
        return None
    o = {"type": kind, "x": float(q[0]), "y": float(q[1]), "height": h, **extra}
    o = {k: (round(v, 3) if isinstance(v, float) else v) for k, v in o.items()}
    if np.hypot(*(q - start)) < p.keep_out_m or np.hypot(*(q - end)) < p.keep_out_m:
        return None
    if not footprint_free(grid, o, p.margin_m):
        return None
    return o


def random_obstacle(rng: np.random.Generator, grid, path: np.ndarray, cum: np.ndarray,
                    p: Placement = Placement(), max_tries: int = 100_000, site=None) -> dict:
    """One obstacle, rejection-sampled with ``rng`` at ``site`` (``propose_obstacle``; ValueError
    when the site's part is empty or none fits in ``max_tries``)."""
    site = ArcSite(path, cum, p.offset_m) if site is None else site
    if site.ranges() is None:
        raise ValueError("its part of the flown path is empty")
    for _ in range(max_tries):
        o = propose_obstacle(rng.uniform, grid, path, cum, p, site)
        if o is not None:
            return o
    raise ValueError(f"no free placement found in {max_tries} tries (is the placement part of the path empty?)")


def climbable(o: dict, rc) -> bool:
    """The obstacle's top plus the clearance and the body radius is under the replan ceiling (flat field)."""
    return o["height"] + rc.clearance_m + rc.body_radius_m <= rc.ceiling_agl_m


def horizontal_distance(o: dict, x: float, y: float) -> float:
    """From (x, y) to the obstacle's footprint (m, 0 inside)."""
    dx, dy = x - o["x"], y - o["y"]
    if o["type"] == "cylinder":
        return max(math.hypot(dx, dy) - o["radius"], 0.0)
    c, s = math.cos(math.radians(o["yaw_deg"])), math.sin(math.radians(o["yaw_deg"]))
    lx, ly = c * dx + s * dy, -s * dx + c * dy
    return math.hypot(max(abs(lx) - o["size_x"] / 2, 0.0), max(abs(ly) - o["size_y"] / 2, 0.0))
