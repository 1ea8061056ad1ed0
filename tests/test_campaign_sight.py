"""campaign.sight: how long the nearest mover had been in the vehicle's line of sight.

The scene is hand-built: a vehicle hovering at the origin (1 m up, flat ground), a
wall (a static box, 3 m tall) covering x in [-8, -1], y in [1.9, 2.1], and a walker
(radius 0.25 m, 1.8 m tall) walking along y = 4 toward +x at 1 m/s from x = -6.

Expected values, worked by hand (no sphere tracing): the point of the walker nearest
the vehicle lies on the line from the origin to its centre c = (t - 6, 4), at the
vehicle's height, so the sight line crosses the wall's far face y = 2.1 at
x = 2.1 (t - 6) / 4; it passes the wall's end x = -1 once 2.1 (t - 6) / 4 > -1,
i.e. t > 6 - 4 / 2.1 = 4.095 s. The walker is nearest at t = 6 s (c = (0, 4)):
in sight for 1.905 s then, first seen at clearance |c(4.095)| - 0.25 - r.
"""

from __future__ import annotations

import math

import pytest

from companion.campaign.sight import PERIOD_S, line_of_sight, mover_sight, nearest_point
from mavcore.geometry import Box, Cylinder, SceneGeometry
from mavcore.mission.sim import MoverConfig, WALKER_RADIUS_M

WALL = Box(x_m=-4.5, y_m=2.0, base_z_m=0.0, top_z_m=3.0, half_x_m=3.5, half_y_m=0.1)
SCENE = SceneGeometry((WALL,), None, lambda x, y: 0.0)
RADIUS = 0.5
T_EMERGE = 6.0 - 4.0 / 2.1
T_NEAREST = 6.0


def _hover(t_end: float, dt: float = 0.004):
    n = int(round(t_end / dt)) + 1
    return [k * dt for k in range(n)], [(0.0, 0.0, 1.0)] * n


def test_nearest_point_of_a_cylinder_and_a_yawed_box():
    cyl = Cylinder(1.0, 2.0, 0.0, 1.8, 0.25)
    # outside: on the line to the axis, at the radius, height clamped to the top
    assert nearest_point(cyl, 4.0, 6.0, 3.0) == pytest.approx((1.0 + 0.25 * 0.6, 2.0 + 0.25 * 0.8, 1.8))
    box = Box(0.0, 0.0, 0.0, 1.0, 2.0, 0.5, math.radians(90.0))   # long axis along north
    # a point due east at mid-height: the box's east face is at x = half_y = 0.5
    assert nearest_point(box, 3.0, 1.0, 0.5) == pytest.approx((0.5, 1.0, 0.5))
    # north of its end: the end face is at y = half_x = 2
    assert nearest_point(box, 0.2, 5.0, 0.5) == pytest.approx((0.2, 2.0, 0.5))


def test_line_of_sight_is_blocked_by_the_wall_only_where_it_stands():
    assert not line_of_sight(SCENE, (0.0, 0.0, 1.0), (-2.0, 4.0, 1.0))     # crosses y = 2 at x = -1.0 .. -1.05
    assert line_of_sight(SCENE, (0.0, 0.0, 1.0), (-1.5, 4.0, 1.0))         # crosses at x = -0.71 .. -0.79
    assert line_of_sight(SCENE, (0.0, 0.0, 4.0), (-4.0, 4.0, 4.0))         # over the wall's top
    assert not line_of_sight(SCENE, (0.0, 0.0, 1.0), (0.0, 0.0, -1.0))     # into the ground


def test_a_walker_emerging_from_behind_a_wall_is_in_sight_from_then_on():
    walker = MoverConfig("walker", ((-6.0, 4.0), (6.0, 4.0)), 1.0)
    t, p = _hover(8.0)
    (f,) = mover_sight((walker,), SCENE, t, p, RADIUS, reach_m=10.0)
    assert f["t_s"] == pytest.approx(T_NEAREST, abs=0.004)                 # one track frame
    assert f["min_clearance_m"] == pytest.approx(4.0 - WALKER_RADIUS_M - RADIUS, abs=1e-5)
    # sampled every PERIOD_S: the first sample in sight is at most one period after T_EMERGE
    assert T_NEAREST - T_EMERGE - PERIOD_S - 0.004 <= f["in_sight_s"] <= T_NEAREST - T_EMERGE + 0.004
    c_at = math.hypot(T_EMERGE - 6.0, 4.0) - WALKER_RADIUS_M - RADIUS
    assert c_at - PERIOD_S * 1.0 - 0.004 <= f["sighted_m"] <= c_at + 1e-9     # it walks 0.1 m per period


def test_a_walker_that_stops_behind_the_wall_is_hidden_at_its_closest():
    walker = MoverConfig("walker", ((-6.0, 4.0), (-3.0, 4.0)), 1.0)
    t, p = _hover(5.0)
    (f,) = mover_sight((walker,), SCENE, t, p, RADIUS, reach_m=10.0)
    assert f["min_clearance_m"] == pytest.approx(5.0 - WALKER_RADIUS_M - RADIUS, abs=1e-5)
    assert f["in_sight_s"] == 0.0 and f["sighted_m"] is None


def test_beyond_the_rangefinders_reach_nothing_is_in_sight():
    walker = MoverConfig("walker", ((-6.0, 4.0), (6.0, 4.0)), 1.0)
    t, p = _hover(8.0)
    (f,) = mover_sight((walker,), SCENE, t, p, RADIUS, reach_m=3.5)      # nearest point 3.75 m away
    assert f["in_sight_s"] == 0.0 and f["sighted_m"] is None
