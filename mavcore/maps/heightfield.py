"""Scalar terrain-height lookup for per-reading use (plain floats, no arrays).

``ElevationModel.height_at`` is vectorised and strict (an uncovered point is
an error): right for planning. A perception step asks one point at a time
and must answer for any point a rangefinder can hit, so ``HeightField``
fills NODATA cells with the nearest valid cell and clamps points outside the
grid to its edge (the same terrain the bundled SITL renders), bilinear
between cell centres like ``ElevationModel``.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .grid import ElevationModel


class HeightField:
    """Terrain height (m, map z) at (x, y) ENU map-frame points, one at a time.

    Parameters
    ----------
    dem : ElevationModel
        At least one valid (finite) cell.
    """

    def __init__(self, dem: ElevationModel) -> None:
        h = np.asarray(dem.heights_m, dtype=float)
        bad = ~np.isfinite(h)
        if bad.all():
            raise ValueError(f"{dem.source}: DEM has no valid cell")
        if bad.any():
            idx = ndimage.distance_transform_edt(bad, return_distances=False, return_indices=True)
            h = h[tuple(idx)]
        #: The filled heights (rows, cols), m.
        self.heights_m = h
        self._h = h.tolist()
        self._x0, self._y0, self._cs = float(dem.x0_m), float(dem.y0_m), float(dem.cellsize_m)
        self._nr, self._nc = h.shape

    def __call__(self, x: float, y: float) -> float:
        """Bilinear height (m) at (x, y) (m), clamped to the grid's cell centres."""
        fx = (x - self._x0) / self._cs
        fy = (y - self._y0) / self._cs
        nc1, nr1 = self._nc - 1, self._nr - 1
        fx = 0.0 if fx < 0.0 else (nc1 if fx > nc1 else fx)
        fy = 0.0 if fy < 0.0 else (nr1 if fy > nr1 else fy)
        j = min(int(fx), max(nc1 - 1, 0))
        i = min(int(fy), max(nr1 - 1, 0))
        j1 = j + 1 if nc1 > 0 else j
        i1 = i + 1 if nr1 > 0 else i
        tx, ty = fx - j, fy - i
        r0, r1 = self._h[i], self._h[i1]
        a = r0[j] + (r0[j1] - r0[j]) * tx
        b = r1[j] + (r1[j1] - r1[j]) * tx
        return a + (b - a) * ty
