"""Exact coarse connectivity of the eroded free space (a block graph).

The eroded mask (grid frame G, cells of ``h``; see :mod:`freespace`) is cut
into square blocks of ``f x f`` cells. Inside each block the eroded cells
fall into one or more 8-connected pieces, the *sub-components*; they are the
nodes of a sparse graph whose edges join two sub-components of neighbouring
blocks that hold 8-adjacent cells. Two eroded cells are then 8-connected in
the fine mask exactly when their sub-components are connected in the graph
(every sub-component is connected inside itself, and a fine path that
crosses a block boundary crosses an edge), so:

- the connected components of the graph are the components of the free
  space (which main segments can be reached from which);
- a shortest path in the graph gives a corridor of blocks that is known to
  hold a fine path, so the fine search runs on that corridor only, however
  far round the connection has to go.

Everything is vectorised: ``scipy.ndimage.label`` over the blocks seen as
a stack of ``f x f`` images (a 3-D structure that links cells inside a
slice only), ``_LABEL_CELLS`` cells of blocks at a time, four shifted
comparisons for the edges, and ``scipy.sparse.csgraph`` for components and
shortest paths. Work and memory are confined to the bounding box of the
eroded cells. Each cell keeps its piece's number *within its block* (at
most ``ceil(f / 2)^2`` pieces fit in a block, one per 2 x 2 tile: one byte
a cell for ``f <= 32``) and each block the number of pieces before it, so a
10 ha map at 5 cm holds 22 MB of labels instead of 90 MB of int32 ids.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

#: Aim for at most about this many blocks (the coarse graph stays small).
_TARGET_BLOCKS = 40_000
#: Smallest block edge (cells).
_MIN_BLOCK = 8
#: The four "forward" neighbour offsets (dr, dc) of 8-connectivity.
#: Cells labelled per ``ndimage.label`` call (bounds its int32 output).
_LABEL_CELLS = 1 << 20
_FORWARD = ((0, 1), (1, 0), (1, 1), (1, -1))


@dataclass(frozen=True, eq=False)
class BlockGraph:
    """Block graph of an eroded mask (module doc).

    Attributes
    ----------
    block : int
        Block edge ``f`` (cells).
    r0, c0 : int
        Grid cell of the lower-left corner of the covered window (the eroded
        bounding box); block ``(i, j)`` covers rows ``r0 + i f ..`` and
        columns ``c0 + j f ..``.
    shape : (rows, cols)
        Size of the covered window (cells).
    local : (nbr, nbc, f, f) unsigned int
        Number (1, 2, ...) of each eroded cell's sub-component within its
        block, in scan order; 0 elsewhere. Its id is ``local + base``.
    base : (nbr, nbc) int64
        Sub-components of the blocks before each block (scan order).
    graph : (K + 1, K + 1) csr_matrix
        Symmetric adjacency between sub-components, weights the distance
        (cells) between their blocks' centres; node 0 is unused.
    component : (K + 1,) int
        Connected component of each sub-component (-1 for node 0).
    block_of : (K + 1, 2) int
        Block (i, j) of each sub-component.
    """

    block: int
    r0: int
    c0: int
    shape: tuple[int, int]
    local: np.ndarray
    base: np.ndarray
    graph: csr_matrix
    component: np.ndarray
    block_of: np.ndarray

    def sub_at(self, r: int, c: int) -> int:
        """Sub-component id of grid cell (r, c); 0 if not eroded or outside the window."""
        rr, cc = r - self.r0, c - self.c0
        if 0 <= rr < self.shape[0] and 0 <= cc < self.shape[1]:
            f = self.block
            sub = int(self.local[rr // f, cc // f, rr % f, cc % f])
            return sub + int(self.base[rr // f, cc // f]) if sub else 0
        return 0

    def components_of(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Component id of each grid cell (arrays), -1 where not eroded."""
        f = self.block
        rr = np.asarray(rows, dtype=np.int64) - self.r0
        cc = np.asarray(cols, dtype=np.int64) - self.c0
        ok = (rr >= 0) & (rr < self.shape[0]) & (cc >= 0) & (cc < self.shape[1])
        out = np.full(rr.shape, -1, dtype=np.int64)
        r, c = rr[ok], cc[ok]
        s = self.local[r // f, c // f, r % f, c % f].astype(np.int64)
        s = np.where(s > 0, s + self.base[r // f, c // f], 0)
        out[ok] = np.where(s > 0, self.component[s], -1)
        return out

    def cells_of(self, subs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Grid rows and columns (int64 arrays) of the cells of the sub-components ``subs``."""
        f = self.block
        nbc = self.local.shape[1]
        bi, bj = self.block_of[subs].T
        ub = np.unique(bi * nbc + bj)
        loc = self.local[ub // nbc, ub % nbc].astype(np.int64)
        ids = np.where(loc > 0, loc + self.base[ub // nbc, ub % nbc][:, None, None], 0)
        # membership by a table over all sub-component ids (np.isin sorts the cells)
        wanted = np.zeros(len(self.component), dtype=bool)
        wanted[subs] = True
        wanted[0] = False                       # 0: not eroded
        sel = wanted[ids]
        m, lr, lc = np.nonzero(sel)
        return self.r0 + (ub[m] // nbc) * f + lr, self.c0 + (ub[m] % nbc) * f + lc

    def corridor(self, s_from: int, s_to: int) -> np.ndarray | None:
        """Sub-component ids of a shortest graph path from ``s_from`` to ``s_to``
        plus their graph neighbours (room to smooth the fine path); None if
        the two are not connected."""
        if s_from <= 0 or s_to <= 0 or self.component[s_from] != self.component[s_to]:
            return None
        if s_from == s_to:
            nodes = np.array([s_from])
        else:
            # Dijkstra bounded by a distance limit (cells) that doubles until
            # the target is settled: the search stays local for the usual
            # short connection and still reaches any connected target.
            straight = float(np.hypot(*(self.block_of[s_to] - self.block_of[s_from]))) * self.block
            limit = 2.0 * straight + 4.0 * self.block
            while True:
                dist, pred = dijkstra(self.graph, directed=True, indices=s_from, return_predecessors=True,
                                      limit=limit)
                if np.isfinite(dist[s_to]):
                    break
                if limit > float(self.graph.data.sum()):    # longer than any simple path
                    return None
                limit *= 2.0
            step = pred.item            # Python ints per step
            path = [s_to]
            while path[-1] != s_from:
                path.append(step(path[-1]))
            nodes = np.array(path)
        # the nodes' neighbours straight from the CSR arrays (row slicing of the
        # sparse matrix builds a new matrix per call); np.unique sorts them anyway
        indptr, indices = self.graph.indptr, self.graph.indices
        starts = indptr[nodes].astype(np.int64)
        counts = indptr[nodes + 1] - starts
        first = np.cumsum(counts) - counts
        pos = np.arange(int(counts.sum()), dtype=np.int64) + np.repeat(starts - first, counts)
        return np.unique(np.concatenate([nodes, indices[pos]]))


def block_size(n_cells: int) -> int:
    """Block edge (cells) for a window of ``n_cells``: about ``_TARGET_BLOCKS`` blocks."""
    return max(_MIN_BLOCK, int(np.ceil(np.sqrt(n_cells / _TARGET_BLOCKS))))


def _pairs(a: np.ndarray, b: np.ndarray, k: int) -> np.ndarray | None:
    """Unique undirected keys ``min * (k + 1) + max`` of the labelled pairs (a, b), a != b."""
    m = (a > 0) & (b > 0) & (a != b)
    if not m.any():
        return None
    a, b = a[m], b[m]
    key = np.minimum(a, b).astype(np.int64)
    key *= k + 1
    key += np.maximum(a, b)
    # neighbouring border cells mostly join the same two pieces: drop the repeats
    # next to each other before the (hashing) unique, the same set of keys
    if len(key) > 1:
        key = key[np.append(True, key[1:] != key[:-1])]
    return np.unique(key)


def build_block_graph(eroded: np.ndarray, bbox: tuple[int, int, int, int]) -> BlockGraph:
    """Block graph (module doc) of ``eroded`` inside the half-open box ``(r0, r1, c0, c1)``."""
    r0, r1, c0, c1 = bbox
    win = eroded[r0:r1, c0:c1]
    f = block_size(win.size)
    nbr, nbc = -(-win.shape[0] // f), -(-win.shape[1] // f)
    # the blocks as a stack of f x f images; a structure that only links
    # cells within one image labels every block's pieces separately
    padded = np.zeros((nbr * f, nbc * f), dtype=bool)
    padded[: win.shape[0], : win.shape[1]] = win
    stack = np.ascontiguousarray(padded.reshape(nbr, f, nbc, f).transpose(0, 2, 1, 3))
    del padded
    structure = np.zeros((3, 3, 3), dtype=bool)
    structure[1] = True
    nblk = nbr * nbc
    flat = stack.reshape(nblk, f, f)
    most = ((f + 1) // 2) ** 2          # pieces in one block: one per 2 x 2 tile at most
    local = np.empty((nblk, f, f), dtype=np.uint8 if most <= 0xFF else np.uint16 if most <= 0xFFFF else np.int32)
    count = np.zeros(nblk, dtype=np.int64)
    step = max(1, _LABEL_CELLS // (f * f))
    for b0 in range(0, nblk, step):
        lab, _ = ndimage.label(flat[b0:b0 + step], structure=structure, output=np.int32)
        # labels are numbered in scan order and no label spans two blocks, so the
        # ids of block b are (max id before b, max id of b]
        top = np.maximum.accumulate(lab.reshape(len(lab), f * f).max(axis=1))
        before = np.concatenate([[0], top[:-1]])
        count[b0:b0 + len(lab)] = top - before
        lab -= before[:, None, None].astype(np.int32)
        np.maximum(lab, 0, out=lab)
        local[b0:b0 + len(lab)] = lab
        del lab
    del stack, flat
    k = int(count.sum())
    base = (np.cumsum(count) - count).reshape(nbr, nbc)
    L = local.reshape(nbr, nbc, f, f)

    def ids(loc: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Sub-component ids (0: none) of local numbers ``loc`` (..., f) of blocks with bases ``b``."""
        loc = loc.astype(np.int64)
        return np.where(loc > 0, loc + b[..., None], 0)

    # edges between sub-components of neighbouring blocks: only the blocks' border
    # cells can touch across a boundary (8-connectivity: side neighbours and corners)
    east, west = ids(L[:, :, :, f - 1], base), ids(L[:, :, :, 0], base)     # (nbr, nbc, f)
    north, south = ids(L[:, :, f - 1, :], base), ids(L[:, :, 0, :], base)
    keys = []
    right, left = east[:, :-1], west[:, 1:]                        # (nbr, nbc - 1, f)
    top, bottom = north[:-1], south[1:]                            # (nbr - 1, nbc, f)
    for d in (-1, 0, 1):
        lo, hi = max(0, -d), f - max(0, d)
        keys.append(_pairs(right[..., lo:hi], left[..., lo + d: hi + d], k))
        keys.append(_pairs(top[..., lo:hi], bottom[..., lo + d: hi + d], k))
    keys.append(_pairs(north[:-1, :-1, f - 1], south[1:, 1:, 0], k))        # up-right corner
    keys.append(_pairs(north[:-1, 1:, 0], south[1:, :-1, f - 1], k))        # up-left corner
    keys = [x for x in keys if x is not None]
    block_of = np.zeros((k + 1, 2), dtype=np.int64)
    if k:
        owner = np.repeat(np.arange(nblk), count)
        block_of[1:] = np.column_stack([owner // nbc, owner % nbc])
    if keys:
        key = np.unique(np.concatenate(keys))
        u, v = key // (k + 1), key % (k + 1)
        w = np.maximum(np.hypot(*(block_of[u] - block_of[v]).T) * f, 1e-6)
        graph = coo_matrix((np.concatenate([w, w]), (np.concatenate([u, v]), np.concatenate([v, u]))),
                           shape=(k + 1, k + 1)).tocsr()
    else:
        graph = csr_matrix((k + 1, k + 1))
    _, comp = connected_components(graph, directed=False)
    comp = comp.astype(np.int64)
    comp[0] = -1
    return BlockGraph(block=f, r0=r0, c0=c0, shape=win.shape, local=L, base=base, graph=graph,
                      component=comp, block_of=block_of)
