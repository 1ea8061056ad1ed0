"""Auxiliary connections: straight where clear, else a shortest path in the eroded free space.

All points are in the grid frame G (m, see :mod:`freespace`). A connection
is "clear" when every sample every half cell along it falls in an eroded
cell. Otherwise:

1. The block graph of the eroded space (:mod:`blockgraph`, built once per
   plan) tells whether the two end cells are connected at all; if not, the
   connection does not exist (``PlanError``; :mod:`plan` drops unreachable
   segments before it gets here).
2. A shortest path in the block graph gives a corridor of blocks (the path's
   blocks and their neighbours) that is known to hold a fine path, however
   far round it goes: narrow passages, rounded corners at the safety margin
   and pockets reachable only the long way round are all found, at full
   resolution, with no pooling that could close a passage.
3. The shortest 8-connected cell path inside the corridor is found with
   ``scipy.sparse.csgraph.dijkstra`` on a CSR graph built without sorting
   (neighbour indices by array shifts).
4. The cell path is simplified by line-of-sight shortcutting (string
   pulling): from each kept point, the farthest point still visible is
   found by galloping (1, 2, 4, ... points ahead) then bisection, with one
   vectorised visibility test per probe, so a path of ``n`` cells costs
   ``O(k log n)`` tests for ``k`` kept points. Consecutive cell centres see
   each other (a diagonal step's samples at 1/3 and 2/3 lie in its two
   cells), so every kept point sees the next one.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from ..errors import PlanError
from .freespace import FreeSpace

_SQRT2 = float(np.sqrt(2.0))
#: points tested at once by the string pulling before it gallops
_WINDOW = 64
#: 8-neighbourhood offsets (dr, dc) and step lengths (cells).
_NEIGHBOURS = ((0, 1, 1.0), (0, -1, 1.0), (1, 0, 1.0), (-1, 0, 1.0),
               (1, 1, _SQRT2), (1, -1, _SQRT2), (-1, 1, _SQRT2), (-1, -1, _SQRT2))


def is_clear(free: FreeSpace, a: np.ndarray, b: np.ndarray) -> bool:
    """True if the straight segment a-b (G, m) stays in eroded free space."""
    return bool(visible_from(free, a, np.asarray(b, float)[None])[0])


def visible_from(free: FreeSpace, a: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(k,) bool: which straight segments a-targets[j] (G, m) stay in eroded free space.

    Samples every half cell or closer, both ends included, for all targets
    in one vectorised lookup.
    """
    h = free.resolution_m
    a = np.asarray(a, float)
    targets = np.asarray(targets, float).reshape(-1, 2)
    n = np.ceil(np.hypot(*(targets - a).T) / (h / 2)).astype(np.int64) + 1
    seg = np.repeat(np.arange(len(targets)), n)
    first = np.concatenate([[0], np.cumsum(n)[:-1]])
    s = (np.arange(len(seg)) - first[seg]) / np.maximum(n[seg] - 1, 1)
    p = a + s[:, None] * (targets[seg] - a)
    ok = free.raster().sample_points(p[:, 0], p[:, 1])
    return np.logical_and.reduceat(ok, first) if len(seg) else np.zeros(0, dtype=bool)


def grid_graph(mask: np.ndarray) -> tuple[csr_matrix, np.ndarray, np.ndarray]:
    """Directed CSR graph of the 8-connected True cells of ``mask``.

    Returns the graph (edge weights in cells: 1 or sqrt 2) and the (n,) row
    and column of each node (nodes in raster order). Built from eight
    shifted lookups of a padded index array, so the CSR rows come out in
    order and nothing is sorted.
    """
    rows, cols = mask.shape
    fr, fc = np.nonzero(mask)
    n = len(fr)
    idx = np.full((rows + 2, cols + 2), -1, dtype=np.int64)
    idx[fr + 1, fc + 1] = np.arange(n)
    nb = np.stack([idx[fr + 1 + dr, fc + 1 + dc] for dr, dc, _ in _NEIGHBOURS], axis=1)
    w = np.broadcast_to(np.array([s for _, _, s in _NEIGHBOURS]), nb.shape)
    ok = nb >= 0
    indptr = np.concatenate([[0], np.cumsum(ok.sum(axis=1))])
    return csr_matrix((w[ok], nb[ok], indptr), shape=(n, n)), fr, fc


