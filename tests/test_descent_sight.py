"""Descents are not blind: the default suite's down array sees the footprint below.

The rings look at most 14 deg down and the single down beam 2.5 deg off the
vertical, so nothing saw a box beside and below a vehicle coming down on the
spot (obstacles-under flight 10: 0.158 m of true clearance). The default suite
now has a downward array of zones (``mavcore.mission.sim.default_rangefinders``).
Expected values here come from the geometry alone: the mounting rotations are
rebuilt with scipy's Euler convention, and the range of a box is the distance
from the sensor to the box's nearest point, worked by hand.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mavcore.mission.sim import (DEFAULT_DOWN_CONE_DEG, DEFAULT_RING_BEAMS, NoiseConfig, ObstacleConfig,
                                 SimConfig, default_rangefinders)
from sitl.sensors import SensorSuite
from sitl.world import World

QUIET = NoiseConfig(vector_variance=0.0, gyro_variance=0.0, range_std_m=0.0)
FIRST = 2 * DEFAULT_RING_BEAMS + 1


def _zones():
    return [c for c in default_rangefinders() if c.id >= FIRST]


def _in_view(c, d_flu) -> bool:
    roll, pitch, yaw = c.rotation_flu_deg
    S = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True).as_matrix()   # sensor -> body
    x, y, z = S.T @ d_flu
    th, tv = math.tan(math.radians(c.hfov_deg / 2)), math.tan(math.radians(c.vfov_deg / 2))
    return x > 0 and abs(y) <= th * x and abs(z) <= tv * x


def _directions(max_off_nadir_deg: float):
    for a in np.linspace(0.0, max_off_nadir_deg, 46):
        for b in np.linspace(0.0, 360.0, 181):
            sa = math.sin(math.radians(a))
            yield a, np.array([sa * math.cos(math.radians(b)), sa * math.sin(math.radians(b)),
                               -math.cos(math.radians(a))])


def test_the_array_sees_every_direction_within_the_cone():
    zones = _zones()
    assert len(zones) == 9 and len({c.id for c in zones}) == 9
    missed = [a for a, d in _directions(DEFAULT_DOWN_CONE_DEG) if not any(_in_view(c, d) for c in zones)]
    assert missed == []


def test_the_cone_covers_the_clearance_footprint():
    """45 deg: a point within r of the descent axis is in view once it is r or more below
    (r = 0.442 m airframe + 0.5 m clearance), so what the sphere will sink into is seen
    from the array's range down to the depth of the sphere itself."""
    r = 0.942
    for depth in (r, 1.5, 3.0):
        for lateral in (0.0, 0.5, r):
            off = math.degrees(math.atan2(lateral, depth))
            assert off <= DEFAULT_DOWN_CONE_DEG + 1e-9


def _box_distance(o, p) -> float:
    """Distance from p to an axis-aligned box standing on z = 0 (by hand: clamp)."""
    lo = np.array([o.x - o.size_x / 2, o.y - o.size_y / 2, 0.0])
    hi = np.array([o.x + o.size_x / 2, o.y + o.size_y / 2, o.height])
    q = np.minimum(np.maximum(p, lo), hi)
    return float(np.linalg.norm(p - q))


@pytest.mark.parametrize("dx, dy", [(0.7, 0.0), (0.0, -0.8), (0.6, 0.6), (-0.5, 0.3)])
def test_a_box_below_and_beside_is_returned_at_its_true_range(dx, dy):
    """A low box whose nearest point is within 45 deg of the vertical under the vehicle:
    the nearest zone returns the distance from the sensor to it (within 2 cm, the
    range's centimetre rounding and the solver's tolerance); no ring beam sees it."""
    box = ObstacleConfig(type="box", x=dx, y=dy, height=1.1, size_x=0.6, size_y=0.7)
    world = World.build(obstacles=(box,))
    p = np.array([0.0, 0.0, 2.1])
    suite = SensorSuite(SimConfig(noise=QUIET, rangefinders=default_rangefinders()), world,
                        np.random.default_rng(0))
    got = {}
    for rf in suite.rangefinders:
        r = suite.range_reading(rf, tuple(p), tuple(np.eye(3).ravel()))
        d = r.distance_m
        got[rf.cfg.id] = math.inf if d is None else d
    expected = _box_distance(box, p)
    nearest = min(d for k, d in got.items() if k >= FIRST and math.isfinite(d))
    assert nearest == pytest.approx(expected, abs=0.02)
    # nothing else sees it: the rings read beyond it (or no return), the down beam the ground
    others = [d for k, d in got.items() if k < FIRST and math.isfinite(d)]
    assert all(d > expected + 0.3 for d in others)
