"""Auxiliary connections: straight where clear, else a shortest grid path.

All points are in the grid frame G (m, see :mod:`freespace`). A connection is
"clear" when every sample every half cell along it falls in an eroded free
cell. Otherwise the shortest 8-connected path between the two cells is found
with Dijkstra (``scipy.sparse.csgraph``) on the eroded cells of a window
around the two points; the window is the points' bounding box grown by
``P``, starting at ``P = max(1 m, 0.75 D)`` (``D`` their distance), so the
search stays local. A path that leaves the window goes at least ``P``
beyond the bounding box and so is at least ``2 P`` long: a window path no
longer than ``2 P`` is the shortest one. Otherwise (or if there is none)
``P`` doubles, until the window covers the map. Windows over ~1e6 cells are searched on
a min-pooled mask (a pooled cell is free only if all its cells are), which
keeps the path admissible. The cell path is then simplified to a few
turning points by line-of-sight shortcutting (string pulling: from each
kept point, advance along the path while the straight shortcut is clear).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from ..errors import PlanError
from .freespace import FreeSpace, lookup

_MAX_WINDOW_CELLS = 1_000_000


def is_clear(free: FreeSpace, a: np.ndarray, b: np.ndarray) -> bool:
    """True if the straight segment a-b (G, m) stays in eroded free space."""
    h = free.resolution_m
    n = int(np.ceil(np.hypot(*(np.asarray(b) - np.asarray(a))) / (h / 2))) + 1
    s = np.linspace(0.0, 1.0, n)[:, None]
    p = (1 - s) * np.asarray(a) + s * np.asarray(b)
    return bool(lookup(free.eroded, h, p[:, 0], p[:, 1]).all())


def visible_from(free: FreeSpace, a: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(k,) bool: which straight segments a-targets[j] (G, m) stay in eroded free space.

    Same test as :func:`is_clear` (samples every half cell or closer, ends
    included) for all targets in one vectorised lookup.
    """
    h = free.resolution_m
    a = np.asarray(a, float)
    targets = np.asarray(targets, float).reshape(-1, 2)
    n = np.ceil(np.hypot(*(targets - a).T) / (h / 2)).astype(np.int64) + 1
    seg = np.repeat(np.arange(len(targets)), n)
    first = np.concatenate([[0], np.cumsum(n)[:-1]])
    s = (np.arange(len(seg)) - first[seg]) / np.maximum(n[seg] - 1, 1)
    p = a + s[:, None] * (targets[seg] - a)
    ok = lookup(free.eroded, h, p[:, 0], p[:, 1])
    return np.logical_and.reduceat(ok, first) if len(seg) else np.zeros(0, dtype=bool)


def _dijkstra_cells(mask: np.ndarray, src: tuple[int, int],
                    dst: tuple[int, int]) -> tuple[np.ndarray, float] | None:
    """Shortest 8-connected cell path in ``mask`` from src to dst or None.

    Returns the (k, 2) rows/cols of the path and its length (cells).
    """
    rows, cols = mask.shape
    idx = np.full(mask.shape, -1, dtype=np.int64)
    free_r, free_c = np.nonzero(mask)
    idx[free_r, free_c] = np.arange(len(free_r))
    if idx[src] < 0 or idx[dst] < 0:
        return None
    heads, tails, weights = [], [], []
    for dr, dc, w in ((0, 1, 1.0), (1, 0, 1.0), (1, 1, np.sqrt(2)), (1, -1, np.sqrt(2))):
        # pairs (r, c) -- (r + dr, c + dc) over the whole window at once
        a = idx[max(0, -dr): rows - max(0, dr), max(0, -dc): cols - max(0, dc)]
        b = idx[max(0, dr): rows - max(0, -dr), max(0, dc): cols - max(0, -dc)]
        ok = (a >= 0) & (b >= 0)
        heads.append(a[ok])
        tails.append(b[ok])
        weights.append(np.full(int(ok.sum()), w))
    n = len(free_r)
    graph = coo_matrix((np.concatenate(weights), (np.concatenate(heads), np.concatenate(tails))),
                       shape=(n, n)).tocsr()
    dist, pred = dijkstra(graph, directed=False, indices=int(idx[src]), return_predecessors=True)
    target = int(idx[dst])
    if not np.isfinite(dist[target]):
        return None
    path = [target]
    while path[-1] != idx[src]:
        path.append(int(pred[path[-1]]))
    path = np.array(path[::-1])
    return np.column_stack([free_r[path], free_c[path]]), float(dist[target])


