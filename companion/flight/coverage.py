"""How much of the planned coverage path a flight actually flew.

The planned path is sampled every ``spacing_m``; a sample counts as flown
once the vehicle passes within ``radius_m`` of it horizontally. A spatial
hash (cells of ``radius_m``) makes each visit O(1); memory is the number of
samples (the path's length / spacing), not the flight's length.
"""

from __future__ import annotations

import math

import numpy as np


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
        self.points = np.concatenate(pts)
        self.radius_m = float(radius_m)
        self.flown = np.zeros(len(self.points), dtype=bool)
        self._cell = self.radius_m
        keys = np.floor(self.points / self._cell).astype(np.int64)
        self._grid: dict[tuple[int, int], list[int]] = {}
        for i, (kx, ky) in enumerate(keys.tolist()):
            self._grid.setdefault((kx, ky), []).append(i)
        self._r2 = self.radius_m ** 2
        self._pts = self.points.tolist()

    def visit(self, x_m: float, y_m: float) -> None:
        """The vehicle is at (x, y) (ENU m)."""
        cx, cy = math.floor(x_m / self._cell), math.floor(y_m / self._cell)
        g, pts, flown, r2 = self._grid, self._pts, self.flown, self._r2
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                idx = g.get((cx + dx, cy + dy))
                if idx is None:
                    continue
                for i in idx:
                    px, py = pts[i]
                    if (px - x_m) ** 2 + (py - y_m) ** 2 <= r2:
                        flown[i] = True

    def fraction(self) -> float:
        return float(np.count_nonzero(self.flown)) / len(self.flown)
