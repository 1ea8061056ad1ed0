"""What the companion knows of the field: the OGM's rows extruded to the
canopy height, the DEM terrain, and the obstacles added in flight.

A rangefinder hit at (x, y, z) (ENU, m) is a *known* feature when

- ``ground``: z <= terrain(x, y) + tolerance;
- ``row``: (x, y) lies within the tolerance of an occupied OGM cell and
  z <= terrain(x, y) + canopy height + tolerance (a row is a box from the
  ground to the canopy height over each occupied cell, as the SITL renders it);
- ``added``: (x, y) lies within the tolerance of an obstacle cell added by a
  re-route and z is at most its column's top + tolerance (``added_top``: the
  top of the obstacle it stands for, the upper face of the highest voxel the
  map holds there; +inf where unknown: then any height);

and *unknown* otherwise (an unknown OGM cell is not a known feature). The
tolerance is applied on the grid as a dilation of the occupied cells by the
disk of radius tolerance + one cell (the hit lies on a cell's face, so the
extra cell keeps a face hit inside), computed once.

For planning (re-routes) the map also carries the free space eroded by the
mission's safety margin (``companion.coverage.freespace``), updated locally
when an obstacle is added.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
from scipy import ndimage

from ..coverage.freespace import FreeSpace, dilate_runs, dilate_runs_banded, disk_half_widths, erode_free_space
from mavcore.maps.grid import ElevationModel, OccupancyGrid
from mavcore.maps.heightfield import HeightField
from mavcore.pyramid import project_pyramid

KNOWN_GROUND, KNOWN_ROW, KNOWN_ADDED, UNKNOWN = "ground", "row", "added", "unknown"
#: ``explains``: a ray enters a row within this distance (m) beyond the return ...
SURFACE_AHEAD_M = 0.1
#: ... and is outside it this far (m) before the return. Not less: a beam grazing
#: a row's face (a sensor looking along the corridor, 5-15 deg off the face) is
#: 1-3 cm deep in the row 0.1 m before its return once the range is rounded to
#: the centimetre of DISTANCE_SENSOR and noised, and 0.5 m back it is out.
SURFACE_BEHIND_M = 0.5
#: A return beside a row (within a cell of it) is the row when the beam was
#: outside the rows this far (m) before it.
GRAZE_BACK_M = 1.0
#: Steps of ``ground_in_view_m`` on uneven ground (each takes the tangent plane where the last one landed).
GROUND_IN_VIEW_STEPS = 5


@dataclass(frozen=True, eq=False)
class KnownMap:
    """The companion's map (module doc). Build with ``KnownMap.build``.

    Attributes
    ----------
    grid : OccupancyGrid
        The mission's OGM as loaded (never modified).
    dem : ElevationModel
    free : FreeSpace
        Free space eroded by the safety margin, with the added obstacles.
    canopy_height_m, tolerance_m : float
    known_rows : (rows, cols) bool
        Occupied cells dilated by the tolerance (grid array convention).
    added : (rows, cols) bool
        Cells of the obstacles added in flight (not dilated).
    known_added : (rows, cols) bool
        ``added`` dilated by the tolerance.
    height : HeightField
        Scalar terrain lookup.
    added_top : (rows, cols) float32
        Top (m, map z) of the column over each added cell (-inf where none is added,
        +inf where its top is unknown): the guard, the 3-D route search and the route
        check read the added obstacle as the same column (docs/replan.md "One picture").
    known_added_top : (rows, cols) float32
        ``added_top`` dilated (greatest) by the tolerance, as ``known_added``.
    """

    grid: OccupancyGrid
    dem: ElevationModel
    free: FreeSpace
    canopy_height_m: float
    tolerance_m: float
    known_rows: np.ndarray
    added: np.ndarray
    known_added: np.ndarray
    height: HeightField
    added_top: np.ndarray | None = None
    known_added_top: np.ndarray | None = None

    @classmethod
    def build(cls, grid: OccupancyGrid, dem: ElevationModel, free: FreeSpace,
              canopy_height_m: float, tolerance_m: float) -> "KnownMap":
        """Precompute the classification masks.

        Parameters
        ----------
        grid, dem : the mission's maps.
        free : FreeSpace
            The planner's eroded free space (``erode_free_space(grid, safety_margin_m)``;
            the plan's ``coverage.free_eroded`` is its ``eroded``).
        canopy_height_m : float
            Height of the rows above the terrain (m).
        tolerance_m : float
            Classification tolerance (m, >= 0).
        """
        widths = disk_half_widths(tolerance_m / grid.resolution_m + 1.0)
        # a band of rows at a time: the temporaries are a band's, not the whole grid's
        known_rows = dilate_runs_banded(np.asarray(grid.occupied, dtype=bool), widths, outside=False)
        # nothing added yet: a read-only view of one False (no memory; ``with_obstacle`` copies)
        empty = np.broadcast_to(np.zeros(1, dtype=bool), grid.shape)
        no_top = np.broadcast_to(np.full(1, -np.inf, dtype=np.float32), grid.shape)
        return cls(grid, dem, free, float(canopy_height_m), float(tolerance_m), known_rows,
                   empty, empty, HeightField(dem), no_top, no_top)

    @classmethod
    def from_mission(cls, mission, grid: OccupancyGrid, dem: ElevationModel,
                     free_eroded: np.ndarray | None = None) -> "KnownMap":
        """The map of a mission: its ``replan`` canopy height and tolerance, the free
        space eroded by its planning clearance, airframe radius + coverage safety margin
        (``companion.margins``; ``free_eroded``: the plan's ``coverage.free_eroded`` when
        at hand, else computed here)."""
        from ..margins import planning_clearance_m

        margin = planning_clearance_m(mission)
        if free_eroded is None:
            free = erode_free_space(grid, margin)
        else:
            free = FreeSpace(np.asarray(free_eroded, dtype=bool), grid.free & ~grid.occupied, grid.resolution_m,
                             margin + grid.resolution_m)
        return cls.build(grid, dem, free, mission.replan.canopy_height_m, mission.replan.known_tolerance_m)

    # --- scalar queries (per reading) --------------------------------------------------

    @cached_property
    def _cell_frame(self) -> tuple:
        """The grid's frame for ``cell_of``, once per map (it runs for every probe of every
        reading): origin, cos and sin of its yaw, resolution, shape."""
        g = self.grid
        rows, cols = g.shape
        return (g.origin_xy_m[0], g.origin_xy_m[1], math.cos(g.origin_yaw_rad), math.sin(g.origin_yaw_rad),
                g.resolution_m, rows, cols)

    def cell_of(self, x: float, y: float) -> tuple[int, int] | None:
        """(row, col) of the grid cell holding the ENU point (m); None off the grid."""
        ox, oy, c, s, res, rows, cols = self._cell_frame
        dx, dy = x - ox, y - oy
        col = math.floor((c * dx + s * dy) / res)
        row = math.floor((-s * dx + c * dy) / res)
        if 0 <= row < rows and 0 <= col < cols:
            return row, col
        return None

    def ground_z(self, x: float, y: float) -> float:
        """Terrain height (m) under (x, y) (clamped outside the DEM)."""
        return self.height(x, y)

    def ground_in_view_m(self, origin, axis, h_axis, v_axis, half_h_rad: float, half_v_rad: float) -> float:
        """Nearest distance (m) from ``origin`` to the terrain inside a beam's field of
        view: the pyramid of half angles ``half_h_rad`` about ``h_axis`` and
        ``half_v_rad`` about ``v_axis`` around ``axis`` (ENU unit vectors: the beam and
        the directions in which its fields open).

        A rangefinder returns the nearest surface anywhere in its field, so a return
        at or beyond this distance may be the ground (nothing beyond the nearest ground
        in view can be told from it). For a plane with upward normal n at height h
        above the origin's foot, the nearest point in the pyramid lies along the unit
        direction of the projection of -n onto it (``mavcore.pyramid``), at
        ``h / |that projection|``: exact for flat ground. On uneven ground the plane is
        the terrain's tangent plane where the last step landed, for a few steps.
        inf when the field of view does not reach the ground."""
        a, b = math.tan(half_h_rad), math.tan(half_v_rad)
        ox, oy, oz = origin
        x, y = ox, oy
        nx = ny = 0.0
        nz = 1.0
        t = math.inf
        for _ in range(GROUND_IN_VIEW_STEPS):
            zq = self.height(x, y)
            # -n in the sensor frame, projected onto the pyramid
            sx = -(axis[0] * nx + axis[1] * ny + axis[2] * nz)
            sy = -(h_axis[0] * nx + h_axis[1] * ny + h_axis[2] * nz)
            sz = -(v_axis[0] * nx + v_axis[1] * ny + v_axis[2] * nz)
            gx, gy, gz = project_pyramid(sx, sy, sz, a, b)
            g = math.sqrt(gx * gx + gy * gy + gz * gz)
            h = nx * (ox - x) + ny * (oy - y) + nz * (oz - zq)     # the origin's height above the plane
            if h <= 0.0:
                return 0.0
            if not g > 1e-12:
                return math.inf
            t_new = h / g
            ux = (axis[0] * gx + h_axis[0] * gy + v_axis[0] * gz) / g
            uy = (axis[1] * gx + h_axis[1] * gy + v_axis[1] * gz) / g
            if abs(t_new - t) < 1e-3:
                return t_new
            t = t_new
            x, y = ox + t * ux, oy + t * uy
            e = 0.5 * self.grid.resolution_m
            dzx = (self.height(x + e, y) - self.height(x - e, y)) / (2 * e)
            dzy = (self.height(x, y + e) - self.height(x, y - e)) / (2 * e)
            k = 1.0 / math.sqrt(dzx * dzx + dzy * dzy + 1.0)
            nx, ny, nz = -dzx * k, -dzy * k, k
        return t

    def classify(self, x: float, y: float, z: float) -> str:
        """``"ground"``, ``"row"``, ``"added"`` or ``"unknown"`` for a hit at (x, y, z) (module doc)."""
        ground = self.height(x, y)
        if z <= ground + self.tolerance_m:
            return KNOWN_GROUND
        cell = self.cell_of(x, y)
        if cell is not None:
            if self.known_added[cell] and z <= self.added_top_at(cell, dilated=True) + self.tolerance_m:
                return KNOWN_ADDED
            if self.known_rows[cell] and z <= ground + self.canopy_height_m + self.tolerance_m:
                return KNOWN_ROW
        return UNKNOWN

    def added_top_at(self, cell: tuple[int, int], dilated: bool = False) -> float:
        """Top (m) of the added column over ``cell`` (-inf: none; +inf: unknown; a map
        built without tops: +inf over every added cell)."""
        tops = self.known_added_top if dilated else self.added_top
        if tops is None:
            return math.inf if (self.known_added if dilated else self.added)[cell] else -math.inf
        return float(tops[cell])

    def is_known(self, x: float, y: float, z: float) -> bool:
        """True when the hit lies on a known feature (``classify`` is not ``"unknown"``)."""
        return self.classify(x, y, z) != UNKNOWN

    def _beside_row(self, x: float, y: float) -> bool:
        """An occupied cell is the point's cell or one of its eight neighbours."""
        cell = self.cell_of(x, y)
        if cell is None:
            return False
        r, c = cell
        return bool(self.grid.occupied[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2].any())

    def _in_row(self, x: float, y: float, z: float) -> bool:
        cell = self.cell_of(x, y)
        return cell is not None and bool(self.grid.occupied[cell]) and z <= self.height(x, y) + self.canopy_height_m

    def explains(self, origin, direction, distance_m: float) -> bool:
        """Is a return at ``distance_m`` along the unit ``direction`` from ``origin``
        (ENU m) the surface of a known feature?

        - the terrain: the hit is within the tolerance of the ground;
        - an added obstacle: the hit is within the tolerance of its cells;
        - a row: the ray *enters* it there: within ``SURFACE_AHEAD_M`` beyond
          the hit (probed at 0.2, 0.5 and 1 times it) it is inside an
          occupied cell below the canopy (or the hit is within half a cell
          of one: a ray that touches a row's corner), ``SURFACE_BEHIND_M``
          before the hit it is not. A return from an unknown obstacle whose
          beam would reach a row farther on is not explained (a wide beam
          always has a row somewhere in its field of view in a corridor), a
          beam grazing a row's face is.
        """
        ox, oy, oz = origin
        dx, dy, dz = direction
        d = float(distance_m)
        hx, hy, hz = ox + d * dx, oy + d * dy, oz + d * dz
        c = self.classify(hx, hy, hz)
        if c in (KNOWN_GROUND, KNOWN_ADDED):
            return True
        if c == KNOWN_ROW and self._beside_row(hx, hy):
            # Within a cell of a row's box: a beam that grazes a row's face or
            # clips its top edge returns a few centimetres off the face (the
            # range is rounded to the centimetre and noised, the pose is an
            # estimate), so its return is the row unless the beam ran inside
            # the row for ``GRAZE_BACK_M`` before it (then the row would have
            # answered earlier).
            b = max(d - GRAZE_BACK_M, 0.0)
            if not self._in_row(ox + b * dx, oy + b * dy, oz + b * dz):
                return True
        # inside a row just beyond the return (probed at a few depths: a ray that
        # clips a row's corner is inside for a few centimetres only) ...
        if not any(self._in_row(ox + a * dx, oy + a * dy, oz + a * dz)
                   for a in (d + 0.2 * SURFACE_AHEAD_M, d + 0.5 * SURFACE_AHEAD_M, d + SURFACE_AHEAD_M)):
            # ... or the hit touches a row's corner (within half a cell)
            e = 0.5 * self.grid.resolution_m
            if not any(self._in_row(hx + ex, hy + ey, hz) for ex, ey in ((e, e), (e, -e), (-e, e), (-e, -e))):
                return False
        b = max(d - SURFACE_BEHIND_M, 0.0)
        return not self._in_row(ox + b * dx, oy + b * dy, oz + b * dz)

    # --- obstacles added in flight -------------------------------------------------------

    def with_obstacle(self, points_xy_m: np.ndarray, keep_m: float | None = None,
                      tops_z_m: np.ndarray | None = None) -> "KnownMap":
        """A copy with the cells under ``points_xy_m`` ((k, 2), ENU m) occupied.

        The eroded free space loses every cell within ``keep_m`` (at least,
        and by default, the erosion threshold) of a new cell (the disk of
        ``erode_free_space``, computed in a window around the points), the
        classification masks gain the cells dilated by the tolerance. Points
        off the grid are ignored. ``tops_z_m`` ((k,) m, map z): the top of the
        column each point stands for; a cell's top is the greatest of its points'
        (None: unknown, +inf).
        """
        pts = np.asarray(points_xy_m, dtype=float).reshape(-1, 2)
        tops = np.full(len(pts), np.inf) if tops_z_m is None else np.asarray(tops_z_m, dtype=float).reshape(-1)
        on = [(c, float(t)) for c, t in ((self.cell_of(float(x), float(y)), t) for (x, y), t in zip(pts, tops))
              if c is not None]
        if not on:
            return self
        rc = np.array([c for c, _ in on])
        h = self.grid.resolution_m
        keep = max(self.free.threshold_m, keep_m if keep_m is not None else 0.0)
        erode_w = disk_half_widths(keep / h)
        known_w = disk_half_widths(self.tolerance_m / h + 1.0)
        k = int(math.ceil(keep / h)) + int(math.ceil(self.tolerance_m / h)) + 2
        rows, cols = self.grid.shape
        r0, r1 = max(0, rc[:, 0].min() - k), min(rows, rc[:, 0].max() + k + 1)
        c0, c1 = max(0, rc[:, 1].min() - k), min(cols, rc[:, 1].max() + k + 1)
        added = self.added.copy()
        added[rc[:, 0], rc[:, 1]] = True
        base = self.added_top if self.added_top is not None else np.where(self.added, np.inf, -np.inf)
        added_top = np.array(base, dtype=np.float32)
        np.maximum.at(added_top, (rc[:, 0], rc[:, 1]), np.array([t for _, t in on], dtype=np.float32))
        win = added[r0:r1, c0:c1]
        eroded = self.free.eroded.copy()
        eroded[r0:r1, c0:c1] &= ~dilate_runs(win, erode_w, outside=False)
        free_cells = self.free.free.copy()
        free_cells[rc[:, 0], rc[:, 1]] = False
        known_added = self.known_added.copy()
        known_added[r0:r1, c0:c1] |= dilate_runs(win, known_w, outside=False)
        known_top = np.array(self.known_added_top if self.known_added_top is not None
                             else np.where(self.known_added, np.inf, -np.inf), dtype=np.float32)
        disk = _disk(known_w)
        known_top[r0:r1, c0:c1] = np.maximum(known_top[r0:r1, c0:c1], ndimage.maximum_filter(
            added_top[r0:r1, c0:c1], footprint=disk, mode="constant", cval=-np.inf))
        free = FreeSpace(eroded=eroded, free=free_cells, resolution_m=self.free.resolution_m,
                         threshold_m=self.free.threshold_m)
        return replace(self, free=free, added=added, known_added=known_added, added_top=added_top,
                       known_added_top=known_top)


def _disk(half_widths: np.ndarray) -> np.ndarray:
    """The bool footprint of ``dilate_runs``'s set ``{(dr, dc): |dc| <= w[K + dr]}``
    (``disk_half_widths``: 2K + 1 entries, row offsets -K..K)."""
    w = np.asarray(half_widths, dtype=int)
    k = (len(w) - 1) // 2
    p = max(k, int(w.max()) if len(w) else 0, 0)
    out = np.zeros((2 * p + 1, 2 * p + 1), dtype=bool)
    for i, v in enumerate(w.tolist()):
        if v >= 0:
            out[p + i - k, p - v:p + v + 1] = True
    return out
