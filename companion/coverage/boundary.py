"""The field's outer boundary as a polygon, from the occupancy grid.

Used for the inclusion geofence. The field is the free cells' largest
8-connected region with its holes filled (buildings and ponds inside the
field are inside the fence; the fence is about leaving the field). Its
outer boundary is traced on the cell-corner lattice:

1. every cell side between a field cell and a non-field cell is an edge,
   oriented with the field on its left (counter-clockwise around the
   field), found with four shifted comparisons;
2. the edges are chained into the outer loop by a lookup from each start
   corner to its edges; at a corner touched by two diagonal cells the
   rightmost turn is taken, which keeps the loop simple;
3. the loop is simplified by Douglas-Peucker with tolerance ``tol_m`` and
   its vertices are pushed outward by ``tol_m`` (along the vertex normals),
   so the simplified polygon contains every field cell: a path that keeps
   the safety margin from the field's edge keeps ``margin`` minus nothing
   from the fence.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from mavcore.maps.grid import OccupancyGrid
from .freespace import grid_to_world

# edge direction index -> (d_row, d_col) of the corner step; 0 +x, 1 +y, 2 -x, 3 -y
_STEP = np.array([[0, 1], [1, 0], [0, -1], [-1, 0]])


def field_mask(grid: OccupancyGrid) -> np.ndarray:
    """Largest 8-connected region of free cells, holes filled (rows, cols) bool."""
    lab, n = ndimage.label(grid.free, structure=np.ones((3, 3), dtype=bool))
    if n == 0:
        return np.zeros(grid.free.shape, dtype=bool)
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    return ndimage.binary_fill_holes(lab == int(np.argmax(sizes)))


def _outer_loop(mask: np.ndarray) -> np.ndarray:
    """(K, 2) corner lattice points (row, col) of the outer boundary, CCW, not closed."""
    m = np.pad(mask, 1)
    # horizontal edges: between cell (r, c) (field) and (r - 1, c) (outside) -> bottom side, +x
    r, c = np.nonzero(m[1:, :] & ~m[:-1, :])
    e_bottom = np.column_stack([r + 1, c, np.zeros_like(r)])           # from corner (r+1, c) going +x
    r, c = np.nonzero(m[:-1, :] & ~m[1:, :])                           # top side, -x
    e_top = np.column_stack([r + 1, c + 1, np.full_like(r, 2)])
    r, c = np.nonzero(m[:, :-1] & ~m[:, 1:])                           # right side, +y
    e_right = np.column_stack([r, c + 1, np.ones_like(r)])
    r, c = np.nonzero(m[:, 1:] & ~m[:, :-1])                           # left side, -y
    e_left = np.column_stack([r + 1, c + 1, np.full_like(r, 3)])
    edges = np.concatenate([e_bottom, e_top, e_right, e_left])
    # corners are (row, col) of the padded lattice; map start corner -> edges
    by_start: dict[tuple[int, int], list[int]] = {}
    for i, (rr, cc, _) in enumerate(edges.tolist()):
        by_start.setdefault((rr, cc), []).append(i)
    # start at the lowest-row, then lowest-col bottom edge: on the outer loop
    i0 = int(np.lexsort((edges[:, 1], edges[:, 0]))[0])
    loop = []
    used = np.zeros(len(edges), dtype=bool)
    i = i0
    while not used[i]:
        used[i] = True
        rr, cc, d = edges[i]
        loop.append((rr, cc))
        nr, nc = rr + _STEP[d][0], cc + _STEP[d][1]
        cand = [j for j in by_start.get((int(nr), int(nc)), []) if not used[j] or j == i0]
        if not cand:
            break
        # rightmost turn first: right (d - 1), straight, left (d + 1)
        order = {(d - 1) % 4: 0, d: 1, (d + 1) % 4: 2}
        i = min(cand, key=lambda j: order.get(int(edges[j, 2]), 3))
    return np.array(loop, dtype=float) - 1.0          # back to unpadded corner coordinates


def douglas_peucker(pts: np.ndarray, tol: float) -> np.ndarray:
    """Indices of the points Douglas-Peucker keeps on an open polyline (ends kept)."""
    keep = np.zeros(len(pts), dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, len(pts) - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        seg = pts[b] - pts[a]
        L = np.hypot(*seg)
        q = pts[a + 1: b] - pts[a]
        d = np.abs(q[:, 0] * seg[1] - q[:, 1] * seg[0]) / L if L > 0 else np.hypot(q[:, 0], q[:, 1])
        k = int(np.argmax(d))
        if d[k] > tol:
            keep[a + 1 + k] = True
            stack.append((a, a + 1 + k))
            stack.append((a + 1 + k, b))
    return np.flatnonzero(keep)


def field_boundary(grid: OccupancyGrid, tol_m: float, grow_m: float = 0.0) -> np.ndarray:
    """(K, 2) ENU polygon (m, counter-clockwise, not closed) around the field (module doc).

    ``grow_m``: the field is first grown by this distance (every cell whose
    centre is closer than ``grow_m`` to a field cell's centre joins it; the
    grid is padded so that growth is not cut at the map's edge), so the
    polygon keeps at least ``grow_m - h`` (h: the cell size) outside every
    field cell. Returns an empty (0, 2) array when the map has no free cell.
    """
    from .freespace import dilate_runs, disk_half_widths

    mask = field_mask(grid)
    if not mask.any():
        return np.zeros((0, 2))
    h = grid.resolution_m
    pad = 0
    if grow_m > 0:
        widths = disk_half_widths(grow_m / h)
        pad = len(widths) // 2 + 1
        mask = dilate_runs(np.pad(mask, pad), widths, outside=False)
    loop = _outer_loop(mask) - pad                 # (row, col) corners, in the unpadded grid
    g = np.column_stack([loop[:, 1] * h, loop[:, 0] * h])      # G frame (x, y)
    # split the closed loop at its farthest point from the start, simplify both halves
    far = int(np.argmax(np.hypot(*(g - g[0]).T)))
    a = douglas_peucker(g[: far + 1], tol_m)
    b = douglas_peucker(np.vstack([g[far:], g[:1]]), tol_m) + far
    idx = np.concatenate([a, b[1:-1]])
    poly = g[idx]
    # push each vertex out by tol along the bisector of its two edge normals (outward
    # normal of a CCW edge (dx, dy) is (dy, -dx))
    prev = poly - np.roll(poly, 1, axis=0)
    nxt = np.roll(poly, -1, axis=0) - poly
    n1 = np.column_stack([prev[:, 1], -prev[:, 0]]) / np.maximum(np.hypot(*prev.T), 1e-12)[:, None]
    n2 = np.column_stack([nxt[:, 1], -nxt[:, 0]]) / np.maximum(np.hypot(*nxt.T), 1e-12)[:, None]
    bis = n1 + n2
    cos_half = np.maximum(np.hypot(*bis.T) / 2.0, 0.25)
    bis = bis / np.maximum(np.hypot(*bis.T), 1e-12)[:, None]
    poly = poly + bis * (tol_m / cos_half)[:, None]
    return grid_to_world(grid, poly)