def _min_pool(mask: np.ndarray, f: int) -> np.ndarray:
    m = np.zeros((-(-mask.shape[0] // f) * f, -(-mask.shape[1] // f) * f), dtype=bool)
    m[: mask.shape[0], : mask.shape[1]] = mask
    return m.reshape(m.shape[0] // f, f, m.shape[1] // f, f).all(axis=(1, 3))


def _nearest_true(mask: np.ndarray, rc: tuple[int, int]) -> tuple[int, int] | None:
    r, c = np.nonzero(mask)
    if len(r) == 0:
        return None
    k = int(np.argmin((r - rc[0]) ** 2 + (c - rc[1]) ** 2))
    return int(r[k]), int(c[k])


def _simplify(free: FreeSpace, pts: np.ndarray) -> np.ndarray:
    """Line-of-sight shortcutting (string pulling) of a polyline whose consecutive
    points see each other: from each kept point, advance while the next point
    is still visible (one vectorised visibility test per kept point)."""
    out = [pts[0]]
    i, n = 0, len(pts)
    while i < n - 1:
        vis = visible_from(free, pts[i], pts[i + 2:])
        blocked = np.flatnonzero(~vis)
        # pts[i + 1] is visible by assumption; stop before the first hidden one
        j = i + 1 + (int(blocked[0]) if len(blocked) else len(vis))
        out.append(pts[j])
        i = j
    return np.array(out)


def aux_path(free: FreeSpace, a: np.ndarray, b: np.ndarray, source: str = "<map>") -> np.ndarray:
    """Collision-free connection from a to b (G, m) as a (k, 2) polyline, a and b included.

    Raises
    ------
    PlanError
        If b cannot be reached from a in the eroded free space.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    if is_clear(free, a, b):
        return np.array([a, b])
    h = free.resolution_m
    rows, cols = free.eroded.shape
    ra, ca = int(a[1] // h), int(a[0] // h)
    rb, cb = int(b[1] // h), int(b[0] // h)
    pad = max(1.0, 0.75 * float(np.hypot(*(b - a))))
    while True:
        p = int(np.ceil(pad / h))
        r0, r1 = max(0, min(ra, rb) - p), min(rows, max(ra, rb) + p + 1)
        c0, c1 = max(0, min(ca, cb) - p), min(cols, max(ca, cb) + p + 1)
        win = free.eroded[r0:r1, c0:c1]
        f = max(1, int(np.ceil(np.sqrt(win.size / _MAX_WINDOW_CELLS))))
        pooled = _min_pool(win, f)
        src = _nearest_true(pooled, ((ra - r0) // f, (ca - c0) // f))
        dst = _nearest_true(pooled, ((rb - r0) // f, (cb - c0) // f))
        cells = None
        whole = r0 == 0 and c0 == 0 and r1 == rows and c1 == cols
        if src is not None and dst is not None:
            found = _dijkstra_cells(pooled, src, dst)
            # accept only a path that no path leaving the window can beat
            if found is not None and (whole or found[1] * f * h <= 2 * (p - 1) * h):
                cells = found[0]
        if cells is not None:
            centres = np.column_stack([c0 * h + (cells[:, 1] + 0.5) * f * h,
                                       r0 * h + (cells[:, 0] + 0.5) * f * h])
            pts = np.vstack([a, centres, b])
            # a and b may sit off the pooled cell centres: keep only what is clear
            if not is_clear(free, a, pts[1]) or not is_clear(free, pts[-2], b):
                cells = None
            else:
                return _simplify(free, pts)
        if whole:
            raise PlanError(source, f"no collision-free connection from ({a[0]:.2f}, {a[1]:.2f}) to "
                                    f"({b[0]:.2f}, {b[1]:.2f}) m (grid frame) in the eroded free space")
        pad *= 2
