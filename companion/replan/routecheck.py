"""An independent check that a 3-D route exists (``route3d``'s question, other means).

Same lattice and rules as ``companion.replan.route3d`` (its module doc), computed
apart from it: the blocked nodes by a loop over the lattice columns and the
voxels, the clearance by a k-d tree of the blocked nodes (not a distance
transform), reachability by a plain breadth-first search over the same moves
(not a shortest-path solver). A re-route's "no route" is declared only when
this check agrees; the tests check the two on hand-built mazes.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from scipy.spatial import cKDTree

from .route3d import MOVES, WINDOW_MARGIN_M, RouteScene, lattice_for, start_node


def _blocked(scene: RouteScene, lat) -> tuple[np.ndarray, np.ndarray]:
    known = scene.known
    nx, ny, nz = lat.shape
    blocked = np.zeros((nx, ny, nz), dtype=bool)
    ground = np.zeros((nx, ny))
    grid = known.grid
    rows, cols = grid.shape
    for i, x in enumerate(lat.x.tolist()):
        for j, y in enumerate(lat.y.tolist()):
            g = known.ground_z(x, y)
            ground[i, j] = g
            fr, fc = grid.world_to_cell(x, y)
            r, c = int(np.rint(fr)), int(np.rint(fc))
            if not (0 <= r < rows and 0 <= c < cols) or not (grid.free[r, c] or grid.occupied[r, c]):
                blocked[i, j, :] = True
            elif grid.occupied[r, c]:
                blocked[i, j, :] = lat.z <= g + known.canopy_height_m
            if 0 <= r < rows and 0 <= c < cols and known.added[r, c]:
                blocked[i, j, :] |= lat.z <= _added_top(known, r, c)
    v = scene.obstacles.voxel_m
    columns: dict[tuple[int, int], float] = {}
    for a, b, c in scene.obstacles.keys().tolist():
        columns[(a, b)] = max(columns.get((a, b), -np.inf), (c + 1) * v)
    kx, ky = np.floor(lat.x / v).astype(int), np.floor(lat.y / v).astype(int)
    for (a, b), top in columns.items():
        nearest = lat.index(((a + 0.5) * v, (b + 0.5) * v, 0.0))
        cells = {(i, j) for i in np.flatnonzero(kx == a).tolist() for j in np.flatnonzero(ky == b).tolist()}
        for i, j in cells | {(nearest[0], nearest[1])}:
            blocked[i, j, :] |= lat.z <= top
    # the columns a re-route added (the guard's picture): each also blocks its nearest node
    for r, c in zip(*np.nonzero(np.asarray(known.added, dtype=bool))):
        x, y = grid.cell_to_world(r, c)
        i, j, _ = lat.index((float(x), float(y), 0.0))
        if abs(lat.x[i] - x) <= 0.5 * scene.step_m + 1e-9 and abs(lat.y[j] - y) <= 0.5 * scene.step_m + 1e-9:
            blocked[i, j, :] |= lat.z <= _added_top(known, int(r), int(c))
    return blocked, ground


def _added_top(known, r: int, c: int) -> float:
    """Top (m) of the added column over cell (r, c) (+inf: unknown)."""
    tops = getattr(known, "added_top", None)
    return float("inf") if tops is None else float(tops[r, c])


def free_nodes_check(scene: RouteScene, lat) -> np.ndarray:
    """(nx, ny, nz) bool: the free nodes, by a k-d tree of the blocked ones."""
    blocked, ground = _blocked(scene, lat)
    X, Y, Z = np.meshgrid(lat.x, lat.y, lat.z, indexing="ij")
    nodes = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    band = ((Z >= ground[..., None] + scene.floor_agl_m - 1e-9)
            & (Z <= ground[..., None] + scene.ceiling_agl_m + 1e-9)).ravel()
    free = band.copy()
    if blocked.any():
        tree = cKDTree(nodes[blocked.ravel()])
        d, _ = tree.query(nodes[band])
        free[np.flatnonzero(band)] = d >= scene.keep_m + 0.5 * scene.step_m - 1e-9
    return free.reshape(X.shape)


def route_exists(scene: RouteScene, start_enu_m, goals_enu_m, margin_m: float = WINDOW_MARGIN_M) -> list[bool]:
    """For each goal ((k, 3) ENU m): can it be reached from the start (breadth-first)?"""
    goals = np.asarray(goals_enu_m, dtype=float).reshape(-1, 3)
    lat = lattice_for(scene, np.vstack([np.asarray(start_enu_m, dtype=float)[None], goals]), margin_m)
    free = free_nodes_check(scene, lat)
    s0 = start_node(free, lat, start_enu_m)
    if s0 is None:
        return [False] * len(goals)
    seen = np.zeros(free.shape, dtype=bool)
    seen[s0] = True
    queue = deque([s0])
    steps = [m for d in MOVES for m in (d, tuple(-c for c in d))]
    nx, ny, nz = free.shape
    while queue:
        i, j, k = queue.popleft()
        for dx, dy, dz in steps:
            a, b, c = i + dx, j + dy, k + dz
            if 0 <= a < nx and 0 <= b < ny and 0 <= c < nz and free[a, b, c] and not seen[a, b, c]:
                seen[a, b, c] = True
                queue.append((a, b, c))
    return [bool(seen[lat.index(g)]) for g in goals]
