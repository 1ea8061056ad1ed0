"""Free space eroded by the safety margin (ISOA's admissible region).

Works in the grid's own metric frame G: ``gx`` east along the columns, ``gy``
north along the rows, metres from the lower-left corner of cell [0, 0]
(cell ``[r, c]`` covers ``gx in [c h, (c+1) h)``, ``gy in [r h, (r+1) h)``).
G equals the world ENU frame shifted by the map origin and rotated by the
map's origin yaw; :func:`grid_to_world` converts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..maps.grid import OccupancyGrid


@dataclass(frozen=True, eq=False)
class FreeSpace:
    """Eroded free space and clearance of an occupancy grid.

    Attributes
    ----------
    eroded : (rows, cols) bool
        Cells whose centre is at least ``threshold_m`` from the centre of any
        non-free cell (occupied, unknown, or outside the map).
    clearance_m : (rows, cols) float32
        Distance (m) from each cell centre to the nearest non-free cell centre
        (0 on non-free cells).
    resolution_m : float
    threshold_m : float
        ``safety_margin_m + resolution_m``: the extra cell is the slack that
        keeps every point of a path sampled at half-cell steps (each point
        within ``0.71 h + 0.25 h < h`` of an eroded cell centre) at least the
        safety margin from every non-free cell centre.
    """

    eroded: np.ndarray
    clearance_m: np.ndarray
    resolution_m: float
    threshold_m: float

    def contains(self, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
        """True where the points (G frame, m) fall in an eroded cell; False off the map."""
        return lookup(self.eroded, self.resolution_m, gx, gy)


def lookup(mask: np.ndarray, cell_m: float, gx, gy) -> np.ndarray:
    """Nearest-cell lookup of a bool mask at G-frame points (m); False off the map."""
    c = np.floor(np.asarray(gx) / cell_m).astype(np.int64)
    r = np.floor(np.asarray(gy) / cell_m).astype(np.int64)
    rows, cols = mask.shape
    ok = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
    out = np.zeros(np.shape(ok), dtype=bool)
    out[ok] = mask[r[ok], c[ok]]
    return out


def erode_free_space(grid: OccupancyGrid, safety_margin_m: float) -> FreeSpace:
    """Erode the free cells of ``grid`` by ``safety_margin_m`` (one exact EDT).

    Unknown cells and the outside of the map are not free (the grid is padded
    by one non-free cell so the map border counts as an obstacle).
    """
    h = float(grid.resolution_m)
    free = np.zeros((grid.shape[0] + 2, grid.shape[1] + 2), dtype=bool)
    free[1:-1, 1:-1] = grid.free & ~grid.occupied
    clearance = ndimage.distance_transform_edt(free)[1:-1, 1:-1].astype(np.float32) * np.float32(h)
    threshold = float(safety_margin_m) + h
    return FreeSpace(eroded=clearance >= threshold, clearance_m=clearance,
                     resolution_m=h, threshold_m=threshold)


def grid_to_world(grid: OccupancyGrid, gxy: np.ndarray) -> np.ndarray:
    """(..., 2) G-frame points (m) -> (..., 2) world ENU points (m)."""
    gxy = np.asarray(gxy, dtype=float)
    c, s = np.cos(grid.origin_yaw_rad), np.sin(grid.origin_yaw_rad)
    x = grid.origin_xy_m[0] + c * gxy[..., 0] - s * gxy[..., 1]
    y = grid.origin_xy_m[1] + s * gxy[..., 0] + c * gxy[..., 1]
    return np.stack([x, y], axis=-1)


def world_to_grid(grid: OccupancyGrid, xy: np.ndarray) -> np.ndarray:
    """(..., 2) world ENU points (m) -> (..., 2) G-frame points (m)."""
    xy = np.asarray(xy, dtype=float)
    dx = xy[..., 0] - grid.origin_xy_m[0]
    dy = xy[..., 1] - grid.origin_xy_m[1]
    c, s = np.cos(grid.origin_yaw_rad), np.sin(grid.origin_yaw_rad)
    return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)
