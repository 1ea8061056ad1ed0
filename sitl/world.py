"""The simulated world: terrain (DEM), vine rows (OGM extruded to a canopy
height) and the mission's unknown obstacles, with ray casting for the
rangefinders.

Everything is in the map's local ENU frame (m). Pure: the maps come in as
``mavcore.maps.grid`` objects; ``load_world`` is the only function that
reads files.

Ray casting (``World.raycast``) returns the distance along a unit ray to the
first surface, ``math.inf`` if none within ``max_m``:

- terrain: sphere tracing on the height field with its Lipschitz bound (the
  largest slope of the bilinear DEM), exact in one step over flat ground;
- vine rows: a grid traversal in the OGM's frame that leaps through open
  space by the Euclidean distance transform (a distance to the nearest
  occupied cell that is a safe lower bound, minus a cell diagonal) and
  walks cell by cell (Amanatides-Woo) near the rows; an occupied cell is a
  box from the DEM (at the cell centre) up to ``canopy_height_m``;
- obstacles (static, and the movers of ``sim.movers`` at their pose of the
  last ``set_time``, ``sitl.movers``): analytic ray/cylinder (with caps) and ray/box (slab) tests,
  standing on the terrain under their centre; ``Obstacle.project`` (the
  nearest point of the solid) and ``Obstacle.azimuth_span`` serve the exact
  field-of-view pass of ``sitl.fov``.

``World.geometry`` is the same scene for distance queries
(``mavcore.geometry.SceneGeometry``): the collision check of
``sitl.collision`` and the companion's clearance report measure on it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage

from mavcore.geometry import (ExtrudedCells, SceneGeometry, capped_clearance, clearance_sq_cells_capped,
                              obstacle_solids)
from mavcore.maps.heightfield import HeightField
from mavcore.maps.grid import ElevationModel, OccupancyGrid
from mavcore.mission.sim import MoverConfig, ObstacleConfig
from .movers import MovingObstacles

if TYPE_CHECKING:  # pragma: no cover
    from mavcore.mission.schema import Mission

_INF = math.inf
_EPS_T = 1e-9          # nudge (m) past a cell boundary during the traversal
_HIT_EPS_M = 1e-6      # terrain sphere tracing stops this close to the ground
_MAX_TERRAIN_ITERS = 200
#: ``World.near_obstacles`` keeps an obstacle whose bounding sphere is within reach plus this (m)
_BROAD_MARGIN_M = 1e-6


class Terrain:
    """Bilinear height field between DEM cell centres, clamped at the edges.

    NODATA cells take the value of the nearest valid cell. ``None`` for the
    model: flat ground at ``z = 0``.
    """

    def __init__(self, dem: ElevationModel | None = None, flat_height_m: float = 0.0) -> None:
        if dem is None:
            self.flat = True
            self.z = float(flat_height_m)
            self.max_slope = 0.0
            self.min_height_m = self.max_height_m = self.z
            self.height = self._flat_height
            return
        h = np.asarray(dem.heights_m, dtype=float)
        if h.ndim != 2 or h.size == 0:
            raise ValueError("DEM heights must be a non-empty 2D array")
        # the companion's own lookup (NODATA filled from the nearest valid cell,
        # bilinear between cell centres, clamped): the terrain the SITL renders is
        # the one the companion's replanner knows
        field = HeightField(dem)
        h = field.heights_m
        self.flat = bool(np.all(h == h.flat[0]))
        self.z = float(h.flat[0])
        self.min_height_m = float(h.min())
        self.max_height_m = float(h.max())
        self._cs = float(dem.cellsize_m)
        # Lipschitz bound of the bilinear interpolant: on each cell the
        # gradient is bounded by the largest edge difference per axis.
        gx = np.abs(np.diff(h, axis=1)).max() if h.shape[1] > 1 else 0.0
        gy = np.abs(np.diff(h, axis=0)).max() if h.shape[0] > 1 else 0.0
        self.max_slope = float(math.hypot(gx, gy) / self._cs)
        self.height = self._flat_height if self.flat else field

    def _flat_height(self, x: float, y: float) -> float:
        return self.z

    def raycast(self, ox, oy, oz, dx, dy, dz, max_m, ground_z=None) -> float:
        """Distance along the unit ray to the ground (inf if none within max_m).
        ``ground_z``: ``height(ox, oy)`` when the caller has it (a fan of rays from one origin)."""
        hz = oz - (self.height(ox, oy) if ground_z is None else ground_z)
        if hz <= 0.0:
            if hz < 0.0 or dz <= 0.0:
                return 0.0               # under the ground, or on it looking into it
            hz = _HIT_EPS_M * 2.0        # on the ground looking up: trace from just above it
        denom = self.max_slope * math.hypot(dx, dy) - dz
        if denom <= 0.0:
            return _INF
        if self.flat:
            t = hz / -dz
            return t if t <= max_m else _INF
        t = 0.0
        for _ in range(_MAX_TERRAIN_ITERS):
            t += hz / denom
            if t > max_m:
                return _INF
            hz = oz + dz * t - self.height(ox + dx * t, oy + dy * t)
            if hz <= _HIT_EPS_M:
                return t
        return t  # grazing: converging from above; t is a lower bound close to the hit


class RowField:
    """Vine rows: occupied OGM cells extruded from the DEM to the canopy height.

    Held compactly for a 10 ha map (22 M cells at 5 cm): the occupancy as a flat
    view of the grid's own bool array, the clearance as the squared distance
    transform capped at 65 535 cells^2 in uint16
    (``mavcore.geometry.clearance_sq_cells_capped``: below the cap its square
    root is ``ndimage.distance_transform_edt`` bit for bit; a capped cell, ~256
    cells or more from every row, leaps at most ~254 cells, a shorter leap that
    is still clear, so a ray meets the same first cell), and a cell's base
    height read from the terrain the first time a ray reaches that cell (the
    same call on the same cell centre as reading them all up front). Indexing
    a flat memoryview gives a Python bool or int as fast as nested lists did,
    at 3 bytes a cell instead of ~90.
    """

    def __init__(self, grid: OccupancyGrid, terrain: Terrain, canopy_height_m: float,
                 sq_distance_cells: np.ndarray | None = None) -> None:
        occ = np.ascontiguousarray(grid.occupied, dtype=bool)
        self.nr, self.nc = occ.shape
        self.res = float(grid.resolution_m)
        self.X0, self.Y0 = float(grid.origin_xy_m[0]), float(grid.origin_xy_m[1])
        self.c, self.s = math.cos(grid.origin_yaw_rad), math.sin(grid.origin_yaw_rad)
        self.any = bool(occ.any())
        self._grid, self._terrain = grid, terrain
        self.occ = memoryview(occ.reshape(-1))
        self._d2 = None
        if self.any:
            d2 = clearance_sq_cells_capped(occ) if sq_distance_cells is None else capped_clearance(sq_distance_cells)
            self._d2 = memoryview(np.ascontiguousarray(d2).reshape(-1))
        self._base: dict[int, float] = {}
        self.canopy = float(canopy_height_m)

    def base_at(self, r: int, c: int) -> float:
        """Terrain height (m) at the centre of cell (r, c), read once per cell."""
        key = r * self.nc + c
        b = self._base.get(key)
        if b is None:
            x, y = self._grid.cell_to_world(r, c)
            b = self._base[key] = self._terrain.height(float(x), float(y))
        return b

    def leap_cells(self, r: int, c: int) -> float:
        """Leap length (cells) that provably stays clear of every occupied cell from
        any point of cell (r, c): centre distance minus both half diagonals."""
        return math.sqrt(self._d2[r * self.nc + c]) - 1.5

    def _band_hit(self, r, c, oz, dz, t_en, t_ex):
        base = self.base_at(r, c)
        top = base + self.canopy
        z = oz + dz * t_en
        if base <= z <= top:
            return t_en
        if z > top and dz < 0.0:
            tc = (top - oz) / dz
        elif z < base and dz > 0.0:
            tc = (base - oz) / dz
        else:
            return None
        return tc if tc <= t_ex else None

    def raycast(self, ox, oy, oz, dx, dy, dz, max_m) -> float:
        if not self.any:
            return _INF
        res, c, s = self.res, self.c, self.s
        ex, ey = ox - self.X0, oy - self.Y0
        u = (c * ex + s * ey) / res          # column coordinate (cells)
        v = (-s * ex + c * ey) / res         # row coordinate (cells)
        du = (c * dx + s * dy) / res         # cells per metre along the ray
        dv = (-s * dx + c * dy) / res
        nc, nr = self.nc, self.nr
        # Clip to the grid box [0, nc] x [0, nr] (slabs).
        t0, t1 = 0.0, max_m
        for q, dq, hi in ((u, du, nc), (v, dv, nr)):
            if dq == 0.0:
                if q < 0.0 or q >= hi:
                    return _INF
            else:
                ta, tb = (0.0 - q) / dq, (hi - q) / dq
                if ta > tb:
                    ta, tb = tb, ta
                if ta > t0:
                    t0 = ta
                if tb < t1:
                    t1 = tb
        if t0 > t1:
            return _INF
        occ, d2, sqrt = self.occ, self._d2, math.sqrt
        sp = math.hypot(du, dv)
        if sp * (t1 - t0) < 1e-12:   # vertical ray: one column of cells
            r, cc = int(v), int(u)
            if 0 <= r < nr and 0 <= cc < nc and occ[r * nc + cc]:
                hit = self._band_hit(r, cc, oz, dz, t0, t1)
                return _INF if hit is None else hit
            return _INF
        t = t0
        t_in = t0      # exact entry of the current cell (t itself is nudged past boundaries)
        while t <= t1:
            uu = u + du * t
            vv = v + dv * t
            cc = int(uu) if uu < nc else nc - 1
            r = int(vv) if vv < nr else nr - 1
            # On a cell boundary moving toward lower indices the ray is in the
            # lower cell (else the exit distance is 0 and t only creeps by _EPS_T).
            if du < 0.0 and cc == uu:
                cc -= 1
            if dv < 0.0 and r == vv:
                r -= 1
            if cc < 0:
                cc = 0
            if r < 0:
                r = 0
            i = r * nc + cc
            if occ[i]:
                t_ex = _cell_exit(uu, vv, du, dv, cc, r) + t
                hit = self._band_hit(r, cc, oz, dz, t_in, min(t_ex, t1))
                if hit is not None:
                    return hit
                t_in = t_ex
                t = t_ex + _EPS_T
                continue
            lp = sqrt(d2[i]) - 1.5           # leap_cells(r, cc)
            if lp > 1.0:
                t += lp / sp
                t_in = t
            else:
                t_in = t + _cell_exit(uu, vv, du, dv, cc, r)
                t = t_in + _EPS_T
        return _INF


def row_base_heights(grid: OccupancyGrid, terrain: Terrain) -> np.ndarray:
    """(rows, cols) float32: ``terrain.height`` at the centre of every occupied cell
    (the value ``RowField.base_at`` reads, rounded to float32), NaN elsewhere;
    a band of rows at a time (no index arrays or Python floats for the whole grid)."""
    occ = np.asarray(grid.occupied, dtype=bool)
    out = np.full(occ.shape, np.nan, dtype=np.float32)
    step = max(1, (1 << 18) // max(1, occ.shape[1]))
    for r0 in range(0, occ.shape[0], step):
        rows, cols = np.nonzero(occ[r0:r0 + step])
        if rows.size:
            rows += r0
            xs, ys = grid.cell_to_world(rows, cols)
            out[rows, cols] = np.fromiter((terrain.height(float(x), float(y)) for x, y in zip(xs, ys)),
                                          dtype=float, count=rows.size)
    return out


def _cell_exit(uu, vv, du, dv, cc, r):
    """Ray parameter (m) from (uu, vv) to the boundary of cell (r, cc)."""
    if du > 0.0:
        tu = (cc + 1 - uu) / du
    elif du < 0.0:
        tu = (cc - uu) / du
    else:
        tu = _INF
    if dv > 0.0:
        tv = (r + 1 - vv) / dv
    elif dv < 0.0:
        tv = (r - vv) / dv
    else:
        tv = _INF
    return tu if tu < tv else tv


class Obstacle:
    """An obstacle of the mission's ``sim:`` section standing on the terrain."""

    def __init__(self, cfg: ObstacleConfig, terrain: Terrain) -> None:
        self.cfg = cfg
        self.kind = cfg.type
        self.x, self.y = float(cfg.x), float(cfg.y)
        self.base = terrain.height(self.x, self.y)
        self.top = self.base + float(cfg.height)
        self.r = float(cfg.radius)
        self.hx, self.hy = 0.5 * float(cfg.size_x), 0.5 * float(cfg.size_y)
        yaw = math.radians(cfg.yaw_deg)
        self.cy, self.sy = math.cos(yaw), math.sin(yaw)
        # bounding sphere (the field-of-view test's broad phase)
        self.zc = 0.5 * (self.base + self.top)
        hz = 0.5 * (self.top - self.base)
        self.bound_r = math.hypot(self.r, hz) if self.kind == "cylinder" else math.sqrt(
            self.hx * self.hx + self.hy * self.hy + hz * hz)

    def azimuth_span(self, ox, oy):
        """(azimuth of the centre, half-width) (rad) of the footprint seen from
        (ox, oy), ENU; None when (ox, oy) is over the footprint. The solid lies
        between the two vertical planes through (ox, oy) at those azimuths."""
        ex, ey = self.x - ox, self.y - oy
        rho = math.hypot(ex, ey)
        az = math.atan2(ey, ex)
        if self.kind == "cylinder":
            if rho <= self.r:
                return None
            return az, math.asin(self.r / rho)
        c, s = self.cy, self.sy
        lx, ly = -(c * ex + s * ey), -(-s * ex + c * ey)      # the point in the box frame
        if abs(lx) <= self.hx and abs(ly) <= self.hy:
            return None
        half = 0.0
        for sx in (-1.0, 1.0):
            for sy in (-1.0, 1.0):
                cx, cy = sx * self.hx, sy * self.hy
                wx, wy = ex + c * cx - s * cy, ey + s * cx + c * cy
                d = abs(math.atan2(wx * ey - wy * ex, wx * ex + wy * ey))   # angle from the centre's azimuth
                if d > half:
                    half = d
        return az, half

    def project(self, px, py, pz):
        """Euclidean projection (ENU) of a point onto the solid (itself inside)."""
        z = self.base if pz < self.base else (self.top if pz > self.top else pz)
        ex, ey = px - self.x, py - self.y
        if self.kind == "cylinder":
            rho = math.sqrt(ex * ex + ey * ey)
            if rho > self.r:
                k = self.r / rho
                ex, ey = ex * k, ey * k
            return self.x + ex, self.y + ey, z
        c, s = self.cy, self.sy
        lx, ly = c * ex + s * ey, -s * ex + c * ey
        lx = -self.hx if lx < -self.hx else (self.hx if lx > self.hx else lx)
        ly = -self.hy if ly < -self.hy else (self.hy if ly > self.hy else ly)
        return self.x + c * lx - s * ly, self.y + s * lx + c * ly, z

    def raycast(self, ox, oy, oz, dx, dy, dz, max_m) -> float:
        if self.kind == "cylinder":
            return self._cylinder(ox, oy, oz, dx, dy, dz, max_m)
        return self._box(ox, oy, oz, dx, dy, dz, max_m)

    def _cylinder(self, ox, oy, oz, dx, dy, dz, max_m):
        ex, ey = ox - self.x, oy - self.y
        r2 = self.r * self.r
        best = _INF
        a = dx * dx + dy * dy
        c = ex * ex + ey * ey - r2
        if c <= 0.0 and self.base <= oz <= self.top:
            return 0.0
        if a > 0.0:
            b = ex * dx + ey * dy
            disc = b * b - a * c
            if disc >= 0.0:
                t = (-b - math.sqrt(disc)) / a      # entry through the side
                if t >= 0.0 and self.base <= oz + dz * t <= self.top:
                    best = t
        if dz != 0.0:                               # caps
            for zc in (self.top, self.base):
                t = (zc - oz) / dz
                if 0.0 <= t < best:
                    px, py = ex + dx * t, ey + dy * t
                    if px * px + py * py <= r2:
                        best = t
        return best if best <= max_m else _INF

    def _box(self, ox, oy, oz, dx, dy, dz, max_m):
        ex, ey = ox - self.x, oy - self.y
        c, s = self.cy, self.sy
        lx, ly = c * ex + s * ey, -s * ex + c * ey   # box frame
        ldx, ldy = c * dx + s * dy, -s * dx + c * dy
        t0, t1 = 0.0, max_m
        for q, dq, lo, hi in ((lx, ldx, -self.hx, self.hx), (ly, ldy, -self.hy, self.hy),
                              (oz, dz, self.base, self.top)):
            if dq == 0.0:
                if q < lo or q > hi:
                    return _INF
            else:
                ta, tb = (lo - q) / dq, (hi - q) / dq
                if ta > tb:
                    ta, tb = tb, ta
                if ta > t0:
                    t0 = ta
                if tb < t1:
                    t1 = tb
                if t0 > t1:
                    return _INF
        return t0


