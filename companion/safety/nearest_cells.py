"""The nearest occupied cell of each grid cell, a tile at a time (pure).

``scipy.ndimage.distance_transform_edt(~occupied, return_indices=True)`` gives,
for every cell, the occupied cell whose centre is nearest to its centre. On a
10 ha field at 0.1 m (22 M cells) that table is 180 MB held as int32 and
~540 MB while scipy builds it. The guard only asks about cells near the
vehicle, so ``NearestCells`` computes the same table for one tile of
``tile`` x ``tile`` cells when a query first reaches it: the transform of the
tile grown by a halo of ``halo`` cells on every side (clipped to the grid),
the halo doubled until every cell of the tile is nearer to its nearest
occupied cell in that window than to any cell outside it (squared distance
below ``(halo + 1)^2``; a window clipped to the whole grid always is). Then
the cells tied for nearest are all inside the window, and the transform of
the window picks the same one of them as the transform of the whole grid
(checked cell by cell against it, on synthetic grids with ties and on the
10 ha corpus field, in tests/test_safety_nearest_cells.py). The last
``cache_tiles`` tiles used are kept.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
from scipy import ndimage

#: Tile edge (cells): 6.4 m at 0.1 m; a tile's table is 32 KB.
TILE_CELLS = 64
#: First halo (cells) around a tile; doubled until it holds every nearest cell.
HALO_CELLS = 32
#: Tiles kept (8 MB at 64 x 64).
CACHE_TILES = 256


class NearestCells:
    """Nearest occupied cell (row, col) of any cell of ``occupied`` (module doc).

    Parameters
    ----------
    occupied : (rows, cols) bool
        Held by reference, never modified; at least one cell must be True.
    tile, halo, cache_tiles : int
        Tile edge and first halo (cells), tiles kept.
    """

    def __init__(self, occupied: np.ndarray, tile: int = TILE_CELLS, halo: int = HALO_CELLS,
                 cache_tiles: int = CACHE_TILES) -> None:
        self._occ = np.asarray(occupied, dtype=bool)
        if not self._occ.any():
            raise ValueError("NearestCells: no occupied cell")
        self.shape = self._occ.shape
        self._tile, self._halo, self._keep = int(tile), int(halo), max(1, int(cache_tiles))
        self._tiles: OrderedDict[tuple[int, int], np.ndarray] = OrderedDict()
        self._ntc = -(-self.shape[1] // self._tile)

    def tile(self, ti: int, tj: int) -> np.ndarray:
        """(2, h, w) int32 (row, col) of the nearest occupied cell of each cell of tile (ti, tj)."""
        key = (ti, tj)
        t = self._tiles.get(key)
        if t is not None:
            self._tiles.move_to_end(key)
            return t
        t = self._compute(ti, tj)
        self._tiles[key] = t
        if len(self._tiles) > self._keep:
            self._tiles.popitem(last=False)
        return t

    def _compute(self, ti: int, tj: int) -> np.ndarray:
        rows, cols = self.shape
        T = self._tile
        r0, c0 = ti * T, tj * T
        r1, c1 = min(rows, r0 + T), min(cols, c0 + T)
        rr, cc = np.ogrid[r0:r1, c0:c1]
        halo = self._halo
        while True:
            a0, a1, b0, b1 = max(0, r0 - halo), min(rows, r1 + halo), max(0, c0 - halo), min(cols, c1 + halo)
            whole = (a0, a1, b0, b1) == (0, rows, 0, cols)
            win = self._occ[a0:a1, b0:b1]
            if win.any():
                idx = ndimage.distance_transform_edt(~win, return_distances=False, return_indices=True)
                near = idx[:, r0 - a0:r1 - a0, c0 - b0:c1 - b0].astype(np.int32)
                del idx
                near[0] += a0
                near[1] += b0
                if whole:
                    return near
                d2 = (near[0] - rr).astype(np.int64) ** 2 + (near[1] - cc).astype(np.int64) ** 2
                if int(d2.max()) < (halo + 1) ** 2:
                    return near
            halo *= 2

    def at(self, r: int, c: int) -> tuple[int, int]:
        """(row, col) of the nearest occupied cell of cell (r, c) (inside the grid)."""
        T = self._tile
        t = self.tile(r // T, c // T)
        i, j = r % T, c % T
        return int(t[0, i, j]), int(t[1, i, j])

    def gather(self, r: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``at`` of arrays of cells (int, inside the grid, same shape): (rows, cols) int arrays."""
        r = np.asarray(r, dtype=np.intp)
        c = np.asarray(c, dtype=np.intp)
        out_r = np.empty(r.shape, dtype=np.intp)
        out_c = np.empty(r.shape, dtype=np.intp)
        T = self._tile
        key = (r // T) * self._ntc + c // T
        for k in np.unique(key).tolist():
            on = key == k
            ti, tj = divmod(k, self._ntc)
            t = self.tile(ti, tj)
            i, j = r[on] - ti * T, c[on] - tj * T
            out_r[on] = t[0, i, j]
            out_c[on] = t[1, i, j]
        return out_r, out_c
