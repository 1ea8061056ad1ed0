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
3. The cheapest 8-connected cell path over the corridor's cells is found
   with ``scipy.sparse.csgraph.dijkstra`` on a CSR graph of those cells only
   (neighbours by ``searchsorted`` on their linear indices); cells near the
   corridor's edge cost more, so the path keeps off the staircase edge of
   the eroded space where there is room (:func:`cell_path`).
4. The cell path is simplified by line-of-sight shortcutting (string
   pulling): from each kept point, a far visible point is found by testing
   many candidates per vectorised call (the next points, then points
   64, 128, 256, ... ahead, then evenly spaced probes in the last gap), a
   few calls per kept point (:func:`simplify`). Each call only needs the
   farthest visible candidate (:func:`farthest_visible`): every 16th sample
   of every candidate first, then the survivors in full from the far end,
   so the many visible candidates before it are never sampled in full.
   Consecutive cell centres see
   each other (a diagonal step's samples at 1/3 and 2/3 lie in its two
   cells), so every kept point sees the next one.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from mavcore.errors import PlanError
from .freespace import FreeSpace

_SQRT2 = float(np.sqrt(2.0))
#: points tested at once by the string pulling before it looks further ahead
_WINDOW = 64
#: points tested at once when the string pulling narrows a gap
_PROBES = 32
#: farthest_visible: every _STRIDE-th sample first, then _BATCH segments in full at a time
_STRIDE = 16
_BATCH = 4
#: cells this close to the edge of the eroded space cost _EDGE_COST times more to cross
_EDGE_CELLS = 2
_EDGE_COST = 4.0
#: cell_graph looks neighbours up in a grid of node numbers over the cells' bounding box
#: when it has at most this many cells per listed cell, else by searchsorted
_DENSE_BOX = 16
#: 8-neighbourhood offsets (dr, dc) and step lengths (cells).
_NEIGHBOURS = ((0, 1, 1.0), (0, -1, 1.0), (1, 0, 1.0), (-1, 0, 1.0),
               (1, 1, _SQRT2), (1, -1, _SQRT2), (-1, 1, _SQRT2), (-1, -1, _SQRT2))
NEIGHBOURS_4 = _NEIGHBOURS[:4]


def is_clear(free: FreeSpace, a: np.ndarray, b: np.ndarray) -> bool:
    """True if the straight segment a-b (G, m) stays in eroded free space."""
    return bool(visible_from(free, a, np.asarray(b, float)[None])[0])


