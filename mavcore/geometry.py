"""True clearance of the vehicle: distances from a point (the vehicle's
centre) to the solids of a vineyard scene, world ENU, metres.

Pure: arrays and floats in, floats and named results out. The SITL's
collision check (``sitl.collision``) and the companion's flight report use
the same functions, so "the vehicle crashed" and "the closest approach was
x m" are measured on one geometry.

The scene (issue 8)
-------------------
- **unknown obstacles** (the mission's ``sim.obstacles``): vertical capped
  cylinders and boxes yawed about z, standing on the terrain under their
  centre (base = terrain height there, top = base + height);
- **vine rows**: the occupancy grid's occupied cells, each a box over its
  cell from the terrain height at the cell centre up to the canopy height
  above it (``ExtrudedCells``);
- **terrain**: the DEM height field.

The vehicle is a sphere of radius ``r`` about its centre of mass (arm length
plus propeller radius); its clearance to a solid is the signed distance of
the centre to the solid minus ``r`` (negative: penetration).

Signed distances are exact for the cylinder and the box (inside: minus the
distance to the nearest face), exact for the union of cells outside it
(inside it, some value <= 0: the least of the cells' own signed distances,
not the depth below the union's surface), and for the terrain the
distance to the tangent plane of the height field under the point,
``(z - h(x, y)) / sqrt(1 + |grad h|^2)``: exact over a planar patch, a
first-order approximation over a curved one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Union

import numpy as np
from scipy import ndimage

from .maps.grid import OccupancyGrid
from .mission.sim import ObstacleConfig

HeightFn = Callable[[float, float], float]

#: Half-step (m) of the central differences giving the terrain gradient.
_GRAD_STEP_M = 0.01


# --- primitive solids ---------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Cylinder:
    """Vertical capped cylinder: axis through (x_m, y_m), z in [base_z_m, top_z_m]."""

    x_m: float
    y_m: float
    base_z_m: float
    top_z_m: float
    radius_m: float

    def signed_distance_m(self, px: float, py: float, pz: float) -> float:
        """Signed distance (m) from the point (ENU) to the cylinder surface."""
        dr = math.hypot(px - self.x_m, py - self.y_m) - self.radius_m
        dz = max(self.base_z_m - pz, pz - self.top_z_m)
        if dr <= 0.0 and dz <= 0.0:
            return max(dr, dz)
        return math.hypot(max(dr, 0.0), max(dz, 0.0))


@dataclass(frozen=True, slots=True)
class Box:
    """Box yawed about z: centre (x_m, y_m), half sizes along its own axes,
    z in [base_z_m, top_z_m]; ``yaw_rad`` from ENU east, counter-clockwise."""

    x_m: float
    y_m: float
    base_z_m: float
    top_z_m: float
    half_x_m: float
    half_y_m: float
    yaw_rad: float = 0.0

    def signed_distance_m(self, px: float, py: float, pz: float) -> float:
        """Signed distance (m) from the point (ENU) to the box surface."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        ex, ey = px - self.x_m, py - self.y_m
        qx = abs(c * ex + s * ey) - self.half_x_m
        qy = abs(-s * ex + c * ey) - self.half_y_m
        qz = max(self.base_z_m - pz, pz - self.top_z_m)
        if qx <= 0.0 and qy <= 0.0 and qz <= 0.0:
            return max(qx, qy, qz)
        ox, oy, oz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
        return math.sqrt(ox * ox + oy * oy + oz * oz)


Solid = Union[Cylinder, Box]


def obstacle_solids(obstacles: tuple[ObstacleConfig, ...], height: HeightFn) -> tuple[Solid, ...]:
    """The mission's obstacles as solids standing on the terrain under their centre.

    Parameters
    ----------
    obstacles : tuple of ObstacleConfig
        ``sim.obstacles`` (ENU metres on the map frame).
    height : callable (x, y) -> z
        Terrain height (m, ENU).
    """
    out: list[Solid] = []
    for ob in obstacles:
        base = float(height(float(ob.x), float(ob.y)))
        if ob.type == "cylinder":
            out.append(Cylinder(float(ob.x), float(ob.y), base, base + float(ob.height), float(ob.radius)))
        else:
            out.append(Box(float(ob.x), float(ob.y), base, base + float(ob.height), 0.5 * float(ob.size_x),
                           0.5 * float(ob.size_y), math.radians(ob.yaw_deg)))
    return tuple(out)


