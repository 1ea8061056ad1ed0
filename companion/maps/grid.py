"""In-memory map types shared by the planner and the SITL.

Array convention (both types): ``[row, col]`` with **row 0 the southernmost
row** (the loaders flip image/ASCII-grid order, whose first row is north),
column 0 the westernmost, so ``row`` grows with the map's y (north) and
``col`` with x (east). World coordinates are the map's local metric ENU frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
    """

    occupied: np.ndarray
    free: np.ndarray
    resolution_m: float
    origin_xy_m: tuple[float, float] = (0.0, 0.0)
    origin_yaw_rad: float = 0.0
    source: str = "<memory>"

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
