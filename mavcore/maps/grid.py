"""In-memory map types shared by the planner and the SITL.

Array convention (both types): ``[row, col]`` with **row 0 the southernmost
row** (the loaders flip image/ASCII-grid order, whose first row is north),
column 0 the westernmost, so ``row`` grows with the map's y (north) and
``col`` with x (east). World coordinates are the map's local metric ENU frame.
"""

from __future__ import annotations

import math

from dataclasses import dataclass

import numpy as np

from ..errors import MapError


def mask_centroid_rc(mask: np.ndarray) -> tuple[float, float]:
    """Mean (row, column) index of the True cells of a 2-D mask (nan if there are none).

    From the row and column marginals: integer sums, so exactly the mean of
    ``np.nonzero(mask)``, without index arrays over the whole mask.
    """
    n = np.count_nonzero(mask)
    if n == 0:
        return float("nan"), float("nan")
    return (float(np.arange(mask.shape[0]) @ np.count_nonzero(mask, axis=1)) / n,
            float(np.arange(mask.shape[1]) @ np.count_nonzero(mask, axis=0)) / n)


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """Trinary occupancy grid (ROS map_server semantics).

    Attributes
    ----------
    occupied, free : (rows, cols) bool arrays
        A cell is occupied, free, or unknown (neither). Unknown is not free.
    resolution_m : float
        Cell edge (m).
    origin_xy_m : (2,) tuple
        World pose of the lower-left corner of cell [0, 0] (map_server ``origin``).
    origin_yaw_rad : float
        Rotation of the grid about z (map_server ``origin[2]``).
    source : str
        File the grid came from (for messages).
    warnings : tuple of str
        What the loader ignored (unknown map YAML keys, ...), one line each.
    """

    occupied: np.ndarray
    free: np.ndarray
    resolution_m: float
    origin_xy_m: tuple[float, float] = (0.0, 0.0)
    origin_yaw_rad: float = 0.0
    source: str = "<memory>"
    warnings: tuple[str, ...] = ()

    @property
    def shape(self) -> tuple[int, int]:
        return self.occupied.shape

    @property
    def unknown(self) -> np.ndarray:
        return ~(self.occupied | self.free)

    def cell_to_world(self, rows, cols):
        """Cell-centre world coordinates (m) of (fractional) indices; arrays broadcast."""
        gx = (np.asarray(cols, dtype=float) + 0.5) * self.resolution_m
        gy = (np.asarray(rows, dtype=float) + 0.5) * self.resolution_m
        c, s = np.cos(self.origin_yaw_rad), np.sin(self.origin_yaw_rad)
        return self.origin_xy_m[0] + c * gx - s * gy, self.origin_xy_m[1] + s * gx + c * gy

    def world_to_cell(self, x, y):
        """World (m) -> fractional (row, col) such that the cell centre is integral."""
        dx = np.asarray(x, dtype=float) - self.origin_xy_m[0]
        dy = np.asarray(y, dtype=float) - self.origin_xy_m[1]
        c, s = np.cos(self.origin_yaw_rad), np.sin(self.origin_yaw_rad)
        gx = c * dx + s * dy
        gy = -s * dx + c * dy
        return gy / self.resolution_m - 0.5, gx / self.resolution_m - 0.5