def visible_from(free: FreeSpace, a: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(k,) bool: which straight segments a-targets[j] (G, m) stay in eroded free space.

    Samples every half cell or closer, both ends included, for all targets
    in one vectorised lookup. ``a``: (2,), or (k, 2) for one origin per target.
    """
    a = np.asarray(a, float)
    targets = np.asarray(targets, float).reshape(-1, 2)
    return _samples_clear(free, a, targets, _sample_counts(free, a, targets))


def farthest_visible(free: FreeSpace, a: np.ndarray, targets: np.ndarray) -> int:
    """Largest j such that the segment a-targets[j] (G, m) is clear (:func:`visible_from`), or -1.

    The same answer as ``flatnonzero(visible_from(free, a, targets))[-1]``
    at a fraction of the samples: every ``_STRIDE``-th sample of every
    segment is tested first (a subset of the very same sample points, so a
    segment failing there is blocked), then the segments that pass are
    tested in full from the last one backwards, ``_BATCH`` at a time, until
    one is clear. The visible segments before it are never sampled in full.
    """
    return farthest_visible_many(free, np.asarray(a, float)[None], [targets])[0]


def farthest_visible_many(free: FreeSpace, origins: np.ndarray, targets: list) -> list[int]:
    """:func:`farthest_visible` of several queries (origin ``origins[q]`` (G, m), targets
    ``targets[q]`` (k_q, 2)) with one vectorised call per stage for all of them."""
    origins = np.asarray(origins, float).reshape(-1, 2)
    targets = [np.asarray(t, float).reshape(-1, 2) for t in targets]
    sizes = np.array([len(t) for t in targets], dtype=np.int64)
    res = [-1] * len(targets)
    if sizes.sum() == 0:
        return res
    tg = np.concatenate(targets)
    org = np.repeat(origins, sizes, axis=0)
    n = _sample_counts(free, org, tg)
    coarse = _samples_clear(free, org, tg, n, _STRIDE)
    offset = np.concatenate([[0], np.cumsum(sizes)])
    # the survivors of all queries in one sorted array; query q's are surv[lo[q]:top[q]],
    # tested in full from the top down, _BATCH at a time (the bookkeeping in arrays)
    surv = np.flatnonzero(coarse)
    lo = np.searchsorted(surv, offset[:-1])
    top = np.searchsorted(surv, offset[1:])
    pending = np.flatnonzero(top > lo)
    while len(pending):
        start = np.maximum(lo[pending], top[pending] - _BATCH)
        cnt = top[pending] - start
        first = np.cumsum(cnt) - cnt
        idx = surv[np.arange(int(cnt.sum())) + np.repeat(start - first, cnt)]
        ok = _samples_clear(free, org[idx], tg[idx], n[idx])
        # the last clear segment of each query's batch, -1 if none
        last = np.maximum.reduceat(np.where(ok, np.arange(len(ok)), -1), first)
        hit = last >= 0
        for q, j in zip(pending[hit].tolist(), (idx[last[hit]] - offset[pending[hit]]).tolist()):
            res[q] = j
        miss = pending[~hit]
        top[miss] -= _BATCH
        pending = miss[top[miss] > lo[miss]]
    return res


def _sample_counts(free: FreeSpace, a: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(k,) samples of each segment a-targets[j]: every half cell or closer, both ends included
    (``a``: (2,) or (k, 2))."""
    return np.ceil(np.hypot(*(targets - a).T) / (free.resolution_m / 2)).astype(np.int64) + 1


def _samples_clear(free: FreeSpace, a: np.ndarray, targets: np.ndarray, n: np.ndarray,
                   stride: int = 1) -> np.ndarray:
    """(k,) bool: samples ``0, stride, 2 stride, ... <= n[j] - 1`` of the ``n[j]`` evenly
    spaced samples of each segment a-targets[j] are all in eroded space (stride 1: all
    of them). A sample's position does not depend on the stride (same arithmetic).
    ``a``: (2,), or (k, 2) for one origin per segment."""
    m = n if stride == 1 else (n - 1) // stride + 1
    ends = np.cumsum(m)
    total = int(ends[-1]) if len(ends) else 0
    if total == 0:
        return np.zeros(0, dtype=bool)
    first = ends - m
    # per-segment values repeated over their samples (sequential, no index array)
    j = np.arange(total)
    j -= np.repeat(first, m)
    if stride != 1:
        j *= stride
    s = j / np.repeat(np.maximum(n - 1, 1), m)
    # a + s (target - a) per axis (the same arithmetic as one segment at a time)
    d = targets - a
    px = s * np.repeat(d[:, 0], m)
    s *= np.repeat(d[:, 1], m)
    if a.ndim == 1:
        px += a[0]
        s += a[1]
    else:                                   # one origin per segment
        px += np.repeat(a[:, 0], m)
        s += np.repeat(a[:, 1], m)
    ok = free.raster().sample_xy(px, s)
    return np.logical_and.reduceat(ok, first)


def cell_graph(rr: np.ndarray, cc: np.ndarray, neighbours=None,
               edge_cells: int | None = None) -> tuple[csr_matrix, np.ndarray]:
    """Directed CSR graph of 8-connected grid cells given by their rows and columns.

    The cells are sorted by linear index and each one's eight neighbours are
    found in a grid of node numbers over their bounding box when the cells
    fill enough of it, else by ``searchsorted``, so a long diagonal corridor
    costs its own cells, not its bounding box. Edge
    weight: the step (1 or sqrt 2 cells) times the cost of the cell stepped
    into: ``_EDGE_COST`` within ``edge_cells`` (default ``_EDGE_CELLS``) of a
    cell that is not listed, 1 elsewhere (cell_path's doc). ``neighbours``:
    (dr, dc, step) offsets, default the 8-neighbourhood. Returns the graph
    and the order that sorts the input cells into node order.
    """
    neighbours = _NEIGHBOURS if neighbours is None else neighbours
    width = int(cc.max()) + 3
    lin = (rr.astype(np.int64) + 1) * width + (cc.astype(np.int64) + 1)
    order = np.argsort(lin, kind="stable")
    lin = lin[order]
    n = len(lin)
    nb = np.empty((n, len(neighbours)), dtype=np.int32 if n < 2**31 else np.int64)
    r0, c0 = int(rr.min()), int(cc.min())
    wl = int(cc.max()) - c0 + 3
    box = (int(rr.max()) - r0 + 3) * wl
    if box <= _DENSE_BOX * n:
        # a grid of node numbers over the bounding box (and a ring): one lookup per neighbour
        ids = np.full(box, -1, dtype=np.int32 if n < 2**31 else np.int64)
        local = (rr[order].astype(np.int64) - (r0 - 1)) * wl + (cc[order].astype(np.int64) - (c0 - 1))
        ids[local] = np.arange(n)
        for k, (dr, dc, _) in enumerate(neighbours):
            nb[:, k] = ids.take(local + (dr * wl + dc))
    else:
        for k, (dr, dc, _) in enumerate(neighbours):
            t = lin + dr * width + dc
            pos = np.minimum(np.searchsorted(lin, t), n - 1)
            nb[:, k] = np.where(lin[pos] == t, pos, -1)
    return _graph_of(nb, neighbours, edge_cells), order


def mask_graph(mask: np.ndarray, neighbours=None, edge_cells: int | None = None):
    """:func:`cell_graph` of the True cells of a 2-D mask, nodes in ``np.nonzero`` order.

    The same graph as ``cell_graph(*np.nonzero(mask), ...)`` (whose order is then
    the identity), its neighbours looked up in a grid of node numbers instead
    of by ``searchsorted``: for masks whose cells fill their bounding box.
    Returns the graph and the nodes' rows and columns.
    """
    neighbours = _NEIGHBOURS if neighbours is None else neighbours
    rows, cols = np.nonzero(mask)
    n = len(rows)
    width = mask.shape[1] + 2
    ids = np.full((mask.shape[0] + 2) * width, -1, dtype=np.int32 if n < 2**31 else np.int64)
    lin = (rows + 1) * width + (cols + 1)
    ids[lin] = np.arange(n)
    nb = np.empty((n, len(neighbours)), dtype=np.int32 if n < 2**31 else np.int64)
    for k, (dr, dc, _) in enumerate(neighbours):
        nb[:, k] = ids.take(lin + (dr * width + dc))
    del ids, lin
    return _graph_of(nb, neighbours, edge_cells), rows, cols


def _graph_of(nb: np.ndarray, neighbours, edge_cells: int | None) -> csr_matrix:
    """CSR graph from each node's neighbour nodes (-1: none), weights as :func:`cell_graph`."""
    edge_cells = _EDGE_CELLS if edge_cells is None else edge_cells
    n, k = nb.shape
    ok = nb >= 0
    step = np.array([s for _, _, s in neighbours])
    to = nb[ok]
    if edge_cells > 0:
        inner = _rows_all(ok)
        for _ in range(edge_cells - 1):
            # a row that is inner has all its neighbours (no -1 among them); the
            # others are False whatever the -1 entries pick up
            inner &= _rows_all(inner.take(nb))
        # step x cost of the cell stepped into, in the (n, k) layout, one mask at the end
        w = (step * np.where(inner, 1.0, _EDGE_COST).take(nb))[ok]
    else:
        # every cell costs 1: the steps themselves (x * 1.0 is x; no (n k) float temporaries)
        w = np.broadcast_to(step, (n, k))[ok]
    # int32 offsets when they fit, like the indices: scipy would otherwise copy the
    # indices to int64 to match (8 bytes an edge, 28 MB for a 10 ha transit graph)
    idx = np.int32 if n * k < 2**31 - 1 else np.int64
    indptr = np.zeros(n + 1, dtype=idx)
    np.cumsum(_rows_count(ok), dtype=idx, out=indptr[1:])
    return csr_matrix((w, to.astype(idx, copy=False), indptr), shape=(n, n))


def _rows_count(b: np.ndarray) -> np.ndarray:
    """``b.sum(axis=1)`` for an (n, k) bool array; k = 4 or 8: the set bits of each row
    read as one integer (each True is the byte 1)."""
    if b.shape[1] in (4, 8) and b.flags.c_contiguous:
        return np.bitwise_count(b.view(np.uint32 if b.shape[1] == 4 else np.uint64).ravel())
    return b.sum(axis=1)


def _rows_all(b: np.ndarray) -> np.ndarray:
    """``b.all(axis=1)`` for an (n, k) bool array; k = 4 or 8 read as one integer per row
    (a reduction over so short an axis is slow)."""
    if b.shape[1] in (4, 8) and b.flags.c_contiguous:
        dt = np.uint32 if b.shape[1] == 4 else np.uint64
        return b.view(dt).ravel() == np.ones(b.shape[1], dtype=np.uint8).view(dt)[0]
    return b.all(axis=1)


def cell_path(rr: np.ndarray, cc: np.ndarray, src: tuple[int, int], dst: tuple[int, int]) -> np.ndarray | None:
    """(k, 2) rows/cols of a cheapest 8-connected path over the listed cells from src to dst, or None.

    Cells within ``_EDGE_CELLS`` of the edge of the listed set cost
    ``_EDGE_COST`` times more: the path keeps off the staircase edge of the
    eroded space where it can (where straight shortcuts are visible, so
    string pulling leaves few corners, each of which is a stop for the
    way-points), and still takes a passage narrower than that when it must.
    """
    rr = np.asarray(rr, dtype=np.int64)
    cc = np.asarray(cc, dtype=np.int64)
    hit_s = np.flatnonzero((rr == src[0]) & (cc == src[1]))
    hit_d = np.flatnonzero((rr == dst[0]) & (cc == dst[1]))
    if len(hit_s) == 0 or len(hit_d) == 0:
        return None
    graph, order = cell_graph(rr, cc)
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order))
    i_src, i_dst = int(rank[hit_s[0]]), int(rank[hit_d[0]])
    dist, pred = dijkstra(graph, directed=True, indices=i_src, return_predecessors=True)
    if not np.isfinite(dist[i_dst]):
        return None
    step = pred.item            # Python ints per step: no numpy scalar per cell of the path
    path = [i_dst]
    while path[-1] != i_src:
        path.append(step(path[-1]))
    nodes = order[np.array(path[::-1])]
    return np.column_stack([rr[nodes], cc[nodes]])