@dataclass(frozen=True, eq=False)
class World:
    """Terrain, rows and obstacles: everything a rangefinder can see.

    Build with ``World.build``; ``ground_height(x, y)`` and
    ``raycast(origin, direction, max_m)`` are the queries; ``geometry`` the
    same solids for distances (``mavcore.geometry.SceneGeometry``).
    """

    terrain: Terrain
    rows: RowField | None
    obstacles: tuple[Obstacle, ...]
    grid: OccupancyGrid | None = None
    geometry: SceneGeometry | None = None
    moving: MovingObstacles | None = None

    @classmethod
    def build(cls, grid: OccupancyGrid | None = None, dem: ElevationModel | None = None,
              obstacles: tuple[ObstacleConfig, ...] = (), canopy_height_m: float = 2.0,
              movers: tuple[MoverConfig, ...] = ()) -> "World":
        """Assemble a world from in-memory maps (None: flat ground at z = 0, no rows);
        ``movers`` (``sim.movers``) are posed by ``set_time`` on the vehicle clock."""
        terrain = Terrain(dem)
        rows = cells = None
        if grid is not None:
            # one distance transform for the ray leaps and the collision bounds
            d2 = clearance_sq_cells_capped(grid.occupied) if grid.occupied.any() else None
            rows = RowField(grid, terrain, canopy_height_m, d2)
            cells = ExtrudedCells(grid, row_base_heights(grid, terrain), canopy_height_m, d2)
            del d2
        geometry = SceneGeometry(obstacle_solids(tuple(obstacles), terrain.height), cells, terrain.height)
        moving = MovingObstacles(tuple(movers), terrain, Obstacle) if movers else None
        return cls(terrain, rows, tuple(Obstacle(o, terrain) for o in obstacles), grid, geometry, moving)

    def set_time(self, t_s: float) -> None:
        """Pose the moving obstacles at vehicle time ``t_s`` (s since boot); no-op without any."""
        if self.moving is not None:
            self.moving.set_time(t_s)

    @property
    def obstacles_now(self) -> tuple:
        """The static obstacles, then the movers at their current pose (``Obstacle``s)."""
        return self.obstacles if self.moving is None else self.obstacles + self.moving.current

    def ground_height(self, x: float, y: float) -> float:
        """Terrain height (m, ENU z) under (x, y)."""
        return self.terrain.height(x, y)

    def near_obstacles(self, ox, oy, oz, reach_m: float) -> tuple:
        """The obstacles now (``obstacles_now``) that a ray of length ``reach_m`` from
        (ox, oy, oz) may reach: every point of a solid lies within its bounding sphere,
        so one whose sphere is farther (by a micrometre, for rounding) cannot be hit
        before ``reach_m`` and its ``raycast`` would return inf."""
        lim = reach_m + _BROAD_MARGIN_M
        out = []
        for ob in self.obstacles_now:
            cx, cy, cz = ob.x - ox, ob.y - oy, ob.zc - oz
            if math.sqrt(cx * cx + cy * cy + cz * cz) - ob.bound_r <= lim:
                out.append(ob)
        return tuple(out)

    def raycast(self, ox, oy, oz, dx, dy, dz, max_m: float, ground_z=None, obstacles=None) -> float:
        """Distance (m) along the unit ray (dx, dy, dz) from (ox, oy, oz) to the
        first surface of terrain, rows or obstacles; ``math.inf`` if none
        within ``max_m``. Plain floats in and out (hot path). A fan of rays from
        one origin may pass the terrain height under it (``ground_z``) and the
        obstacles within its reach (``near_obstacles``; default all of them)."""
        best = self.terrain.raycast(ox, oy, oz, dx, dy, dz, max_m, ground_z)
        lim = best if best < max_m else max_m
        if self.rows is not None:
            t = self.rows.raycast(ox, oy, oz, dx, dy, dz, lim)
            if t < best:
                best = t
                lim = t
        for ob in (self.obstacles_now if obstacles is None else obstacles):
            t = ob.raycast(ox, oy, oz, dx, dy, dz, lim)
            if t < best:
                best = t
                lim = t
        return best

    def first_free_cell_enu(self) -> tuple[float, float] | None:
        """World (x, y) of the first free OGM cell (row-major from the
        south-west corner), or None without a grid."""
        if self.grid is None:
            return None
        rows, cols = np.nonzero(self.grid.free)
        if rows.size == 0:
            return None
        x, y = self.grid.cell_to_world(rows[0], cols[0])
        return float(x), float(y)


    def start_cell_enu(self) -> tuple[float, float] | None:
        """World (x, y) of the SITL's default start cell, or None without a
        grid or free cell.

        Among the free cells on the ridge of the clearance (distance to the
        nearest cell that is not free, the map border included: a local
        maximum, i.e. the middle of a corridor between rows) with at least
        half the map's largest clearance, the one nearest to the centroid of
        all free cells (ties: the first in row-major order). Well inside the
        mapped area and away from the rows, chosen without any planning.
        """
        if self.grid is None:
            return None
        free = np.asarray(self.grid.free, dtype=bool)
        if not free.any():
            return None
        # Clearance in cells; the padding makes the map border count as not free.
        clear = ndimage.distance_transform_edt(np.pad(free, 1))[1:-1, 1:-1]
        rows, cols = np.nonzero(free)
        rc, cc = rows.mean(), cols.mean()
        # On the ridge of the clearance (the middle of a corridor between rows).
        ridge = clear >= ndimage.maximum_filter(clear, size=3, mode="constant")
        rows, cols = np.nonzero((clear >= 0.5 * clear.max()) & ridge)   # never empty: holds the max
        # Centroid in cell coordinates: the grid is rigid (rotation + offset),
        # so the nearest cell is the same in world coordinates.
        k = int(np.argmin((rows - rc) ** 2 + (cols - cc) ** 2))
        x, y = self.grid.cell_to_world(rows[k], cols[k])
        return float(x), float(y)


def load_world(mission: "Mission") -> World:
    """Read the mission's OGM and DEM and build its ``World`` (the I/O edge).

    Raises
    ------
    MapError
        A map file cannot be loaded (from the companion's loaders).
    """
    from mavcore.maps.field import load_mission_maps  # noqa: PLC0415  (I/O only here)

    # the planner's loader: Nav2 maps or vector fields, local or georeferenced DEMs, home heading
    grid, dem = load_mission_maps(mission)
    return World.build(grid, dem, mission.sim.obstacles, mission.sim.canopy_height_m, mission.sim.movers)
