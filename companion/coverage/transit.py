"""Transits from one point (the launch point) to anywhere in the eroded free space.

Every sortie leaves the launch point and comes back to it, so all transits
share one end. One shortest-path tree from that point serves them all:

- The eroded mask (G frame, :mod:`freespace`) is min-pooled into cells of
  ``p x p`` fine cells (a pooled cell is free only if all its cells are), so
  any straight step between the centres of two side-by-side pooled cells
  stays in eroded space; the pooled cells are joined 4-connected.
- ``scipy.sparse.csgraph.dijkstra`` from the launch point's pooled cell gives
  distances and predecessors for every pooled cell at once (one search per
  plan instead of two per sortie).
- A transit to a point ``q`` walks the predecessors back from the nearest
  reachable pooled cell whose centre ``q`` sees, then is simplified by string
  pulling (``gridpath.simplify``): on the pooled mask first (clear there is
  clear in the fine mask), then on the fine mask over the few points left. When no such cell is near ``q`` (a passage
  narrower than a pooled cell), ``gridpath.aux_path`` finds the exact
  connection instead.

Pooled distances are also the sorties' transit estimates.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.sparse.csgraph import dijkstra

from .freespace import FreeSpace, min_pool
from .gridpath import NEIGHBOURS_4, aux_path, mask_graph, simplify_many, visible_from

#: pooled cell edge (m) aimed at; at least one fine cell
POOL_M = 0.2
#: how far (pooled cells) a point looks for a pooled cell it sees
_SEARCH = 4


def _search_offsets() -> tuple[np.ndarray, np.ndarray]:
    """(dr, dc) pooled-cell offsets within ``_SEARCH``, nearest first (stable ties)."""
    dr, dc = np.meshgrid(np.arange(-_SEARCH, _SEARCH + 1), np.arange(-_SEARCH, _SEARCH + 1), indexing="ij")
    order = np.argsort((dr * dr + dc * dc).ravel(), kind="stable")
    return dr.ravel()[order], dc.ravel()[order]


_DR, _DC = _search_offsets()


@dataclass(frozen=True, eq=False)
class TransitTree:
    """Shortest-path tree of the pooled eroded space from ``root_g`` (module doc)."""

    free: FreeSpace
    root_g: np.ndarray
    pool: int
    r0: int
    c0: int
    lin: np.ndarray        # sorted linear indices (row * width + col) of the pooled nodes
    width: int
    rows: np.ndarray
    cols: np.ndarray
    dist: np.ndarray       # (n,) pooled steps from the root (inf: unreachable)
    pred: np.ndarray       # (n,) predecessor node, -9999 at the root / unreachable
    source: str
    pooled: FreeSpace | None = None   # the pooled mask as a FreeSpace in the pooled frame

    def _centre_g(self, r, c) -> np.ndarray:
        cell = self.pool * self.free.resolution_m
        return np.column_stack([(self.c0 * self.free.resolution_m + (np.asarray(c) + 0.5) * cell),
                                (self.r0 * self.free.resolution_m + (np.asarray(r) + 0.5) * cell)])

    def _attach(self, qs_g: np.ndarray) -> list[int | None]:
        """For each point (m, 2) of ``qs_g``: the node of the nearest reachable pooled cell
        whose centre it sees, or None; all visibility tests in one call."""
        qs_g = np.asarray(qs_g, float).reshape(-1, 2)
        out: list = [None] * len(qs_g)
        if len(self.lin) == 0 or len(qs_g) == 0:
            return out
        h = self.free.resolution_m
        cell = self.pool * h
        pr = np.array([int((q[1] - self.r0 * h) // cell) for q in qs_g])
        pc = np.array([int((q[0] - self.c0 * h) // cell) for q in qs_g])
        r = pr[:, None] + _DR
        c = pc[:, None] + _DC
        t = r * self.width + c
        pos = np.minimum(np.searchsorted(self.lin, t), len(self.lin) - 1)
        hit = (self.lin[pos] == t) & (r >= 0) & (c >= 0)
        hit[hit] = np.isfinite(self.dist[pos[hit]])
        qi, k = np.nonzero(hit)                 # per point, nearest offsets first
        nodes = pos[qi, k]
        vis = visible_from(self.free, qs_g[qi], self._centre_g(self.rows[nodes], self.cols[nodes]))
        first_q, first = np.unique(qi[vis], return_index=True)
        for q, node in zip(first_q, nodes[vis][first]):
            out[int(q)] = int(node)
        return out

    def distance_m(self, q_g: np.ndarray) -> float:
        """Length (m) of the pooled transit from the root to ``q_g``; inf if it cannot attach."""
        return self.distances_m(np.asarray(q_g, float)[None])[0]

    def distances_m(self, qs_g: np.ndarray) -> list[float]:
        """:meth:`distance_m` of each point (m, 2) of ``qs_g``."""
        qs_g = np.asarray(qs_g, float).reshape(-1, 2)
        out = []
        for q_g, node in zip(qs_g, self._attach(qs_g)):
            if node is None:
                out.append(np.inf)
                continue
            centre = self._centre_g(self.rows[node], self.cols[node])[0]
            out.append(float(self.dist[node]) * self.pool * self.free.resolution_m
                       + float(np.hypot(*(centre - q_g))))
        return out

    def path_to(self, q_g: np.ndarray) -> np.ndarray:
        """(k, 2) G polyline from the root to ``q_g`` in eroded free space (module doc)."""
        return self.paths_to([q_g])[0]

    def paths_to(self, qs_g: list) -> list[np.ndarray]:
        """:meth:`path_to` of several points, their string pulling in lock step
        (``gridpath.simplify_many``): the same paths, far fewer vectorised calls."""
        out: list = [None] * len(qs_g)
        who, chains, ends = [], [], []
        pred = self.pred.item       # Python ints per step, without a list of all n nodes
        off = np.array([self.c0, self.r0]) * self.free.resolution_m
        qs_g = np.asarray(qs_g, float).reshape(-1, 2)
        for k, (q_g, node) in enumerate(zip(qs_g, self._attach(qs_g))):
            if node is None:
                out[k] = aux_path(self.free, self.root_g, q_g, self.source)
                continue
            chain = [node]
            p = pred(node)
            while p >= 0:
                chain.append(p)
                p = pred(p)
            chain = np.array(chain[::-1])
            who.append(k)
            ends.append(q_g)
            chains.append(self._centre_g(self.rows[chain], self.cols[chain]) - off)
        # string pulling on the pooled mask first (pooled cells are wholly eroded, so a
        # segment clear there is clear in the fine mask; half the samples), then on the
        # fine mask over the few points left, with the two end hops
        coarse = simplify_many(self.pooled, chains) if chains else []
        fine = simplify_many(self.free, [np.vstack([self.root_g, c + off, q]) for c, q in zip(coarse, ends)])
        for k, f in zip(who, fine):
            out[k] = f
        return out


def build_transit_tree(free: FreeSpace, root_g: np.ndarray, source: str = "<map>") -> TransitTree:
    """The tree from ``root_g`` (G, m; in eroded space) over the pooled eroded space (module doc)."""
    h = free.resolution_m
    p = max(1, int(round(POOL_M / h)))
    r0, r1, c0, c1 = free.bbox_cells
    win = free.eroded[r0:r1, c0:c1]
    pooled = min_pool(win, p)
    width = pooled.shape[1] + 2
    if not pooled.any():
        empty = np.zeros(0, dtype=np.int64)
        return TransitTree(free, np.asarray(root_g, float), p, r0, c0, empty, width, empty, empty,
                           np.zeros(0), empty, source)
    graph, rows, cols = mask_graph(pooled, neighbours=NEIGHBOURS_4, edge_cells=0)
    lin = rows * width + cols
    if pooled.size < 2**31:     # int32 node cells: the same centres, half the memory held
        rows, cols = rows.astype(np.int32), cols.astype(np.int32)
    # a tree without distances yet: only its cell centres are used to attach the root
    tree = TransitTree(free, np.asarray(root_g, float), p, r0, c0, lin, width, rows, cols,
                       np.zeros(0), np.zeros(0, dtype=np.int64), source)
    start = None
    # the root attaches to the nearest pooled cell it sees (distances not known yet)
    cell = p * h
    pr = int((root_g[1] - r0 * h) // cell)
    pc = int((root_g[0] - c0 * h) // cell)
    r = pr + _DR
    c = pc + _DC
    t = r * width + c
    pos = np.minimum(np.searchsorted(lin, t), len(lin) - 1)
    nodes = pos[(lin[pos] == t) & (r >= 0) & (c >= 0)]
    if len(nodes):
        vis = visible_from(free, np.asarray(root_g, float), tree._centre_g(rows[nodes], cols[nodes]))
        start = int(nodes[vis][0]) if vis.any() else None
    if start is None:           # no node reachable from the root
        return dataclasses.replace(tree, dist=np.full(len(lin), np.inf), pred=np.full(len(lin), -9999))
    del tree
    dist, pred = dijkstra(graph, directed=True, indices=start, return_predecessors=True)
    pooled_fs = FreeSpace(eroded=pooled, free=pooled, resolution_m=p * h, threshold_m=free.threshold_m)
    return TransitTree(free, np.asarray(root_g, float), p, r0, c0, lin, width, rows, cols, dist, pred, source,
                       pooled_fs)