@dataclass(frozen=True, eq=False)
class ElevationModel:
    """Terrain height grid (ESRI ASCII grid semantics), bilinear between cell centres.

    Attributes
    ----------
    heights_m : (rows, cols) float array
        Terrain height (m, same vertical datum as the mission home alt is
        *not* assumed: heights are relative to the map frame's z = 0). NaN
        where the file had NODATA.
    x0_m, y0_m : float
        World coordinates of the centre of cell [0, 0] (the south-west cell).
    cellsize_m : float
    source : str
    """

    heights_m: np.ndarray
    x0_m: float
    y0_m: float
    cellsize_m: float
    source: str = "<memory>"

    @property
    def shape(self) -> tuple[int, int]:
        return self.heights_m.shape

    @property
    def extent_m(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) of the area the file covers: the outer
        cell edges, half a cell beyond the outermost cell centres."""
        rows, cols = self.heights_m.shape
        h = 0.5 * self.cellsize_m
        return (self.x0_m - h, self.x0_m + (cols - 1) * self.cellsize_m + h,
                self.y0_m - h, self.y0_m + (rows - 1) * self.cellsize_m + h)

    def _interp(self, x, y):
        """Bilinear interpolation; returns (z, ok) with ok False outside or on NODATA.

        Between cell centres this is the usual bilinear patch. In the outer
        half cell (between the last centre and the grid edge, still inside
        the file's extent) the edge patch is extended linearly, so a plane is
        reproduced exactly everywhere in the extent. A NODATA cell that gets
        a non-zero weight makes the point not covered.
        """
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        x, y = np.broadcast_arrays(x, y)
        z_grid = self.heights_m
        rows, cols = z_grid.shape
        x_min, x_max, y_min, y_max = self.extent_m
        tol = 1e-9 * max(1.0, self.cellsize_m)
        inside = (x >= x_min - tol) & (x <= x_max + tol) & (y >= y_min - tol) & (y <= y_max + tol)
        inside &= np.isfinite(x) & np.isfinite(y)
        fc = np.where(inside, (x - self.x0_m) / self.cellsize_m, 0.0)
        fr = np.where(inside, (y - self.y0_m) / self.cellsize_m, 0.0)

        def axis(f, n):
            if n == 1:
                i0 = np.zeros(f.shape, dtype=np.intp)
                return i0, i0, np.zeros(f.shape)
            i0 = np.clip(np.floor(f).astype(np.intp), 0, n - 2)
            return i0, i0 + 1, f - i0

        c0, c1, tx = axis(fc, cols)
        r0, r1, ty = axis(fr, rows)
        w = ((1 - ty) * (1 - tx), (1 - ty) * tx, ty * (1 - tx), ty * tx)
        v = (z_grid[r0, c0], z_grid[r0, c1], z_grid[r1, c0], z_grid[r1, c1])
        z = np.zeros(x.shape)
        ok = inside.copy()
        for wi, vi in zip(w, v):
            nodata = np.isnan(vi)
            if not nodata.any():        # the usual case: no NODATA among these corners
                z += wi * vi
                continue
            ok &= ~(nodata & (wi != 0.0))
            z += wi * np.where(nodata, 0.0, vi)
        return z, ok

    def height_one(self, x: float, y: float) -> float:
        """``float(height_at(x, y))`` of one point in plain floats: the same operations in
        the same order (so the same number, bit for bit), ~20x cheaper than the arrays for
        a per-frame query. Points outside the extent, non-finite ones and those whose
        corners hold NODATA take the array path (and its error)."""
        x, y = float(x), float(y)
        x_min, x_max, y_min, y_max = self.extent_m
        tol = 1e-9 * max(1.0, self.cellsize_m)
        if not (x_min - tol <= x <= x_max + tol and y_min - tol <= y <= y_max + tol):
            return float(self.height_at(x, y))
        rows, cols = self.heights_m.shape
        fc = (x - self.x0_m) / self.cellsize_m
        fr = (y - self.y0_m) / self.cellsize_m
        c0, c1, tx = _axis_one(fc, cols)
        r0, r1, ty = _axis_one(fr, rows)
        z_grid = self.heights_m
        v0, v1, v2, v3 = (float(z_grid[r0, c0]), float(z_grid[r0, c1]), float(z_grid[r1, c0]),
                          float(z_grid[r1, c1]))
        if v0 != v0 or v1 != v1 or v2 != v2 or v3 != v3:      # NODATA among the corners
            return float(self.height_at(x, y))
        z = 0.0
        z += (1 - ty) * (1 - tx) * v0
        z += (1 - ty) * tx * v1
        z += ty * (1 - tx) * v2
        z += ty * tx * v3
        return z

    def covers(self, x, y) -> np.ndarray:
        """True where ``height_at`` is defined: inside the extent, no NODATA used.

        Parameters
        ----------
        x, y : array_like (broadcast together)
            ENU map-frame coordinates (m).

        Returns
        -------
        bool ndarray of the broadcast shape.
        """
        return self._interp(x, y)[1]

    def height_or(self, x, y, fill: float) -> np.ndarray:
        """``height_at`` where ``covers``, ``fill`` elsewhere, from one interpolation (each
        point on its own: ``height_at(x[ok], y[ok])``'s numbers, bit for bit)."""
        z, ok = self._interp(x, y)
        return np.where(ok, z, fill)

    def height_at(self, x, y) -> np.ndarray:
        """Terrain height (m, map z) at ENU map-frame points, bilinear between cell centres.

        Parameters
        ----------
        x, y : array_like (broadcast together)
            ENU map-frame coordinates (m).

        Returns
        -------
        float ndarray of the broadcast shape.

        Raises
        ------
        MapError
            Naming the DEM file, if any point is outside the DEM's extent or
            its interpolation touches a NODATA cell.
        """
        z, ok = self._interp(x, y)
        if not np.all(ok):
            xb, yb = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
            bad = np.flatnonzero(~ok.ravel())
            i = bad[0]
            x_min, x_max, y_min, y_max = self.extent_m
            raise MapError(self.source, f"{bad.size} query point(s) not covered by the DEM "
                           f"(first at x={xb.ravel()[i]:.2f}, y={yb.ravel()[i]:.2f} m; DEM covers "
                           f"x {x_min:.2f}..{x_max:.2f}, y {y_min:.2f}..{y_max:.2f} m, NODATA excluded)")
        return z


def _axis_one(f: float, n: int) -> tuple[int, int, float]:
    """One point's (i0, i1, fraction) along an axis of n cell centres (``_interp``'s ``axis``)."""
    if n == 1:
        return 0, 0, 0.0
    i0 = min(max(math.floor(f), 0), n - 2)
    return i0, i0 + 1, f - i0
