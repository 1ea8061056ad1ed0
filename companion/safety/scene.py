"""The known world the guard checks against (pure): terrain and vine rows as
distance fields over arrays of ENU points.

Terrain
    ``TerrainField``: the DEM's height under each point, bilinear between cell
    centres, clamped to the grid and NODATA filled with the nearest valid cell
    (the same terrain as ``mavcore.maps.heightfield.HeightField``, the SITL's
    and the replanner's, vectorised).
Rows
    ``RowField``: each occupied OGM cell is a box from the ground to the
    canopy height (``replan.canopy_height_m``), as the replanner's known map
    and the SITL render it. The distance from a point to the rows is exact
    for the nearest occupied cell: the horizontal distance ``r`` to that
    cell's square, and above the canopy ``sqrt(r^2 + (z - top)^2)``. The
    nearest cell of the point's cell is the one of a Euclidean distance
    transform with indices (``scipy.ndimage``), computed a tile of the grid
    at a time where a query reaches (``companion.safety.nearest_cells``: the
    same cells as the whole grid's transform, without its 180 MB table on a
    10 ha field); a point off the grid is measured to the nearest cell of the
    grid's edge cell.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mavcore.maps.heightfield import HeightField
from .nearest_cells import NearestCells


class TerrainField:
    """Terrain height (m, map z) under arrays of ENU points (module doc).

    Parameters
    ----------
    height : HeightField
        The filled DEM (``HeightField(dem)``; ``KnownMap.height``).
    """

    def __init__(self, height: HeightField) -> None:
        self._h = np.asarray(height.heights_m, dtype=float)
        self._x0, self._y0, self._cs = height._x0, height._y0, height._cs
        self.scalar = height
        h = self._h
        gx = float(np.abs(np.diff(h, axis=1)).max()) if h.shape[1] > 1 else 0.0
        gy = float(np.abs(np.diff(h, axis=0)).max()) if h.shape[0] > 1 else 0.0
        #: The steepest slope (m/m) the surface has anywhere: within a cell each partial
        #: derivative of the bilinear surface is a blend of its edges' differences over the
        #: cell size, and the clamped surface outside the grid is flatter still.
        self.max_slope = math.hypot(gx, gy) / self._cs

    def z(self, x, y) -> np.ndarray:
        """Terrain height (m) at (x, y) arrays (m), clamped bilinear."""
        h = self._h
        nr, nc = h.shape
        fx = np.clip((np.asarray(x, float) - self._x0) / self._cs, 0.0, nc - 1)
        fy = np.clip((np.asarray(y, float) - self._y0) / self._cs, 0.0, nr - 1)
        j = np.minimum(fx.astype(np.intp), max(nc - 2, 0))
        i = np.minimum(fy.astype(np.intp), max(nr - 2, 0))
        j1 = np.minimum(j + 1, nc - 1)
        i1 = np.minimum(i + 1, nr - 1)
        tx, ty = fx - j, fy - i
        a = h[i, j] + (h[i, j1] - h[i, j]) * tx
        b = h[i1, j] + (h[i1, j1] - h[i1, j]) * tx
        return a + (b - a) * ty


class RowField:
    """Distance (m) from ENU points to the vine rows extruded to the canopy (module doc).

    Parameters
    ----------
    grid : OccupancyGrid
        The mission's OGM (its occupied cells are the rows).
    terrain : TerrainField
    canopy_height_m : float
        Height of the rows above the terrain (m).
    """

    def __init__(self, grid, terrain: TerrainField, canopy_height_m: float) -> None:
        occ = np.asarray(grid.occupied, dtype=bool)
        self.res_m = float(grid.resolution_m)
        self._ox, self._oy = float(grid.origin_xy_m[0]), float(grid.origin_xy_m[1])
        self._c, self._s = math.cos(grid.origin_yaw_rad), math.sin(grid.origin_yaw_rad)
        self.terrain = terrain
        self.canopy_height_m = float(canopy_height_m)
        self._shape = occ.shape
        self.empty = not occ.any()
        self._near = None if self.empty else NearestCells(occ)

    def horizontal(self, x, y) -> np.ndarray:
        """Horizontal distance (m) from (x, y) arrays to the nearest row cell's square."""
        x = np.asarray(x, float)
        if self.empty:
            return np.full(x.shape, np.inf)
        dx, dy = x - self._ox, np.asarray(y, float) - self._oy
        gx = self._c * dx + self._s * dy
        gy = -self._s * dx + self._c * dy
        h = self.res_m
        rows, cols = self._shape
        r = np.clip(np.floor(gy / h).astype(np.intp), 0, rows - 1)
        c = np.clip(np.floor(gx / h).astype(np.intp), 0, cols - 1)
        rr, cc = self._near.gather(r, c)
        ex = np.maximum(np.maximum(cc * h - gx, gx - (cc + 1) * h), 0.0)
        ey = np.maximum(np.maximum(rr * h - gy, gy - (rr + 1) * h), 0.0)
        return np.hypot(ex, ey)

    def distance_one(self, x: float, y: float, z: float) -> float:
        """``distance`` of one point, in plain floats (the per-frame path)."""
        if self.empty:
            return math.inf
        dx, dy = x - self._ox, y - self._oy
        gx = self._c * dx + self._s * dy
        gy = -self._s * dx + self._c * dy
        h = self.res_m
        rows, cols = self._shape
        r = min(max(int(math.floor(gy / h)), 0), rows - 1)
        c = min(max(int(math.floor(gx / h)), 0), cols - 1)
        rr, cc = self._near.at(r, c)
        ex = max(cc * h - gx, gx - (cc + 1) * h, 0.0)
        ey = max(rr * h - gy, gy - (rr + 1) * h, 0.0)
        d = math.hypot(ex, ey)
        above = z - (self.terrain.scalar(x, y) + self.canopy_height_m)
        return math.hypot(d, above) if above > 0.0 else d

    def distance(self, points_enu_m: np.ndarray) -> np.ndarray:
        """(M,) distance (m) from (M, 3) ENU points to the rows' boxes (inf without rows)."""
        p = np.asarray(points_enu_m, float).reshape(-1, 3)
        r = self.horizontal(p[:, 0], p[:, 1])
        if self.empty:
            return r
        above = p[:, 2] - (self.terrain.z(p[:, 0], p[:, 1]) + self.canopy_height_m)
        return np.where(above > 0.0, np.hypot(r, np.maximum(above, 0.0)), r)


@dataclass(frozen=True, eq=False)
class SafetyScene:
    """The static world of the guard: ``terrain`` and ``rows`` (module doc)."""

    terrain: TerrainField
    rows: RowField

    @classmethod
    def from_known_map(cls, known) -> "SafetyScene":
        """The scene of a ``companion.replan.KnownMap`` (its grid, DEM and canopy height)."""
        terrain = TerrainField(known.height)
        return cls(terrain, RowField(known.grid, terrain, known.canopy_height_m))

    @classmethod
    def from_maps(cls, grid, dem, canopy_height_m: float) -> "SafetyScene":
        """The scene of an OGM and a DEM."""
        terrain = TerrainField(HeightField(dem))
        return cls(terrain, RowField(grid, terrain, canopy_height_m))
