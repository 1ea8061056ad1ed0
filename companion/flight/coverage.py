"""How much of the planned coverage path a flight actually flew.

The planned path is sampled every ``spacing_m``; a sample counts as flown
once the vehicle passes within ``radius_m`` of it horizontally. A spatial
hash (cells of ``radius_m``) makes each visit O(1); memory is the number of
samples (the path's length / spacing), not the flight's length.
"""

from __future__ import annotations

import math

import numpy as np

#: Cell keys are ``kx * _KEY_STRIDE + ky`` (fields up to ~1e9 cells a side).
_KEY_STRIDE = 1 << 31


class PathCoverage:
    """Flown fraction of a 2D path.

    Parameters
    ----------
    path_xy_m : (N, 2) array
        The planned coverage path (ENU m), as flown in order.
    spacing_m : float
        Sample spacing along the path (m).
    radius_m : float
        A sample is flown when the vehicle passes within this horizontal
        distance (m).
    """

    def __init__(self, path_xy_m, spacing_m: float = 0.5, radius_m: float = 0.5) -> None:
        P = np.asarray(path_xy_m, dtype=float).reshape(-1, 2)
        if P.shape[0] == 0:
            raise ValueError("empty path")
        pts = [P[:1]]
        for a, b in zip(P[:-1], P[1:]):
            L = float(np.hypot(*(b - a)))
            n = max(1, int(math.ceil(L / spacing_m)))
            s = np.arange(1, n + 1) / n
            pts.append(a + s[:, None] * (b - a))
        pts = np.concatenate(pts)
        self.radius_m = float(radius_m)
        self._cell = self.radius_m
        # Points sorted by grid cell; each cell's points are one slice.
        keys = np.floor(pts / self._cell).astype(np.int64)
        k1 = keys[:, 0] * _KEY_STRIDE + keys[:, 1]
        order = np.argsort(k1, kind="stable")
        self.points = pts[order]
        self._x = np.ascontiguousarray(self.points[:, 0])
        self._y = np.ascontiguousarray(self.points[:, 1])
        k1 = k1[order]
        starts = np.flatnonzero(np.r_[True, k1[1:] != k1[:-1]])
        ends = np.r_[starts[1:], len(k1)]
        # per cell: the (index, x, y) of its points not flown yet, as Python floats (a visit
        # looks at a few points: plain floats beat numpy slices there)
        self._todo = {int(k): [(j, float(self._x[j]), float(self._y[j])) for j in range(a, b)]
                      for k, a, b in zip(k1[starts].tolist(), starts.tolist(), ends.tolist())}
        self.flown = np.zeros(len(self.points), dtype=bool)
        self._r2 = self.radius_m ** 2

    def visit(self, x_m: float, y_m: float) -> None:
        """The vehicle is at (x, y) (ENU m)."""
        cx, cy = math.floor(x_m / self._cell), math.floor(y_m / self._cell)
        todo, r2 = self._todo, self._r2
        for dx in (-1, 0, 1):
            base = (cx + dx) * _KEY_STRIDE + cy
            for dy in (-1, 0, 1):
                pts = todo.get(base + dy)
                if not pts:
                    continue
                left = []
                for p in pts:
                    ex, ey = p[1] - x_m, p[2] - y_m
                    if ex * ex + ey * ey <= r2:
                        self.flown[p[0]] = True
                    else:
                        left.append(p)
                if len(left) < len(pts):
                    todo[base + dy] = left

    def fraction(self) -> float:
        return float(np.count_nonzero(self.flown)) / len(self.flown)