def simplify(free: FreeSpace, pts: np.ndarray) -> np.ndarray:
    """String pulling of a polyline whose consecutive points see each other (module doc, step 4).

    From each kept point, one vectorised visibility test of the next
    ``_WINDOW`` points and of points ``_WINDOW 2^k`` ahead picks the farthest
    visible candidate; the gap up to the next candidate is then narrowed by
    testing ``_PROBES`` evenly spaced points at once (a few rounds). A few
    calls per kept point, each testing many segments.
    """
    return simplify_many(free, [pts])[0]


class _Pull:
    """State of one polyline's string pulling (:func:`simplify_many`)."""

    __slots__ = ("pts", "n", "out", "i", "lo", "hi", "ask", "probing")

    def __init__(self, pts: np.ndarray):
        self.pts = np.asarray(pts, float)
        self.n = len(self.pts)
        self.out = [0]
        self.i = 0
        self.probing = False
        if self.n - 1 > 0:
            self._candidates()

    def _candidates(self) -> None:
        i, n = self.i, self.n
        near = np.arange(i + 1, min(n, i + 1 + _WINDOW))
        far = i + _WINDOW * 2 ** np.arange(1, 40)
        cand = np.concatenate([near, far[far < n]])      # sorted, distinct
        if cand[-1] != n - 1:
            cand = np.append(cand, n - 1)
        self.ask, self.probing = cand, False

    def answer(self, j: int) -> bool:
        """Take the farthest visible one of ``ask`` (index or -1); True while more to ask."""
        ask = self.ask
        if not self.probing:
            k = max(j, 0)                       # pts[i + 1] (ask[0]) is visible by assumption
            self.lo = int(ask[k])
            self.hi = int(ask[k + 1]) if k + 1 < len(ask) else self.n
        elif j >= 0:
            self.lo = int(ask[j])
            self.hi = int(ask[j + 1]) if j + 1 < len(ask) else self.hi
        else:
            self.hi = int(ask[0])
        lo, hi = self.lo, self.hi
        if hi - lo > 1:
            probe = np.linspace(lo, hi, _PROBES + 2)[1:-1].astype(np.int64)     # non-decreasing
            probe = probe[(probe > lo) & (probe < hi) & np.append(True, probe[1:] != probe[:-1])]
            if len(probe):
                self.ask, self.probing = probe, True
                return True
        self.out.append(lo)
        self.i = lo
        if self.i < self.n - 1:
            self._candidates()
            return True
        return False


