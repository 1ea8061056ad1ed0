"""The guard's one window on the obstacles the vehicle knows (pure).

The guard reads obstacles only through ``obstacle_distance(points) ->
distances`` (``known_obstacle_distance``'s also takes the map whose added cells
count, ``obstacle_distance(points, known)``, for ``Guard.distances(known=...)``):
``(M, 3)`` ENU points (m) in, ``(M,)`` distances (m) from each
point to the nearest known obstacle surface out, ``inf`` where none is
known. Any map can stand behind it. This module adapts the replanner's: its
persistent ``ObstacleMap`` (``companion.replan.voxmap``: ``distance`` to the
occupied voxels' boxes, never above the true distance), or any memory of
surface points (``points()``; brute-force nearest point), and the obstacle cells a re-route added to its
``KnownMap`` (``added``: each a column over its cell's square from the ground
to its top, ``added_top``, the top of the obstacle the map holds there; of any
height where that is unknown). The 3-D route search and the route check read
the same columns (``companion.replan.route3d``): one picture of the obstacles.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

ObstacleDistance = Callable[[np.ndarray], np.ndarray]


def points_distance(points_enu_m: np.ndarray, surface_pts_enu_m: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """(M,) distance (m) from each of ``points_enu_m`` (M, 3) to the nearest of
    ``surface_pts_enu_m`` (K, 3); inf when K = 0. Brute force in chunks (K is at
    most the memory's capacity)."""
    p = np.asarray(points_enu_m, float).reshape(-1, 3)
    q = np.asarray(surface_pts_enu_m, float).reshape(-1, 3)
    if len(q) == 0:
        return np.full(len(p), np.inf)
    if len(p) * len(q) <= 4 * chunk * 64:
        d = p[:, None, :] - q[None, :, :]
        return np.sqrt(np.einsum("mki,mki->mk", d, d).min(axis=1))
    from scipy.spatial import cKDTree

    return cKDTree(q).query(p)[0]


def added_rectangles(rr: np.ndarray, cc: np.ndarray, top: np.ndarray) -> tuple:
    """The cells (rr[i], cc[i]) with tops ``top[i]`` (row-major order, as ``np.nonzero``
    gives them) as (r0, r1, c0, c1, top) rectangles of whole cells with one top: runs
    along a row, then runs of identical (c0, c1, top) on consecutive rows.

    The distance to such a rectangle, computed as ``_AddedCells`` computes a cell's, is the
    least of its cells' to the last bit: its x-gap ``max(c0 h - x, x - (c1 + 1) h, 0)`` is
    the x-gap of its nearest column (0 inside one: neighbours share their edge's float; the
    end column's own float outside), its y-gap likewise, its height gap is every cell's, and
    the rounded sum of squares grows with each. So the minimum over the rectangles is the
    minimum over the cells, bit for bit."""
    runs = []                                 # [r, c0, c1, top] along rows
    for r, c, t in zip(rr.tolist(), cc.tolist(), top.tolist()):
        if runs and runs[-1][0] == r and runs[-1][2] == c - 1 and runs[-1][3] == t:
            runs[-1][2] = c
        else:
            runs.append([r, c, c, t])
    rects, open_ = [], {}                     # open_[(c0, c1, top)]: the rectangle last extended by that run
    for r, c0, c1, t in runs:
        key = (c0, c1, t)
        i = open_.get(key)
        if i is not None and rects[i][1] == r - 1:
            rects[i][1] = r
        else:
            open_[key] = len(rects)
            rects.append([r, r, c0, c1, t])
    if not rects:
        z = np.zeros(0, int)
        return z, z, z, z, np.zeros(0)
    a = np.array([q[:4] for q in rects], dtype=int)
    return a[:, 0], a[:, 1], a[:, 2], a[:, 3], np.array([q[4] for q in rects], dtype=float)


class _AddedCells:
    """Distance to the columns over the cells of ``known.added`` (from the ground up to
    ``known.added_top``; any height where it is +inf or the map has no tops),
    recomputed when the replanner's map object changes (a re-route replaces it). The
    cells are taken as rectangles of one top (``added_rectangles``: the same numbers from
    a fraction of the boxes)."""

    def __init__(self) -> None:
        self._known = None
        self._sq = None          # (k, 4) rectangles in grid metres: x0, x1, y0, y1
        self._top = None         # (k,) their tops (m, map z)
        self._frame = None

    def distance(self, known, x, y, z=None) -> np.ndarray:
        if known is not self._known:
            self._known = known
            added = np.asarray(known.added, dtype=bool)
            rr, cc = np.nonzero(added) if added.any() else (np.zeros(0, int), np.zeros(0, int))
            g = known.grid
            h = float(g.resolution_m)
            tops = getattr(known, "added_top", None)
            top = np.full(len(rr), np.inf) if tops is None else np.asarray(tops, float)[rr, cc]
            r0, r1, c0, c1, self._top = added_rectangles(rr, cc, top)
            self._sq = np.stack([c0 * h, (c1 + 1) * h, r0 * h, (r1 + 1) * h], axis=1).astype(float)
            self._frame = (float(g.origin_xy_m[0]), float(g.origin_xy_m[1]),
                           np.cos(g.origin_yaw_rad), np.sin(g.origin_yaw_rad))
        x = np.asarray(x, float)
        if len(self._sq) == 0:
            return np.full(x.shape, np.inf)
        ox, oy, c, s = self._frame
        dx, dy = x - ox, np.asarray(y, float) - oy
        gx = (c * dx + s * dy)[:, None]
        gy = (-s * dx + c * dy)[:, None]
        sq = self._sq
        ex = np.maximum(np.maximum(sq[:, 0] - gx, gx - sq[:, 1]), 0.0)
        ey = np.maximum(np.maximum(sq[:, 2] - gy, gy - sq[:, 3]), 0.0)
        e2 = ex * ex + ey * ey
        if z is not None and np.isfinite(self._top).any():
            ez = np.maximum(np.asarray(z, float)[:, None] - self._top[None, :], 0.0)   # 0 under a top of +inf
            e2 = e2 + ez * ez
        return np.sqrt(e2.min(axis=1))


def known_obstacle_distance(memory, known_map: Callable[[], object] | None = None) -> ObstacleDistance:
    """``obstacle_distance`` over an ``ObstacleMemory`` (read at every call: the points
    it holds then) and, when ``known_map`` is given, the obstacle cells added to the
    map it returns (``lambda: replanner.known``; module doc). A call may name the map
    instead (``obstacle_distance(points, known)``: a route searched on a map it will
    be flown on, ``companion.replan.route3d``)."""
    cells = _AddedCells()
    box_distance = getattr(memory, "distance", None)

    def obstacle_distance(points_enu_m: np.ndarray, known=None) -> np.ndarray:
        p = np.asarray(points_enu_m, float).reshape(-1, 3)
        if not len(memory):
            d = np.full(len(p), np.inf)
        elif box_distance is not None:       # the persistent map: distance to its voxels' boxes
            d = np.asarray(box_distance(p), float)
        else:
            d = points_distance(p, memory.points())
        if known is None and known_map is not None:
            known = known_map()
        if known is not None:
            d = np.minimum(d, cells.distance(known, p[:, 0], p[:, 1], p[:, 2]))
        return d
    return obstacle_distance
