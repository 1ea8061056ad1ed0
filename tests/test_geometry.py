"""True clearance (mavcore/geometry.py) against hand-placed geometry and
against an independent computation (the nearest point by clipping into each
box, or into the cylinder's half-section)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavcore.geometry import (Box, Cylinder, ExtrudedCells, SceneGeometry, obstacle_solids, scene_from_maps,
                              terrain_distance_m)
from mavcore.maps.grid import ElevationModel, OccupancyGrid
from mavcore.mission.sim import ObstacleConfig


def _grid(occ, res=0.1, origin=(0.0, 0.0), yaw=0.0):
    occ = np.asarray(occ, dtype=bool)
    return OccupancyGrid(occ, ~occ, res, origin, yaw)


def _plane_dem(a, b, c, n=40, cs=0.5, x0=-5.0, y0=-5.0):
    xs = x0 + cs * np.arange(n)
    ys = y0 + cs * np.arange(n)
    X, Y = np.meshgrid(xs, ys)
    return ElevationModel(a * X + b * Y + c, x0, y0, cs)


# --- cylinder ------------------------------------------------------------------------


CYL = Cylinder(2.0, 1.0, 0.5, 2.5, 0.3)   # axis (2, 1), z in [0.5, 2.5], r = 0.3


@pytest.mark.parametrize("p, want", [
    ((2.0 + 0.3 + 0.7, 1.0, 1.5), 0.7),                       # side, along +x
    ((2.0, 1.0 - 0.3 - 0.25, 2.0), 0.25),                     # side, along -y
    ((2.0 + 0.1, 1.0, 2.5 + 0.4), 0.4),                       # above the top cap, inside the rim
    ((2.0, 1.0, 0.5 - 0.2), 0.2),                             # below the base
    ((2.0 + 0.3 + 0.3, 1.0, 2.5 + 0.4), 0.5),                 # beyond the rim: 3-4-5 from the edge
    ((2.0 + 0.1, 1.0, 1.5), -0.2),                            # inside: 0.2 to the side wall
    ((2.0, 1.0, 2.4), -0.1),                                  # inside: 0.1 below the top
])
def test_cylinder_side_top_rim_inside(p, want):
    assert CYL.signed_distance_m(*p) == pytest.approx(want, abs=1e-12)


# --- box --------------------------------------------------------------------------------


def test_box_face_edge_and_corner():
    box = Box(0.0, 0.0, 0.0, 1.0, 0.5, 0.25)   # x in [-0.5, 0.5], y in [-0.25, 0.25], z in [0, 1]
    assert box.signed_distance_m(1.5, 0.0, 0.5) == pytest.approx(1.0)            # face
    assert box.signed_distance_m(0.5 + 0.3, 0.25 + 0.4, 0.5) == pytest.approx(0.5)   # vertical edge: 3-4-5
    assert box.signed_distance_m(0.5 + 0.1, -0.25 - 0.2, 1.0 + 0.2) == pytest.approx(0.3)  # corner: 1-2-2 -> 3
    assert box.signed_distance_m(0.4, 0.0, 0.5) == pytest.approx(-0.1)           # inside, 0.1 from the +x face


def test_yawed_box_corner_and_face():
    yaw = math.radians(30.0)
    box = Box(3.0, -1.0, 0.0, 2.0, 1.0, 0.5, yaw)
    c, s = math.cos(yaw), math.sin(yaw)
    # the box's +x face is 1.0 from the centre along (c, s): 0.7 beyond it
    assert box.signed_distance_m(3.0 + 1.7 * c, -1.0 + 1.7 * s, 1.0) == pytest.approx(0.7)
    # its (+x, +y) corner in world coordinates, then 0.2 along the corner's diagonal outward
    corner = np.array([3.0 + c * 1.0 - s * 0.5, -1.0 + s * 1.0 + c * 0.5])
    out = np.array([c - s, s + c]) / math.sqrt(2.0)   # the box's (1, 1)/sqrt2 direction in world axes
    p = corner + 0.2 * out
    assert box.signed_distance_m(p[0], p[1], 1.0) == pytest.approx(0.2)
    # the same point is 0.2 * cos(45 deg) beyond each of the two faces: the
    # unyawed reading would be wrong, so the yaw is really applied
    assert Box(3.0, -1.0, 0.0, 2.0, 1.0, 0.5).signed_distance_m(p[0], p[1], 1.0) != pytest.approx(0.2, abs=0.01)


def _brute_box(b: Box, p):
    """Distance by clipping the point into the box in its own frame (independent of the q-vector form)."""
    c, s = math.cos(b.yaw_rad), math.sin(b.yaw_rad)
    lx = c * (p[0] - b.x_m) + s * (p[1] - b.y_m)
    ly = -s * (p[0] - b.x_m) + c * (p[1] - b.y_m)
    q = np.clip([lx, ly, p[2]], [-b.half_x_m, -b.half_y_m, b.base_z_m], [b.half_x_m, b.half_y_m, b.top_z_m])
    return float(np.linalg.norm(np.array([lx, ly, p[2]]) - q))


def _brute_cylinder(cy: Cylinder, p):
    """Distance by symmetry: clip (radius, z) of the point into the rectangle
    [0, r] x [base, top] of the cylinder's half-section."""
    rho = math.hypot(p[0] - cy.x_m, p[1] - cy.y_m)
    q = np.array([rho, p[2]])
    return float(np.linalg.norm(q - np.clip(q, [0.0, cy.base_z_m], [cy.radius_m, cy.top_z_m])))


