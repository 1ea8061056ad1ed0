"""The SITL rangefinder resolves its whole field of view (sitl/fov.py, sitl/sensors.py).

Every expected range is worked by hand from the geometry: a level sensor at
z = 1.5 m looking along +x (22.5 deg wide, 2 deg tall: the obstacle-* missions'
ring beams), a post of radius r = 0.05 m whose axis is D = 3 m away.

- post centre inside the field of view (|azimuth| <= 11.25 deg): the nearest
  surface point is straight toward the axis, at D - r;
- centre outside by delta: the nearest point in view is on the edge of the
  field of view (the vertical face at azimuth 11.25 deg, at the sensor's
  height): the edge ray passes the axis at D sin(delta) and enters the post at
  D cos(delta) - sqrt(r^2 - D^2 sin^2(delta)), if D sin(delta) < r; else the
  post is out of view.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavcore.mission.sim import ObstacleConfig, RangefinderConfig
from sitl.fov import Pyramid, project_pyramid
from sitl.sensors import Rangefinder, fan_directions_flu
from sitl.world import World

D, R_POST, Z0 = 3.0, 0.05, 1.5
HALF_H = 11.25
RING = RangefinderConfig(id=0, orientation=0, hfov_deg=22.5, vfov_deg=2.0, max_m=10.0, min_m=0.1)
LEVEL = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


def _yaw9(psi):
    c, s = math.cos(psi), math.sin(psi)
    return (c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)


def _post(az_deg, height=3.0, radius=R_POST, dist=D, yaw=0.0):
    a = math.radians(az_deg) + yaw
    return ObstacleConfig(type="cylinder", x=dist * math.cos(a), y=dist * math.sin(a), radius=radius, height=height)


def _expected_post(az_deg):
    delta = math.radians(abs(az_deg) - HALF_H)
    if delta <= 0.0:
        return D - R_POST
    off = D * math.sin(delta)
    if off >= R_POST:
        return math.inf
    return D * math.cos(delta) - math.sqrt(R_POST ** 2 - off ** 2)


def _fan_only(world, cfg, p, R):
    """The old model: the minimum over the five rays of ``fan_directions_flu``."""
    Rm = np.array(R).reshape(3, 3)
    return min(world.raycast(*p, *(Rm @ np.array(r)), cfg.max_m) for r in fan_directions_flu(cfg))


@pytest.mark.parametrize("az_deg", [0.0, 3.0, 5.625, -8.0, 11.25, -11.25, 11.8, -12.0, 12.1])
@pytest.mark.parametrize("yaw", [0.0, 2.1])
def test_thin_post_in_view_returns_its_true_range(az_deg, yaw):
    world = World.build(obstacles=(_post(az_deg, yaw=yaw),))
    d = Rangefinder(RING, 0).true_distance(world, (0.0, 0.0, Z0), _yaw9(yaw))
    expect = _expected_post(az_deg)
    assert math.isfinite(expect)
    assert d == pytest.approx(expect, abs=0.02)
    assert d >= expect - 1e-9          # a real surface point: never nearer than the truth


@pytest.mark.parametrize("az_deg", [12.35, -12.5, 14.0, 30.0, 180.0])
def test_post_just_outside_the_field_of_view_is_not_seen(az_deg):
    # D sin(12.35 - 11.25 deg) = 0.0576 m > r: the edge ray passes beside it
    assert _expected_post(az_deg) == math.inf
    world = World.build(obstacles=(_post(az_deg),))
    assert Rangefinder(RING, 0).true_distance(world, (0.0, 0.0, Z0), LEVEL) == math.inf


def test_the_old_five_ray_fan_missed_a_post_between_its_rays():
    # the reference scenario: a post half-way between the axis and the edge ray
    # (5.625 deg) passes 3 sin(5.625 deg) = 0.294 m from both rays
    world = World.build(obstacles=(_post(5.625),))
    assert _fan_only(world, RING, (0.0, 0.0, Z0), LEVEL) == math.inf
    assert Rangefinder(RING, 0).true_distance(world, (0.0, 0.0, Z0), LEVEL) == pytest.approx(D - R_POST, abs=1e-6)


def test_short_post_seen_over_its_top_edge_within_the_vertical_field():
    # top at 1.45 m, 0.05 m under the sensor: the nearest rim point is at
    # elevation -atan(0.05 / 2.95) = -0.97 deg, inside the +-1 deg field
    world = World.build(obstacles=(_post(4.0, height=1.45),))
    d = Rangefinder(RING, 0).true_distance(world, (0.0, 0.0, Z0), LEVEL)
    assert d == pytest.approx(math.hypot(D - R_POST, 0.05), abs=1e-4)
    # top at 1.40 m: the lowest ray of the field (-1 deg) reaches z = 1.5 - 3.05 tan(1 deg)
    # = 1.447 m above the far side of the post: out of view
    low = World.build(obstacles=(_post(4.0, height=1.40),))
    assert Rangefinder(RING, 0).true_distance(low, (0.0, 0.0, Z0), LEVEL) == math.inf


def test_flat_ground_from_a_tilted_beam_is_at_its_steepest_edge():
    # pitched 30 deg down, 10 deg tall: the steepest ray in view is 35 deg down
    cfg = RangefinderConfig(id=0, orientation=100, rotation_flu_deg=(0.0, 30.0, 0.0),
                            hfov_deg=10.0, vfov_deg=10.0, max_m=20.0)
    d = Rangefinder(cfg, 0).true_distance(World.build(), (0.0, 0.0, 2.0), LEVEL)
    assert d == pytest.approx(2.0 / math.sin(math.radians(35.0)), abs=1e-9)


def test_analytic_result_matches_a_dense_ray_fan_on_boxes_and_posts():
    # an independent computation: 601 x 33 rays over the field of view, each
    # cast through the world; the analytic minimum is a ray in view (>= the
    # true minimum) and no ray of the dense fan may beat it by more than 2 cm
    cfg = RangefinderConfig(id=0, orientation=0, hfov_deg=22.5, vfov_deg=8.0, max_m=10.0)
    rng = np.random.default_rng(7)
    obstacles = []
    for _ in range(6):
        az, dist = rng.uniform(-15.0, 15.0), rng.uniform(1.5, 6.0)
        a = math.radians(az)
        if rng.random() < 0.5:
            obstacles.append(ObstacleConfig(type="cylinder", x=dist * math.cos(a), y=dist * math.sin(a),
                                            radius=float(rng.uniform(0.05, 0.3)), height=float(rng.uniform(1.0, 2.5))))
        else:
            obstacles.append(ObstacleConfig(type="box", x=dist * math.cos(a), y=dist * math.sin(a),
                                            size_x=float(rng.uniform(0.1, 0.8)), size_y=float(rng.uniform(0.1, 0.8)),
                                            height=float(rng.uniform(1.0, 2.5)), yaw_deg=float(rng.uniform(0, 90))))
    th, tv = math.tan(math.radians(11.25)), math.tan(math.radians(4.0))
    for ob in obstacles:
        world = World.build(obstacles=(ob,))
        d = Rangefinder(cfg, 0).true_distance(world, (0.0, 0.0, Z0), LEVEL)
        dense = math.inf
        for b in np.linspace(-tv, tv, 33):
            for a in np.linspace(-th, th, 601):
                u = np.array([1.0, a, b]) / math.sqrt(1.0 + a * a + b * b)
                dense = min(dense, world.raycast(0.0, 0.0, Z0, *u, 10.0))
        if dense == math.inf:
            assert d == math.inf
        else:
            assert dense - 0.02 <= d <= dense + 1e-9


def test_a_row_in_front_hides_a_post_behind_it():
    # a wide box between the sensor and the post: the post's nearest point in
    # view is behind it, and the box face (x = 1.0) is what the beam returns
    wall = ObstacleConfig(type="box", x=1.1, y=0.0, size_x=0.2, size_y=3.0, height=3.0)
    world = World.build(obstacles=(_post(5.625), wall))
    assert Rangefinder(RING, 0).true_distance(world, (0.0, 0.0, Z0), LEVEL) == pytest.approx(1.0, abs=1e-9)


def test_pyramid_projection_is_the_nearest_point_of_the_cone():
    # an independent check: the projection is in K, and no sampled point of K is nearer
    a, b = math.tan(math.radians(11.25)), math.tan(math.radians(1.0))
    rng = np.random.default_rng(3)
    cone = [np.array([x, x * u * a, x * v * b]) for x, u, v in
            zip(rng.uniform(0, 6, 4000), rng.uniform(-1, 1, 4000), rng.uniform(-1, 1, 4000))]
    cone = np.array(cone)
    for p in rng.uniform(-4, 4, (40, 3)):
        q = np.array(project_pyramid(*p, a, b))
        assert abs(q[1]) <= a * q[0] + 1e-9 and abs(q[2]) <= b * q[0] + 1e-9
        assert np.linalg.norm(q - p) <= np.min(np.linalg.norm(cone - p, axis=1)) + 1e-9
    # Moreau: the ground from a level beam 1 deg tall is 1.5 / sin(1 deg) away
    fov = Pyramid((0.0, 0.0, 1.5), LEVEL, a, b, 100.0)
    assert fov.ground_distance(0.0) == pytest.approx(1.5 / math.sin(math.radians(1.0)), rel=1e-12)