def simplify_many(free: FreeSpace, polylines: list) -> list[np.ndarray]:
    """:func:`simplify` of several polylines in lock step: each round asks every
    unfinished one's next question in one :func:`farthest_visible_many` call."""
    pulls = [_Pull(p) for p in polylines]
    active = [p for p in pulls if p.n - 1 > 0]
    while active:
        res = farthest_visible_many(free, np.array([p.pts[p.i] for p in active]),
                                    [p.pts[p.ask] for p in active])
        active = [p for p, j in zip(active, res) if p.answer(j)]
    return [p.pts[p.out] for p in pulls]


def aux_path(free: FreeSpace, a: np.ndarray, b: np.ndarray, source: str = "<map>") -> np.ndarray:
    """Collision-free connection from a to b (G, m) as a (k, 2) polyline, a and b included.

    Raises
    ------
    PlanError
        If a or b is not in the eroded free space or they are not connected in it.
    """
    return aux_paths(free, np.asarray(a, float)[None], np.asarray(b, float)[None], source)[0]


def aux_paths(free: FreeSpace, a: np.ndarray, b: np.ndarray, source: str = "<map>") -> list[np.ndarray]:
    """:func:`aux_path` from each ``a[j]`` to ``b[j]`` ((k, 2), G, m): the straight ones
    found in one visibility call, the cell paths of the others string-pulled in lock step
    (:func:`simplify_many`). Raises for the first pair (in order) that has no connection."""
    a = np.asarray(a, float).reshape(-1, 2)
    b = np.asarray(b, float).reshape(-1, 2)
    out: list = [None] * len(a)
    if len(a) == 0:
        return out
    clear = visible_from(free, a, b)
    h = free.resolution_m
    bg = free.block_graph() if not clear.all() else None
    who, lines = [], []
    for j, (p, q) in enumerate(zip(a, b)):
        if clear[j]:
            out[j] = np.array([p, q])
            continue
        ra, ca = int(p[1] // h), int(p[0] // h)
        rb, cb = int(q[1] // h), int(q[0] // h)
        corridor = bg.corridor(bg.sub_at(ra, ca), bg.sub_at(rb, cb))
        if corridor is None:
            raise PlanError(source, f"no collision-free connection from ({p[0]:.2f}, {p[1]:.2f}) to "
                                    f"({q[0]:.2f}, {q[1]:.2f}) m (grid frame) in the eroded free space")
        rr, cc = bg.cells_of(corridor)
        cells = cell_path(rr, cc, (ra, ca), (rb, cb))
        if cells is None:   # cannot happen: the corridor holds a fine path (module doc)
            raise PlanError(source, f"internal: no path in the corridor from ({p[0]:.2f}, {p[1]:.2f}) "
                                    f"to ({q[0]:.2f}, {q[1]:.2f}) m")
        centres = np.column_stack([(cells[:, 1] + 0.5) * h, (cells[:, 0] + 0.5) * h])
        who.append(j)
        lines.append(np.vstack([p, centres, q]))
    for j, line in zip(who, simplify_many(free, lines)):
        out[j] = line
    return out