def cell_path(mask: np.ndarray, src: tuple[int, int], dst: tuple[int, int]) -> np.ndarray | None:
    """(k, 2) rows/cols of a shortest 8-connected path in ``mask`` from src to dst, or None."""
    if not (mask[src] and mask[dst]):
        return None
    graph, fr, fc = grid_graph(mask)
    rows, cols = mask.shape
    lin = fr * cols + fc
    i_src = int(np.searchsorted(lin, src[0] * cols + src[1]))
    i_dst = int(np.searchsorted(lin, dst[0] * cols + dst[1]))
    dist, pred = dijkstra(graph, directed=True, indices=i_src, return_predecessors=True)
    if not np.isfinite(dist[i_dst]):
        return None
    path = [i_dst]
    while path[-1] != i_src:
        path.append(int(pred[path[-1]]))
    path = np.array(path[::-1])
    return np.column_stack([fr[path], fc[path]])


def simplify(free: FreeSpace, pts: np.ndarray) -> np.ndarray:
    """String pulling of a polyline whose consecutive points see each other (module doc, step 4).

    From each kept point the next kept point is the last one before the first
    hidden one: found with one vectorised test of the next ``_WINDOW`` points
    (most connections are that short), then by galloping and bisection.
    """
    pts = np.asarray(pts, float)
    n = len(pts)
    out = [0]
    i = 0
    while i < n - 1:
        ahead = pts[i + 1: min(n, i + 1 + _WINDOW)]
        vis = visible_from(free, pts[i], ahead)
        hidden = np.flatnonzero(~vis[1:])          # pts[i + 1] is visible by assumption
        if len(hidden) or i + 1 + _WINDOW >= n:
            lo = i + 1 + (int(hidden[0]) if len(hidden) else len(vis) - 1)
        else:
            lo, step = i + _WINDOW, _WINDOW       # all of the window is visible: gallop on
            hi = n
            while lo + step < n:
                if visible_from(free, pts[i], pts[lo + step][None])[0]:
                    lo += step
                    step *= 2
                else:
                    hi = lo + step
                    break
            while hi - lo > 1 and lo + 1 < n:
                mid = (lo + hi) // 2
                if visible_from(free, pts[i], pts[mid][None])[0]:
                    lo = mid
                else:
                    hi = mid
        out.append(lo)
        i = lo
    return pts[out]


def aux_path(free: FreeSpace, a: np.ndarray, b: np.ndarray, source: str = "<map>") -> np.ndarray:
    """Collision-free connection from a to b (G, m) as a (k, 2) polyline, a and b included.

    Raises
    ------
    PlanError
        If a or b is not in the eroded free space or they are not connected in it.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    if is_clear(free, a, b):
        return np.array([a, b])
    h = free.resolution_m
    ra, ca = int(a[1] // h), int(a[0] // h)
    rb, cb = int(b[1] // h), int(b[0] // h)
    bg = free.block_graph()
    corridor = bg.corridor(bg.sub_at(ra, ca), bg.sub_at(rb, cb))
    if corridor is None:
        raise PlanError(source, f"no collision-free connection from ({a[0]:.2f}, {a[1]:.2f}) to "
                                f"({b[0]:.2f}, {b[1]:.2f}) m (grid frame) in the eroded free space")
    blocks = bg.block_of[corridor]
    i0, j0 = blocks.min(axis=0)
    i1, j1 = blocks.max(axis=0) + 1
    r0, c0 = bg.r0 + int(i0) * bg.block, bg.c0 + int(j0) * bg.block
    mask = np.isin(bg.window(int(i0), int(i1), int(j0), int(j1)), corridor)
    cells = cell_path(mask, (ra - r0, ca - c0), (rb - r0, cb - c0))
    if cells is None:   # cannot happen: the corridor holds a fine path (module doc)
        raise PlanError(source, f"internal: no path in the corridor from ({a[0]:.2f}, {a[1]:.2f}) "
                                f"to ({b[0]:.2f}, {b[1]:.2f}) m")
    centres = np.column_stack([(c0 + cells[:, 1] + 0.5) * h, (r0 + cells[:, 0] + 0.5) * h])
    return simplify(free, np.vstack([a, centres, b]))
