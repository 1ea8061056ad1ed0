"""Routes through the free space in 3-D (ENU, m): under the ceiling, over obstacles
that can be climbed, round those that cannot, keeping the clearance from the
airframe's surface.

The space is a lattice of nodes ``step_m`` apart (axis-aligned ENU) over a
window round the start and the goals. A node is *blocked* when it lies

- in a row: over an occupied map cell, at or below terrain + canopy height;
- over a map cell that is not free (unknown, or off the map): at any height;
- in an obstacle column: horizontally inside an occupied voxel of the
  ``ObstacleMap`` and at or below that voxel's top (obstacles stand on the
  ground: the beams may have seen a top edge and not the sides below it);
- in a column a re-route added to the map (``KnownMap.added``, up to its
  ``added_top``): the blocking obstacle and its assumed depth, as the guard
  reads it (``companion.safety.obstacles``).

A node is *free* when it lies between terrain + ``floor_agl_m`` and terrain +
``ceiling_agl_m`` and every blocked node is at least ``keep_m + step_m / 2``
away (``keep_m`` = airframe radius + clearance, from the vehicle's centre;
the half step: a blocked node stands for the lattice cell round it). Moves
join free nodes to their 6 axis neighbours and 4 horizontal diagonals.

With the scene's ``guard`` (the one every reference passes), a free node also
keeps the guard's own distance to the rows and the obstacles (``Guard.distances``
on the scene's map), raised so that every move between two free nodes keeps it
too (``edge_keep_m``): the blocked nodes sample the rows' boxes and the
obstacle columns at the lattice step, so a node they leave free can lie inside
the clearance the guard measures to the surfaces themselves (mix flights 137
and 168: a route 5 cm inside a row's clearance, refused whole, and the vehicle
held although the independent check found routes). The search's free space
is then inside the guard's, by construction.

``find_route`` searches it (``scipy.ndimage.distance_transform_edt`` for the
clearance, ``scipy.sparse.csgraph.dijkstra`` for the path).
``companion.replan.routecheck.route_exists`` answers the same question by
other means (a k-d tree and a plain breadth-first search): "no route" is
declared only when it agrees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from .knownmap import KnownMap
from .voxmap import ObstacleMap

#: Window margin (m) round the start and the goals.
WINDOW_MARGIN_M = 3.0
#: Moves: the 6 axis neighbours and the 4 horizontal diagonals (half of each pair).
MOVES = ((1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, -1, 0))
#: A start inside the clearance (a vehicle stopped within it) joins the nearest free node within this (m).
START_SNAP_M = 1.5


@dataclass(frozen=True)
class RouteScene:
    """What a 3-D route is searched in.

    Attributes
    ----------
    known : KnownMap
        Rows, terrain and map cells.
    obstacles : ObstacleMap
    keep_m : float
        Distance the vehicle's centre keeps from everything blocked (airframe radius + clearance, m).
    floor_agl_m, ceiling_agl_m : float
        Height band above the terrain (m).
    step_m : float
        Lattice spacing (m).
    guard : Guard or None
        The guard whose row and obstacle clearances every move between free nodes keeps
        (module doc); None: the blocked nodes alone.
    """

    known: KnownMap
    obstacles: ObstacleMap
    keep_m: float
    floor_agl_m: float
    ceiling_agl_m: float
    step_m: float = 0.25
    guard: object = None


@dataclass(frozen=True)
class Lattice:
    """Node coordinates: x (nx,), y (ny,), z (nz,) ENU m; node (i, j, k) at (x[i], y[j], z[k])."""

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray

    @property
    def shape(self) -> tuple[int, int, int]:
        return len(self.x), len(self.y), len(self.z)

    def index(self, p) -> tuple[int, int, int]:
        """Nearest node of an ENU point (clamped to the lattice)."""
        out = []
        for axis, c in zip((self.x, self.y, self.z), p):
            step = axis[1] - axis[0] if len(axis) > 1 else 1.0
            out.append(int(np.clip(round((float(c) - axis[0]) / step), 0, len(axis) - 1)))
        return tuple(out)

    def point(self, ijk) -> np.ndarray:
        return np.array([self.x[ijk[0]], self.y[ijk[1]], self.z[ijk[2]]])


@dataclass(frozen=True)
class Route3D:
    """A route: ``path_enu_m`` (n, 3) turning points from the start to ``goal_index``'s goal."""

    path_enu_m: np.ndarray
    goal_index: int
    length_m: float


