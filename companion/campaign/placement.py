"""Unknown obstacles placed on or near the flown path (moved here from
``benchmarks/bench_obstacles_sitl.py``, which imports it).

A centre is a point of the flown (cut) trajectory, uniform in arc length over
the allowed part of it (``path``: all of it; ``rows``: its straight runs
along the dominant direction, the corridors; ``headlands``: the rest), moved
up to ``offset_m`` across the direction of travel; it is at least
``keep_out_m`` from the launch point and from the end of the cut trajectory;
the footprint, grown by ``margin_m``, lies in free cells of the map (no vine
row, inside the mapped field).

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


def flown_path(mission, cut_s: float | None, step_s: float = 0.05):
    """The base mission's plan, the flown (cut) trajectory sampled every ``step_s``.

    Returns
    -------
    grid : OccupancyGrid
    path : (N, 3) ENU m
    duration_s : float
    """
    from ..flight_plan import FlightPlan
    from ..planner import plan_mission

    plan = plan_mission(mission)
    fp = FlightPlan.from_plan(plan)
    if cut_s is not None:
        fp = fp.cut(cut_s, mission.trajectory)
    tr = fp.trajectory
    t = np.arange(float(tr.t0), float(tr.t0) + float(tr.duration_s), step_s)
    return plan.grid, np.asarray(tr.sample(t).p, dtype=float), float(tr.duration_s)


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
                     p: Placement = Placement()) -> dict | None:
    """One obstacle from the draws, or None where the point is rejected
    (a zero-length segment, too near the launch or the end, footprint not free).

    Draw order (``DRAWS_PER_OBSTACLE`` at most): arc length, offset, height,
    kind, then the radius (cylinder) or side x, side y, yaw (box). Values are
    rounded to the millimetre (0.001 deg) as written to the scenario file.
    """
    if cum[-1] <= 0.0:
        return None
    start, end = path[0, :2], path[-1, :2]
    s = draw(0.0, float(cum[-1]))
    off = draw(-p.offset_m, p.offset_m)
    h = float(draw(*p.height_m))
    kind = p.kinds[min(int(draw(0.0, 1.0) * len(p.kinds)), len(p.kinds) - 1)]
    if kind == "cylinder":
        extra = {"radius": float(draw(*p.radius_m))}
    else:
        extra = {"size_x": float(draw(*p.side_m)), "size_y": float(draw(*p.side_m)),
                 "yaw_deg": float(draw(*p.yaw_deg))}
    i = int(min(np.searchsorted(cum, s, side="right") - 1, len(path) - 2))
    d = path[i + 1, :2] - path[i, :2]
    n = float(np.hypot(*d))
    if n < 1e-9:
        return None
    f = (s - cum[i]) / max(cum[i + 1] - cum[i], 1e-12)
    q = path[i, :2] + f * d + off * np.array([-d[1], d[0]]) / n
    o = {"type": kind, "x": float(q[0]), "y": float(q[1]), "height": h, **extra}
    o = {k: (round(v, 3) if isinstance(v, float) else v) for k, v in o.items()}
    if np.hypot(*(q - start)) < p.keep_out_m or np.hypot(*(q - end)) < p.keep_out_m:
        return None
    if not footprint_free(grid, o, p.margin_m):
        return None
    return o


def random_obstacle(rng: np.random.Generator, grid, path: np.ndarray, cum: np.ndarray,
                    p: Placement = Placement(), max_tries: int = 100_000) -> dict:
    """One obstacle, rejection-sampled with ``rng`` (ValueError when none fits in ``max_tries``)."""
    for _ in range(max_tries):
        o = propose_obstacle(rng.uniform, grid, path, cum, p)
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
