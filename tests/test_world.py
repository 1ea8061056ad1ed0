"""World geometry and ray casting (sitl/world.py) against hand-placed geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavcore.maps.grid import ElevationModel, OccupancyGrid
from mavcore.mission.sim import ObstacleConfig
from sitl.world import Terrain, World


def _grid(occ, res=0.1, origin=(0.0, 0.0), yaw=0.0):
    occ = np.asarray(occ, dtype=bool)
    return OccupancyGrid(occ, ~occ, res, origin, yaw)


def _plane_dem(a=0.1, b=-0.2, c=1.0, n=40, cs=0.5, x0=-5.0, y0=-5.0):
    xs = x0 + cs * np.arange(n)
    ys = y0 + cs * np.arange(n)
    X, Y = np.meshgrid(xs, ys)                   # [row, col]: row with y
    return ElevationModel(a * X + b * Y + c, x0, y0, cs)


def test_bilinear_terrain_reproduces_a_plane():
    t = Terrain(_plane_dem())
    for x, y in [(0.0, 0.0), (1.23, -3.3), (7.7, 2.1)]:
        assert t.height(x, y) == pytest.approx(0.1 * x - 0.2 * y + 1.0, abs=1e-12)
    assert t.max_slope == pytest.approx(math.hypot(0.1, 0.2), rel=1e-12)


def test_terrain_nodata_takes_nearest_valid():
    h = np.array([[1.0, 2.0], [np.nan, 4.0]])
    t = Terrain(ElevationModel(h, 0.0, 0.0, 1.0))
    assert t.height(0.0, 1.0) == 1.0          # the NaN cell [1, 0] took its nearest neighbour [0, 0]


def test_ray_hits_sloped_plane_where_the_algebra_says():
    w = World.build(dem=_plane_dem())
    o = np.array([0.5, 0.5, 4.0])
    d = np.array([0.6, 0.3, -0.5])
    d /= np.linalg.norm(d)
    # plane z = a x + b y + c  ->  oz + t dz = a (ox + t dx) + b (oy + t dy) + c
    a, b, c = 0.1, -0.2, 1.0
    t_exact = (a * o[0] + b * o[1] + c - o[2]) / (d[2] - a * d[0] - b * d[1])
    assert w.raycast(*o, *d, 50.0) == pytest.approx(t_exact, abs=1e-5)
    # straight down from 2.5 m above the plane
    z0 = a * 0.5 + b * 0.5 + c
    assert w.raycast(0.5, 0.5, z0 + 2.5, 0.0, 0.0, -1.0, 10.0) == pytest.approx(2.5, abs=1e-6)
    assert w.raycast(0.5, 0.5, z0 + 2.5, 0.0, 0.0, -1.0, 2.0) == math.inf


def test_flat_ground_down_ray_and_horizontal_ray():
    w = World.build()
    assert w.raycast(3.0, 4.0, 1.5, 0.0, 0.0, -1.0, 10.0) == 1.5
    assert w.raycast(3.0, 4.0, 1.5, 1.0, 0.0, 0.0, 100.0) == math.inf
    d = np.array([1.0, 0.0, -1.0]) / math.sqrt(2)
    assert w.raycast(0.0, 0.0, 2.0, *d, 10.0) == pytest.approx(2.0 * math.sqrt(2), rel=1e-15)


def test_vine_row_cell_at_known_distance():
    occ = np.zeros((100, 100), bool)
    occ[40:60, 70] = True                           # a row segment: x in [7.0, 7.1), y in [4, 6)
    w = World.build(_grid(occ), canopy_height_m=2.0)
    # from (2, 5, 1) looking east: the west face of column 70 is at x = 7.0
    assert w.raycast(2.0, 5.0, 1.0, 1.0, 0.0, 0.0, 20.0) == pytest.approx(5.0, abs=1e-8)
    # looking west from the other side: east face at x = 7.1
    assert w.raycast(9.0, 5.0, 1.0, -1.0, 0.0, 0.0, 20.0) == pytest.approx(1.9, abs=1e-8)
    # above the canopy (2 m): misses; beside the segment (y = 3): misses
    assert w.raycast(2.0, 5.0, 2.5, 1.0, 0.0, 0.0, 20.0) == math.inf
    assert w.raycast(2.0, 3.0, 1.0, 1.0, 0.0, 0.0, 20.0) == math.inf
    # descending from above onto the canopy top (z = 2) over the cell
    assert w.raycast(7.05, 5.0, 3.0, 0.0, 0.0, -1.0, 20.0) == pytest.approx(1.0, abs=1e-12)
    # shorter max range than the row: nothing
    assert w.raycast(2.0, 5.0, 1.0, 1.0, 0.0, 0.0, 4.9) == math.inf


def test_rotated_grid_row_face():
    occ = np.zeros((50, 50), bool)
    occ[:, 30] = True                               # a full row at grid x in [3.0, 3.1)
    yaw = math.radians(30.0)
    w = World.build(_grid(occ, origin=(1.0, 2.0), yaw=yaw))
    # ray along the grid's x axis from grid point (0.5, 2.5)
    c, s = math.cos(yaw), math.sin(yaw)
    ox, oy = 1.0 + c * 0.5 - s * 2.5, 2.0 + s * 0.5 + c * 2.5
    assert w.raycast(ox, oy, 1.0, c, s, 0.0, 10.0) == pytest.approx(2.5, abs=1e-8)


def test_row_traversal_matches_dense_sampling():
    """The distance-transform leaps never skip a cell: compare with a 1 mm march."""
    rng = np.random.default_rng(7)
    occ = rng.random((60, 80)) < 0.02
    dem = ElevationModel(np.zeros((2, 2)), 0.0, 0.0, 10.0)
    grid = _grid(occ, res=0.1)
    w = World.build(grid, dem, canopy_height_m=1.0)
    for _ in range(40):
        o = np.array([rng.uniform(0, 8), rng.uniform(0, 6), rng.uniform(0.2, 1.5)])
        d = rng.normal(size=3) * np.array([1, 1, 0.15])
        d /= np.linalg.norm(d)
        got = w.rows.raycast(*o, *d, 6.0)
        ref = math.inf
        for t in np.arange(0.0, 6.0, 1e-3):
            x, y, z = o + t * d
            r, c = int(y / 0.1), int(x / 0.1)
            if 0 <= r < 60 and 0 <= c < 80 and occ[r, c] and 0.0 <= z <= 1.0:
                ref = t
                break
        if math.isinf(ref):
            assert math.isinf(got) or got > 6.0 - 2e-3
        else:
            assert got == pytest.approx(ref, abs=1.5e-3)


def test_cylinder_distance_is_centre_distance_minus_radius():
    obs = (ObstacleConfig("cylinder", x=10.0, y=3.75, height=3.0, radius=0.3),)
    w = World.build(obstacles=obs)
    assert w.raycast(4.0, 3.75, 1.5, 1.0, 0.0, 0.0, 20.0) == pytest.approx(6.0 - 0.3, abs=1e-12)
    # above it: the ray passes
    assert w.raycast(4.0, 3.75, 3.5, 1.0, 0.0, 0.0, 20.0) == math.inf
    # from above onto the top cap
    assert w.raycast(10.1, 3.75, 5.0, 0.0, 0.0, -1.0, 20.0) == pytest.approx(2.0, abs=1e-12)
    # off-centre chord: x distance to the circle at lateral offset 0.18
    assert w.raycast(4.0, 3.93, 1.0, 1.0, 0.0, 0.0, 20.0) == pytest.approx(6.0 - math.sqrt(0.09 - 0.0324), abs=1e-12)


def test_box_faces_and_rotated_corner():
    box = ObstacleConfig("box", x=5.0, y=0.0, height=2.0, size_x=2.0, size_y=1.0)
    w = World.build(obstacles=(box,))
    assert w.raycast(0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 20.0) == pytest.approx(4.0, abs=1e-12)
    assert w.raycast(5.0, -3.0, 1.0, 0.0, 1.0, 0.0, 20.0) == pytest.approx(2.5, abs=1e-12)
    rot = ObstacleConfig("box", x=5.0, y=0.0, height=2.0, size_x=1.0, size_y=1.0, yaw_deg=45.0)
    w = World.build(obstacles=(rot,))
    assert w.raycast(0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 20.0) == pytest.approx(5.0 - math.sqrt(0.5), abs=1e-12)


def test_obstacle_stands_on_sloped_terrain():
    dem = _plane_dem()
    cyl = ObstacleConfig("cylinder", x=2.0, y=1.0, height=1.0, radius=0.5)
    w = World.build(dem=dem, obstacles=(cyl,))
    base = 0.1 * 2.0 - 0.2 * 1.0 + 1.0
    # a horizontal ray just above the base hits it; just above the top misses
    assert w.obstacles[0].raycast(-1.0, 1.0, base + 0.9, 1.0, 0.0, 0.0, 20.0) == pytest.approx(2.5, abs=1e-12)
    assert w.obstacles[0].raycast(-1.0, 1.0, base + 1.1, 1.0, 0.0, 0.0, 20.0) == math.inf


def test_first_free_cell():
    occ = np.zeros((3, 3), bool)
    free = np.zeros((3, 3), bool)
    free[1, 2] = True
    w = World.build(OccupancyGrid(occ, free, 0.5, (10.0, 20.0)))
    assert w.first_free_cell_enu() == pytest.approx((11.25, 20.75))


def test_ray_from_the_ground_looking_up_or_along_does_not_hit_it():
    w = World.build(dem=_plane_dem())
    z0 = 0.1 * 0.5 - 0.2 * 0.5 + 1.0
    assert w.raycast(0.5, 0.5, z0, 0.0, 0.0, 1.0, 10.0) == math.inf
    assert w.raycast(0.5, 0.5, z0, 0.0, 0.0, -1.0, 10.0) == 0.0
    assert w.raycast(0.5, 0.5, z0 - 0.01, 0.0, 0.0, 1.0, 10.0) == 0.0    # from under the ground


def test_ray_starting_on_a_cell_boundary_moving_down_index_terminates():
    """A ray starting exactly on a cell edge with a -4e-21 x component (from a
    rotation matrix's rounding) used to creep by 1e-9 m per step."""
    occ = np.zeros((40, 40), dtype=bool)
    occ[30, :] = True                                     # a row at y in [3.0, 3.1]
    w = World.build(grid=_grid(occ))
    assert w.raycast(2.0, 1.0, 0.5, -3.9e-21, 1.0, 0.0, 10.0) == pytest.approx(2.0)
    assert w.raycast(2.0, 1.0, 0.5, 1e-300, 1.0, 0.0, 10.0) == pytest.approx(2.0)
    assert w.raycast(2.0, 3.5, 0.5, -3.9e-21, -1.0, 0.0, 10.0) == pytest.approx(0.4)


def test_a_fan_with_its_ground_and_near_obstacles_casts_the_same_rays():
    """``near_obstacles`` drops only solids whose bounding sphere is out of reach (a
    cylinder 6 m away from a 5 m fan; the one 2 m away stays), and casting with the
    fan's ground height and that subset gives every ray's distance bit for bit."""
    dem = _plane_dem()
    obs = (ObstacleConfig("cylinder", x=2.0, y=1.0, height=1.5, radius=0.3),
           ObstacleConfig("box", x=0.5, y=-1.0, height=2.0, size_x=0.8, size_y=0.4, yaw_deg=30.0),
           ObstacleConfig("cylinder", x=6.0, y=0.0, height=1.0, radius=0.2))
    w = World.build(dem=dem, obstacles=obs)
    o = (0.0, 0.0, 1.0 + 0.8)                                  # 0.8 m above the plane's height at the origin
    near = w.near_obstacles(*o, 5.0)
    assert near == w.obstacles[:2]
    # the far cylinder's sphere: centre ~6.0 m away, radius hypot(0.2, 0.5) = 0.54 m: out of a 5 m reach,
    # within a 5.5 m one
    assert w.obstacles[2] in w.near_obstacles(*o, 5.5)
    ground = w.terrain.height(o[0], o[1])
    assert ground == pytest.approx(1.0, abs=1e-12)
    rng = np.random.default_rng(4)
    hits = 0
    for d in rng.normal(size=(500, 3)):
        d = d / np.linalg.norm(d)
        full = w.raycast(*o, *d, 5.0)
        assert w.raycast(*o, *d, 5.0, ground, near) == full
        hits += math.isfinite(full)
    assert hits > 100