# --- vine rows: occupied cells extruded ------------------------------------------


#: cells per row band of the distance computations (bounded temporaries)
_ROWS_CELLS = 1 << 20


def clearance_sq_cells(occupied: np.ndarray) -> np.ndarray:
    """(rows, cols) int32 (int64 for grids of 46 341 cells across or more): squared Euclidean distance (cells^2) from each cell's
    centre to the nearest occupied cell's centre (0 on them).

    ``scipy.ndimage.distance_transform_edt(~occupied)`` is the square root of
    exactly these integers (it sums the squared offsets of its feature
    transform in float64, exact below 2^53, then takes the correctly rounded
    square root), so ``sqrt(float(d2))`` gives its values bit for bit. It holds
    the feature transform (8 bytes a cell) and this result, instead of the
    ~40 bytes a cell of its float64 temporaries (0.9 GB for a 10 ha map at 5 cm).
    """
    occ = np.asarray(occupied, dtype=bool)
    ft = ndimage.distance_transform_edt(~occ, return_distances=False, return_indices=True)
    nr, nc = occ.shape
    out = np.empty(occ.shape, dtype=np.int32 if nr * nr + nc * nc < 2**31 else np.int64)
    cols = np.arange(nc, dtype=np.int64)
    step = max(1, _ROWS_CELLS // max(1, nc))
    for r0 in range(0, nr, step):
        r1 = min(nr, r0 + step)
        dr = ft[0, r0:r1].astype(np.int64) - np.arange(r0, r1, dtype=np.int64)[:, None]
        dc = ft[1, r0:r1].astype(np.int64) - cols
        out[r0:r1] = dr * dr + dc * dc
    return out


#: the largest squared clearance (cells^2) a capped table holds (uint16); a cell
#: further than sqrt(65535) ~ 256 cells from every occupied cell reads this
CLEARANCE_SQ_CAP = 65535
_CAP_ROWS = 256     # 256^2 + 1 > the cap: an occupied cell more rows away is beyond it


def clearance_sq_cells_capped(occupied: np.ndarray) -> np.ndarray:
    """(rows, cols) uint16: ``min(clearance_sq_cells(occupied), CLEARANCE_SQ_CAP)``.

    Computed a band of rows at a time: the feature transform of the band and
    ``_CAP_ROWS`` rows on either side. An occupied cell outside that window is
    at least 257 rows from every cell of the band, so beyond the cap; within it
    the window's nearest occupied cell is the grid's (an exact transform). So
    the values are exact below the cap, and the transient memory is that of a
    window (~26 MB on a 10 ha map at 5 cm) instead of 8 bytes a cell for the
    whole grid's feature transform. A capped value still bounds the distance
    from below, which is all a ray's leap or a collision bound asks of it.
    """
    occ = np.asarray(occupied, dtype=bool)
    nr, nc = occ.shape
    out = np.full(occ.shape, CLEARANCE_SQ_CAP, dtype=np.uint16)
    cols = np.arange(nc, dtype=np.int64)
    step = max(1, _ROWS_CELLS // max(1, nc))
    for r0 in range(0, nr, step):
        r1 = min(nr, r0 + step)
        w0, w1 = max(0, r0 - _CAP_ROWS), min(nr, r1 + _CAP_ROWS)
        win = occ[w0:w1]
        if not win.any():
            continue                      # every occupied cell is beyond the cap
        ft = ndimage.distance_transform_edt(~win, return_distances=False, return_indices=True)
        dr = ft[0, r0 - w0:r1 - w0].astype(np.int64) - np.arange(r0, r1, dtype=np.int64)[:, None] + w0
        dc = ft[1, r0 - w0:r1 - w0].astype(np.int64) - cols
        del ft
        d2 = dr * dr
        d2 += dc * dc
        np.minimum(d2, CLEARANCE_SQ_CAP, out=d2)
        out[r0:r1] = d2
    return out


def capped_clearance(sq_distance_cells: np.ndarray) -> np.ndarray:
    """A squared clearance table (cells^2) as :func:`clearance_sq_cells_capped` holds it
    (uint16, capped): the array itself when it already is one."""
    d2 = np.asarray(sq_distance_cells)
    if d2.dtype == np.uint16:
        return d2
    return np.minimum(d2, CLEARANCE_SQ_CAP).astype(np.uint16)


class ExtrudedCells:
    """The occupied cells of an occupancy grid, each a box from ``base_z_m``
    (per cell) up to ``base_z_m + canopy_height_m``.

    Parameters
    ----------
    grid : OccupancyGrid
        Cells, resolution and pose (the grid may be yawed).
    base_z_m : (rows, cols) array
        Bottom of each cell's box (m, ENU z); read at occupied cells only.
    canopy_height_m : float
        Height of the boxes above their base (m).

    ``lower_bound_m`` is a cheap bound (one table lookup, from the Euclidean
    distance transform of the grid) for broad-phase rejection;
    ``signed_distance_m`` is exact (a vectorised search of the cells in a
    square about the point, grown until it must hold the nearest).
    """

    def __init__(self, grid: OccupancyGrid, base_z_m, canopy_height_m: float,
                 sq_distance_cells: np.ndarray | None = None) -> None:
        occ = np.asarray(grid.occupied, dtype=bool)
        self.nr, self.nc = occ.shape
        self.res = float(grid.resolution_m)
        self.x0, self.y0 = float(grid.origin_xy_m[0]), float(grid.origin_xy_m[1])
        self.c, self.s = math.cos(grid.origin_yaw_rad), math.sin(grid.origin_yaw_rad)
        self.canopy_height_m = float(canopy_height_m)
        self.occ = occ
        self.any = bool(occ.any())
        # float32 first, then NaN off the cells: the same values as rounding the
        # masked float64 array, without a float64 copy of the grid. A float32
        # array that already has NaN off the cells (``cell_centre_heights(...,
        # np.float32)``, the SITL's ``row_base_heights``) is kept, not copied.
        base = np.asarray(base_z_m, dtype=np.float32)
        done = np.isnan(base)
        done |= occ
        if base is not base_z_m or not done.all():
            base = np.array(base, dtype=np.float32)
            base[~occ] = np.nan
        del done
        self.base = base
        self.top_max_m = float(np.nanmax(base)) + self.canopy_height_m if self.any else -math.inf
        # Horizontal distance (m) from any point of a cell to the nearest
        # occupied cell is at least (centre distance - both half diagonals),
        # float32, stepped down one ulp after rounding. It depends on the cell's
        # squared clearance alone, so the cells hold that (uint16, capped:
        # clearance_sq_cells_capped) and a table of its 65 536 bounds gives the
        # bound: 2 bytes a cell instead of 4 (a 10 ha field at 5 cm is 22 M cells),
        # the same bounds below the cap, a smaller (still valid) one above it.
        if self.any:
            d2 = clearance_sq_cells_capped(occ) if sq_distance_cells is None else capped_clearance(sq_distance_cells)
            self._d2 = np.ascontiguousarray(d2)
            edt = np.sqrt(np.arange(CLEARANCE_SQ_CAP + 1, dtype=np.float64))
            b = (np.maximum(edt - math.sqrt(2.0), 0.0) * self.res).astype(np.float32)
            table = np.maximum(np.nextafter(b, np.float32(-np.inf)), np.float32(0.0))
        else:
            self._d2 = np.zeros(occ.shape, dtype=np.uint16)
            table = np.array([np.inf], dtype=np.float32)
        self._bound_table = table.tolist()                                   # Python floats, fast
        self._d2_flat = memoryview(self._d2.reshape(-1))

    @property
    def _bound(self) -> np.ndarray:
        """(rows, cols) float32: every cell's horizontal bound (m) of ``lower_bound_m``
        (built on request: for tests and inspection)."""
        return np.asarray(self._bound_table, dtype=np.float32)[self._d2]

    # grid frame: u (columns, along the grid's x) and v (rows), in metres
    def _to_grid_m(self, px: float, py: float) -> tuple[float, float]:
        ex, ey = px - self.x0, py - self.y0
        return self.c * ex + self.s * ey, -self.s * ex + self.c * ey

    def top_at_m(self, px: float, py: float) -> float | None:
        """Top (m, ENU z) of the occupied cell under (px, py); None if that cell is not occupied."""
        u, v = self._to_grid_m(px, py)
        i, j = math.floor(v / self.res), math.floor(u / self.res)
        if 0 <= i < self.nr and 0 <= j < self.nc and self.occ[i, j]:
            return float(self.base[i, j]) + self.canopy_height_m
        return None

    def lower_bound_m(self, px: float, py: float, pz: float) -> float:
        """A lower bound (m) of the distance from the point to the cells; cheap."""
        if not self.any:
            return math.inf
        u, v = self._to_grid_m(px, py)
        res = self.res
        cu = min(max(u, 0.0), self.nc * res)
        cv = min(max(v, 0.0), self.nr * res)
        j = min(int(cu / res), self.nc - 1)
        i = min(int(cv / res), self.nr - 1)
        horiz = self._bound_table[self._d2_flat[i * self.nc + j]]
        if cu != u or cv != v:
            # outside the grid: projecting onto the (convex) grid box, the
            # offset to it is orthogonal to any path inside it
            horiz = math.hypot(horiz, math.hypot(u - cu, v - cv))
        above = pz - self.top_max_m
        return math.hypot(horiz, above) if above > 0.0 else horiz

    def signed_distance_m(self, px: float, py: float, pz: float, max_m: float = math.inf) -> float:
        """Distance (m) from the point to the nearest cell box; inside the
        cells, the least of the cells' signed distances (<= 0). ``inf`` without cells.

        Exact when the result is at most ``max_m``; otherwise some value
        above ``max_m`` (the search stops at that radius).
        """
        if not self.any:
            return math.inf
        u, v = self._to_grid_m(px, py)
        res = self.res
        fi, fj = int(math.floor(v / res)), int(math.floor(u / res))
        # Search squares of growing half-size k (cells) about the point's
        # cell until one holds an occupied cell whose distance d is within
        # reach of the square (every cell nearer than d lies inside it).
        lb = self.lower_bound_m(px, py, pz)
        if lb > max_m:
            return lb
        k = int(math.ceil(lb / res)) + 1
        kmax = max(self.nr, self.nc) + abs(fi) + abs(fj) + 1
        while True:
            i0, i1 = max(fi - k, 0), min(fi + k, self.nr - 1)
            j0, j1 = max(fj - k, 0), min(fj + k, self.nc - 1)
            d = math.inf
            if i0 <= i1 and j0 <= j1:
                rows, cols = np.nonzero(self.occ[i0:i1 + 1, j0:j1 + 1])
                if rows.size:
                    d = self._cells_distance(u, v, pz, rows + i0, cols + j0)
            reach = k * res   # every cell outside the square is at least this far
            if d <= reach or k >= kmax or reach >= max_m:
                return d          # exact, or (d > reach >= max_m) the nearest is beyond max_m
            want = min(d, max_m)
            k = min(max(2 * k, int(math.ceil(want / res)) + 1 if want < math.inf else 0), kmax)

    def _cells_distance(self, u: float, v: float, pz: float, rows, cols) -> float:
        """Minimum signed distance (m) from grid-frame point (u, v, pz) to the listed cells."""
        res = self.res
        qx = np.abs(u - (cols + 0.5) * res) - 0.5 * res
        qy = np.abs(v - (rows + 0.5) * res) - 0.5 * res
        base = self.base[rows, cols]
        qz = np.maximum(base - pz, pz - (base + self.canopy_height_m))
        out = np.sqrt(np.maximum(qx, 0.0) ** 2 + np.maximum(qy, 0.0) ** 2 + np.maximum(qz, 0.0) ** 2)
        inside = np.minimum(np.maximum(np.maximum(qx, qy), qz), 0.0)
        return float(np.min(out + inside))


# --- terrain ---------------------------------------------------------------------


def terrain_distance_m(px: float, py: float, pz: float, height: HeightFn) -> float:
    """Signed distance (m) from the point to the terrain's tangent plane under it.

    ``(pz - h) / sqrt(1 + |grad h|^2)`` with ``grad h`` by central differences
    (half-step 1 cm): exact over a planar patch of the height field.
    """
    e = _GRAD_STEP_M
    gx = (height(px + e, py) - height(px - e, py)) / (2.0 * e)
    gy = (height(px, py + e) - height(px, py - e)) / (2.0 * e)
    return (pz - height(px, py)) / math.sqrt(1.0 + gx * gx + gy * gy)


# --- the scene and the clearance ---------------------------------------------------


@dataclass(frozen=True, slots=True)
class Clearance:
    """Clearance of the vehicle sphere (m): distance from the sphere's surface
    to the nearest solid of each kind; negative: penetration; ``inf``: none.

    Attributes
    ----------
    obstacle_m : float
        To the nearest unknown obstacle (``sim.obstacles``).
    obstacle_index : int or None
        Its index in ``sim.obstacles`` (0-based); None without obstacles.
    rows_m : float
        To the vine rows (OGM occupied cells extruded to the canopy height).
    terrain_m : float
        To the terrain (tangent plane under the vehicle, see the module notes).
    """

    obstacle_m: float
    obstacle_index: int | None
    rows_m: float
    terrain_m: float

    @property
    def known_m(self) -> float:
        """To the nearest map feature (rows or terrain)."""
        return min(self.rows_m, self.terrain_m)


class SceneGeometry:
    """Obstacles, rows and terrain of one vineyard, for distance queries.

    Parameters
    ----------
    obstacles : tuple of Cylinder/Box
        The unknown obstacles (``obstacle_solids``), in ``sim.obstacles`` order.
    rows : ExtrudedCells or None
        The vine rows; None: no rows.
    height : callable (x, y) -> z
        Terrain height (m, ENU).

    Build from in-memory maps with ``scene_from_maps``.
    """

    def __init__(self, obstacles: tuple[Solid, ...], rows: ExtrudedCells | None, height: HeightFn) -> None:
        self.obstacles = tuple(obstacles)
        self.rows = rows
        self.height = height

    def nearest_obstacle(self, px: float, py: float, pz: float) -> tuple[float, int | None]:
        """(signed distance m, index) of the nearest obstacle; (inf, None) without any."""
        best, k = math.inf, None
        for i, ob in enumerate(self.obstacles):
            d = ob.signed_distance_m(px, py, pz)
            if d < best:
                best, k = d, i
        return best, k

    def clearance(self, pos_enu_m, radius_m: float) -> Clearance:
        """Clearance of a sphere of ``radius_m`` centred at ``pos_enu_m`` (3,).

        Returns
        -------
        Clearance
            Each distance is the centre's signed distance minus ``radius_m``.
        """
        px, py, pz = (float(c) for c in pos_enu_m)
        r = float(radius_m)
        d_ob, k = self.nearest_obstacle(px, py, pz)
        d_rows = self.rows.signed_distance_m(px, py, pz) if self.rows is not None else math.inf
        d_ter = terrain_distance_m(px, py, pz, self.height)
        return Clearance(d_ob - r, k, d_rows - r, d_ter - r)


def cell_centre_heights(grid: OccupancyGrid, height_xy, dtype=float) -> np.ndarray:
    """Terrain height (m) at the centre of every occupied cell (NaN elsewhere).

    ``height_xy`` takes arrays of x and y (m) and returns the heights (e.g.
    ``ElevationModel.height_at``). ``dtype``: of the result (``np.float32`` for
    ``ExtrudedCells``, which keeps them so: half the memory, the same values).
    """
    occ = np.asarray(grid.occupied, dtype=bool)
    out = np.full(occ.shape, np.nan, dtype=dtype)
    rows, cols = np.nonzero(occ)
    if rows.size:
        xs, ys = grid.cell_to_world(rows, cols)
        out[rows, cols] = np.asarray(height_xy(xs, ys), dtype=float)
    return out


def scene_from_maps(grid: OccupancyGrid | None, dem, obstacles: tuple[ObstacleConfig, ...],
                    canopy_height_m: float) -> SceneGeometry:
    """The scene of a mission from in-memory maps (the companion's builder).

    Parameters
    ----------
    grid : OccupancyGrid or None
        None: no rows.
    dem : ElevationModel or None
        None: flat ground at z = 0. Points outside the DEM's extent take the
        height at the nearest point of the extent.
    obstacles : tuple of ObstacleConfig
    canopy_height_m : float
    """
    if dem is None:
        def height(x: float, y: float) -> float:
            return 0.0

        def height_xy(xs, ys):
            return np.zeros(np.shape(xs))
    else:
        x_min, x_max, y_min, y_max = dem.extent_m

        def height_xy(xs, ys):
            return dem.height_at(np.clip(xs, x_min, x_max), np.clip(ys, y_min, y_max))

        def height(x: float, y: float) -> float:
            # one point: the same number as float(height_xy(x, y)) in plain floats
            return dem.height_one(min(max(x, x_min), x_max), min(max(y, y_min), y_max))
    rows = None
    if grid is not None:
        rows = ExtrudedCells(grid, cell_centre_heights(grid, height_xy, np.float32), canopy_height_m)
    return SceneGeometry(obstacle_solids(obstacles, height), rows, height)