def test_random_points_against_brute_force():
    rng = np.random.default_rng(7)
    box = Box(1.0, 2.0, 0.2, 1.4, 0.6, 0.3, math.radians(-35.0))
    for _ in range(60):
        p = rng.uniform([-1.0, 0.0, -0.5], [3.0, 4.0, 2.5])
        d = box.signed_distance_m(*p)
        if d > 0:
            assert d == pytest.approx(_brute_box(box, p), abs=1e-12)
    for _ in range(60):
        p = rng.uniform([1.0, 0.0, 0.0], [3.0, 2.0, 3.2])
        d = CYL.signed_distance_m(*p)
        if d > 0:
            assert d == pytest.approx(_brute_cylinder(CYL, p), abs=1e-12)


# --- rows: extruded cells ---------------------------------------------------------------


def _row_cells(yaw=0.0, origin=(0.0, 0.0)):
    occ = np.zeros((30, 40), dtype=bool)
    occ[10:12, 5:35] = True                 # a row 0.2 m wide, 3 m long: v in [1.0, 1.2], u in [0.5, 3.5]
    g = _grid(occ, 0.1, origin, yaw)
    base = np.where(occ, 0.3, np.nan)      # the rows stand on ground at z = 0.3
    return ExtrudedCells(g, base, 2.0), g  # top at 2.3


def test_row_side_top_end_and_outside_the_grid():
    cells, _ = _row_cells()
    assert cells.signed_distance_m(2.0, 1.2 + 0.6, 1.0) == pytest.approx(0.6)     # beside the row
    assert cells.signed_distance_m(2.0, 0.4, 1.0) == pytest.approx(0.6)           # other side
    assert cells.signed_distance_m(2.0, 1.1, 2.3 + 0.5) == pytest.approx(0.5)     # above the canopy
    assert cells.signed_distance_m(3.5 + 0.3, 1.2 + 0.4, 1.0) == pytest.approx(0.5)   # past its end, 3-4-5
    assert cells.signed_distance_m(-2.0, 1.1, 1.0) == pytest.approx(2.5)          # outside the grid, west
    assert cells.signed_distance_m(2.0, 1.1, 0.1) == pytest.approx(0.2)           # under the base (ground step)
    assert cells.signed_distance_m(2.05, 1.15, 1.0) == pytest.approx(-0.05)       # in a cell: 5 cm to its faces
    assert cells.signed_distance_m(2.0, 1.15, 1.0) <= 0.0                          # between two cells: inside


def test_yawed_grid_row_distance():
    yaw = math.radians(30.0)
    cells, g = _row_cells(yaw, (1.0, -2.0))
    c, s = math.cos(yaw), math.sin(yaw)
    # grid point (u, v) = (2.0, 1.8) is 0.6 from the row's +v face
    x, y = 1.0 + c * 2.0 - s * 1.8, -2.0 + s * 2.0 + c * 1.8
    assert cells.signed_distance_m(x, y, 1.0) == pytest.approx(0.6)


def _brute_cells(cells: ExtrudedCells, grid: OccupancyGrid, p):
    rows, cols = np.nonzero(grid.occupied)
    best = math.inf
    c, s = math.cos(grid.origin_yaw_rad), math.sin(grid.origin_yaw_rad)
    ex, ey = p[0] - grid.origin_xy_m[0], p[1] - grid.origin_xy_m[1]
    u, v = c * ex + s * ey, -s * ex + c * ey
    res = grid.resolution_m
    for r, k in zip(rows, cols):
        lo = np.array([k * res, r * res, cells.base[r, k]])
        hi = np.array([(k + 1) * res, (r + 1) * res, cells.base[r, k] + cells.canopy_height_m])
        q = np.array([u, v, p[2]])
        best = min(best, float(np.linalg.norm(q - np.clip(q, lo, hi))))
    return best