def lattice_for(scene: RouteScene, points_enu_m, margin_m: float = WINDOW_MARGIN_M) -> Lattice:
    """The lattice over the window round ``points_enu_m`` ((k, 3)), its height the band
    over the lowest and highest terrain under the window (sampled every step)."""
    P = np.asarray(points_enu_m, dtype=float).reshape(-1, 3)
    s = scene.step_m
    lo = np.floor((P[:, :2].min(axis=0) - margin_m) / s) * s
    hi = np.ceil((P[:, :2].max(axis=0) + margin_m) / s) * s
    x = np.arange(lo[0], hi[0] + 0.5 * s, s)
    y = np.arange(lo[1], hi[1] + 0.5 * s, s)
    X, Y = np.meshgrid(x, y, indexing="ij")
    g = terrain(scene.known, X, Y)
    z0 = np.floor((float(g.min()) + scene.floor_agl_m) / s) * s
    z1 = np.ceil((float(g.max()) + scene.ceiling_agl_m) / s) * s
    return Lattice(x, y, np.arange(z0, z1 + 0.5 * s, s))


def terrain(known: KnownMap, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Terrain height (m) under each (x, y)."""
    return np.vectorize(lambda a, b: known.ground_z(float(a), float(b)), otypes=[float])(X, Y)


def blocked_nodes(scene: RouteScene, lat: Lattice) -> tuple[np.ndarray, np.ndarray]:
    """(blocked (nx, ny, nz) bool, terrain (nx, ny)) of the lattice (module doc), vectorised."""
    known = scene.known
    X, Y = np.meshgrid(lat.x, lat.y, indexing="ij")
    ground = terrain(known, X, Y)
    r, c = known.grid.world_to_cell(X, Y)
    r, c = np.rint(r).astype(int), np.rint(c).astype(int)
    rows, cols = known.grid.shape
    on = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
    rr, cc = np.clip(r, 0, rows - 1), np.clip(c, 0, cols - 1)
    occupied = on & known.grid.occupied[rr, cc]
    not_free = ~on | ~(known.grid.free[rr, cc] | known.grid.occupied[rr, cc])
    Z = lat.z[None, None, :]
    blocked = not_free[..., None] | (occupied[..., None] & (Z <= (ground + known.canopy_height_m)[..., None]))
    # obstacle columns: the top of the occupied voxels over each node's (x, y)
    if len(scene.obstacles):
        blocked |= Z <= column_tops(scene.obstacles, lat, X, Y)[..., None]
    added = added_tops(known, lat, rr, cc, on)
    if (added > -np.inf).any():
        blocked |= Z <= added[..., None]
    return blocked, ground


def added_tops(known: KnownMap, lat: Lattice, rr: np.ndarray, cc: np.ndarray, on: np.ndarray) -> np.ndarray:
    """(nx, ny) the top (m) of the column a re-route added over each lattice node's cell
    (``rr``, ``cc``: the nodes' cells, ``on``: on the grid; -inf: none, +inf: unknown
    top). A cell between nodes gives its top to its nearest node too (as ``column_tops``)."""
    added = np.asarray(known.added, dtype=bool)
    tops = getattr(known, "added_top", None)
    if not added.any():
        return np.full(rr.shape, -np.inf)
    tops = np.where(added, np.inf, -np.inf) if tops is None else np.asarray(tops, dtype=float)
    out = np.where(on, tops[rr, cc], -np.inf)
    r, c = np.nonzero(added)
    x, y = known.grid.cell_to_world(r, c)
    s = lat.x[1] - lat.x[0] if len(lat.x) > 1 else 1.0
    i = np.rint((x - lat.x[0]) / s).astype(int)
    j = np.rint((y - lat.y[0]) / s).astype(int)
    inside = (i >= 0) & (i < len(lat.x)) & (j >= 0) & (j < len(lat.y))
    np.maximum.at(out, (i[inside], j[inside]), tops[r[inside], c[inside]])
    return out


def column_tops(obstacles: ObstacleMap, lat: Lattice, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """(nx, ny) the top (m) of the obstacle column over each lattice node's (x, y): the
    highest occupied voxel's upper face in the voxel column holding it (-inf: none).
    A column thinner than the lattice step may fall between nodes: its nearest node
    gets it too."""
    vk = obstacles.keys()
    v = obstacles.voxel_m
    keys, inv = np.unique(vk[:, 0] * (1 << 32) + (vk[:, 1] + (1 << 31)), return_inverse=True)
    tops = np.full(len(keys), -np.inf)
    np.maximum.at(tops, inv.ravel(), (vk[:, 2] + 1) * v)
    nk = np.floor(X / v).astype(np.int64) * (1 << 32) + (np.floor(Y / v).astype(np.int64) + (1 << 31))
    pos = np.clip(np.searchsorted(keys, nk), 0, len(keys) - 1)
    top = np.where(keys[pos] == nk, tops[pos], -np.inf)
    cx, cy = keys >> 32, (keys & 0xFFFFFFFF) - (1 << 31)
    s = lat.x[1] - lat.x[0] if len(lat.x) > 1 else 1.0
    i = np.rint(((cx + 0.5) * v - lat.x[0]) / s).astype(int)
    j = np.rint(((cy + 0.5) * v - lat.y[0]) / s).astype(int)
    inside = (i >= 0) & (i < len(lat.x)) & (j >= 0) & (j < len(lat.y))
    np.maximum.at(top, (i[inside], j[inside]), tops[inside])
    return top


def free_nodes(scene: RouteScene, lat: Lattice) -> np.ndarray:
    """(nx, ny, nz) bool: the free nodes (module doc)."""
    blocked, ground = blocked_nodes(scene, lat)
    s = scene.step_m
    if blocked.any():
        clear = ndimage.distance_transform_edt(~blocked, sampling=(s, s, s))
    else:
        clear = np.full(blocked.shape, np.inf)
    Z = lat.z[None, None, :]
    band = ((Z >= (ground + scene.floor_agl_m)[..., None] - 1e-9)
            & (Z <= (ground + scene.ceiling_agl_m)[..., None] + 1e-9))
    free = band & (clear >= scene.keep_m + 0.5 * s - 1e-9)
    if scene.guard is not None and free.any():
        free &= guard_keeps(scene, lat, free)
    return free


#: The guard's surfaces a free node keeps its distance from (the terrain: the band itself).
GUARD_KINDS = ("row", "obstacle")


def edge_keep_m(required_m: float, step_m: float) -> float:
    """The distance (m) two nodes one move apart must keep from every point of a set for
    the straight move between them to keep ``required_m``: any point ``c`` of the set is
    at least ``k`` from both ends, so the move, a chord of the ball of radius ``k`` round
    ``c`` at most ``L`` long, passes ``c`` at no less than ``sqrt(k^2 - L^2 / 4)``; with
    ``L`` the longest move (a horizontal diagonal, ``step_m * sqrt(2)``) that is
    ``required_m`` for ``k = sqrt(required_m^2 + L^2 / 4)``. Any set: rows' boxes,
    voxels, their union."""
    half = 0.5 * step_m * float(np.sqrt(2.0))
    return float(np.sqrt(required_m * required_m + half * half))


def guard_keeps(scene: RouteScene, lat: Lattice, candidates: np.ndarray) -> np.ndarray:
    """(nx, ny, nz) bool: the ``candidates`` nodes that keep ``edge_keep_m`` of the guard's
    clearance from the rows and the obstacles, measured by the guard on the scene's map."""
    idx = np.nonzero(candidates)
    P = np.stack([lat.x[idx[0]], lat.y[idx[1]], lat.z[idx[2]]], axis=1)
    d = scene.guard.distances(P, terrain=False, known=scene.known)
    ok = np.ones(len(P), dtype=bool)
    for kind in GUARD_KINDS:
        ok &= d[kind] >= edge_keep_m(scene.guard.required_m(kind), scene.step_m)
    out = np.zeros(candidates.shape, dtype=bool)
    out[idx] = ok
    return out


def _graph(free: np.ndarray, s: float):
    ids = np.full(free.shape, -1, dtype=np.int64)
    ids[free] = np.arange(int(free.sum()))
    src, dst, w = [], [], []
    nx, ny, nz = free.shape
    for dx, dy, dz in MOVES:
        a = ids[max(0, -dx):nx - max(0, dx), max(0, -dy):ny - max(0, dy), max(0, -dz):nz - max(0, dz)]
        b = ids[max(0, dx):nx + min(0, dx), max(0, dy):ny + min(0, dy), max(0, dz):nz + min(0, dz)]
        m = (a >= 0) & (b >= 0)
        src.append(a[m])
        dst.append(b[m])
        w.append(np.full(int(m.sum()), s * float(np.sqrt(dx * dx + dy * dy + dz * dz))))
    n = int(free.sum())
    src, dst, w = np.concatenate(src), np.concatenate(dst), np.concatenate(w)
    return ids, coo_matrix((w, (src, dst)), shape=(n, n)).tocsr()


def start_node(free: np.ndarray, lat: Lattice, start_enu_m, snap_m: float = START_SNAP_M):
    """The start's node, or (when it is not free) the nearest free node within ``snap_m``; None if none."""
    ijk = lat.index(start_enu_m)
    if free[ijk]:
        return ijk
    cand = np.argwhere(free)
    if len(cand) == 0:
        return None
    P = np.stack([lat.x[cand[:, 0]], lat.y[cand[:, 1]], lat.z[cand[:, 2]]], axis=1)
    d = np.linalg.norm(P - np.asarray(start_enu_m, dtype=float), axis=1)
    k = int(np.argmin(d))
    return tuple(int(c) for c in cand[k]) if d[k] <= snap_m else None


def find_route(scene: RouteScene, start_enu_m, goals_enu_m, margin_m: float = WINDOW_MARGIN_M) -> Route3D | None:
    """The shortest lattice route from the start to the nearest reachable goal ((k, 3)
    ENU m; a goal is reached at its node, which must be free), simplified to its
    turning points; None when no goal is reachable."""
    goals = np.asarray(goals_enu_m, dtype=float).reshape(-1, 3)
    lat = lattice_for(scene, np.vstack([np.asarray(start_enu_m, dtype=float)[None], goals]), margin_m)
    free = free_nodes(scene, lat)
    s0 = start_node(free, lat, start_enu_m)
    if s0 is None:
        return None
    ids, G = _graph(free, scene.step_m)
    dist, pred = dijkstra(G, directed=False, indices=int(ids[s0]), return_predecessors=True)
    best, best_d = None, np.inf
    for k, g in enumerate(goals):
        gi = lat.index(g)
        if free[gi] and dist[ids[gi]] < best_d:
            best, best_d = k, float(dist[ids[gi]])
    if best is None:
        return None
    node = int(ids[lat.index(goals[best])])
    where = np.argwhere(free)
    source = int(ids[s0])
    chain = [lat.point(where[node])]
    while node != source:
        node = int(pred[node])
        chain.append(lat.point(where[node]))
    path = np.array(chain[::-1])
    path = np.vstack([np.asarray(start_enu_m, dtype=float)[None], path, goals[best][None]])
    return Route3D(_turning_points(path), best, best_d)


def _turning_points(path: np.ndarray) -> np.ndarray:
    """The path without the points where it goes straight on."""
    if len(path) < 3:
        return path
    keep = [0]
    for i in range(1, len(path) - 1):
        a, b = path[i] - path[keep[-1]], path[i + 1] - path[i]
        if np.linalg.norm(np.cross(a, b)) > 1e-9 * max(1.0, np.linalg.norm(a) * np.linalg.norm(b)):
            keep.append(i)
    keep.append(len(path) - 1)
    return path[keep]