def test_cells_against_brute_force_and_bound_below_exact():
    rng = np.random.default_rng(3)
    occ = rng.random((20, 25)) < 0.08
    g = _grid(occ, 0.2, (-1.0, 0.5), math.radians(12.0))
    base = rng.uniform(0.0, 0.5, occ.shape)
    cells = ExtrudedCells(g, base, 1.5)
    for _ in range(80):
        p = rng.uniform([-3.0, -2.0, -0.5], [6.0, 6.0, 3.0])
        d = cells.signed_distance_m(*p)
        if d > 0:
            assert d == pytest.approx(_brute_cells(cells, g, p), abs=1e-9)
        assert cells.lower_bound_m(*p) <= max(d, 0.0) + 1e-12


def test_capped_search_is_exact_below_the_cap():
    cells, _ = _row_cells()
    assert cells.signed_distance_m(2.0, 2.5, 1.0, max_m=0.5) > 0.5   # 1.3 m away: only "beyond the cap"
    assert cells.signed_distance_m(2.0, 1.5, 1.0, max_m=0.5) == pytest.approx(0.3)


# --- terrain --------------------------------------------------------------------------


def test_terrain_slope_distance_is_the_point_plane_distance():
    a, b, c = 0.2, -0.1, 1.0
    dem = _plane_dem(a, b, c)
    scene = scene_from_maps(None, dem, (), 2.0)
    n = np.array([-a, -b, 1.0]) / math.sqrt(1 + a * a + b * b)   # upward unit normal
    for p in [(1.0, 2.0, 3.0), (-2.5, 0.3, 1.7), (4.0, -4.0, 0.9)]:
        p0 = np.array([p[0], p[1], a * p[0] + b * p[1] + c])      # a point of the plane
        want = float(n @ (np.array(p) - p0))
        assert terrain_distance_m(*p, scene.height) == pytest.approx(want, abs=1e-9)


# --- the scene --------------------------------------------------------------------------


def test_obstacles_stand_on_the_terrain_and_clearance_subtracts_the_radius():
    a, b, c = 0.1, 0.0, 0.5
    dem = _plane_dem(a, b, c)
    occ = np.zeros((40, 40), dtype=bool)
    occ[20, 10:35] = True                                          # row: v in [2.0, 2.1], u in [1.0, 3.5]
    grid = _grid(occ, 0.1, (0.0, 0.0))
    obs = (ObstacleConfig("cylinder", x=2.0, y=0.5, height=1.0, radius=0.2),
           ObstacleConfig("box", x=3.0, y=3.5, height=2.0, size_x=0.4, size_y=0.4, yaw_deg=45.0))
    scene = scene_from_maps(grid, dem, obs, 1.8)
    cyl, box = scene.obstacles
    assert cyl.base_z_m == pytest.approx(a * 2.0 + c) and cyl.top_z_m == pytest.approx(a * 2.0 + c + 1.0)
    assert box.base_z_m == pytest.approx(a * 3.0 + c) and box.yaw_rad == pytest.approx(math.pi / 4)
    r = 0.4
    p = (2.0 + 0.2 + 0.9, 0.5, cyl.base_z_m + 0.5)                # 0.9 from the cylinder's side
    cl = scene.clearance(p, r)
    assert cl.obstacle_index == 0 and cl.obstacle_m == pytest.approx(0.9 - r)
    assert cl.rows_m == pytest.approx((2.0 - 0.5) - r)             # the row's south face is at y = 2.0
    assert cl.terrain_m == pytest.approx((p[2] - (a * p[0] + c)) / math.sqrt(1 + a * a) - r)
    assert cl.known_m == min(cl.rows_m, cl.terrain_m)
    # the rows stand on the DEM too: each cell from the terrain at its centre
    assert scene.rows.base[20, 15] == pytest.approx(a * 1.55 + c)
    assert scene.rows.base[20, 34] == pytest.approx(a * 3.45 + c)


def test_empty_scene():
    scene = SceneGeometry(obstacle_solids((), lambda x, y: 0.0), None, lambda x, y: 0.0)
    cl = scene.clearance((1.0, 2.0, 3.0), 0.5)
    assert cl.obstacle_m == math.inf and cl.obstacle_index is None and cl.rows_m == math.inf
    assert cl.terrain_m == pytest.approx(2.5)


def test_top_of_the_cell_under_a_point():
    cells, _ = _row_cells()
    assert cells.top_at_m(2.0, 1.1) == pytest.approx(2.3)
    assert cells.top_at_m(2.0, 1.5) is None and cells.top_at_m(-1.0, 1.1) is None
