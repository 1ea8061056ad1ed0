"""The avoidance's governor against the vine rows (``Replanner._govern_rows``, through
``Guard.row_room``): the approach to a row is at most the speed that stops the governor's
margin short of the distance the guard makes the reference keep.

Scene as tests/test_safety_guard.py: one row, cells x in [5.0, 5.2], y in [0, 5.0], canopy
2 m, flat ground; R = 0.4, clearance 0.5: the guard keeps 0.9 m less half a 0.1 m cell,
0.85 m, from the row. Hand values: at (4.0, 2.5, 1.0) the row is 1.0 m away along -x
(room 0.15 m); the allowed approach solves v^2 / (2 a) + v t = room - 0.1 with a = 1 m/s^2,
t = 0.6 s: v = sqrt(0.36 + 0.1) - 0.6 = 0.0782 m/s.
"""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

from mavcore.maps.grid import ElevationModel, OccupancyGrid
from companion.replan.replanner import GOVERNOR_LAG_S, GOVERNOR_MARGIN_M, Replanner
from companion.safety import Guard, GuardConfig, SafetyScene

R, C = 0.4, 0.5
REQ = R + C - 0.05


def _guard() -> Guard:
    occ = np.zeros((100, 100), bool)
    occ[0:50, 50:52] = True
    grid = OccupancyGrid(occ, ~occ, 0.1)
    dem = ElevationModel(np.zeros((11, 11)), 0.0, 0.0, 1.0)
    cfg = GuardConfig(airframe_radius_m=R, terrain_clearance_m=C, row_clearance_m=C, obstacle_clearance_m=C,
                      accel_m_s2=1.0, delay_s=0.2)
    return Guard(cfg, SafetyScene.from_maps(grid, dem, 2.0), None)


def _replanner(guard):
    """The two members ``_govern_rows`` reads, on a bare object (a whole replanner needs a plan)."""
    rp = types.SimpleNamespace(guard=guard, _brake=1.0)
    rp._allowed_speed = types.MethodType(Replanner._allowed_speed, rp)
    rp._govern_rows = types.MethodType(Replanner._govern_rows, rp)
    return rp


@pytest.mark.parametrize("p, d, n", [
    ((4.0, 2.5, 1.0), 1.0, (-1.0, 0.0, 0.0)),                                  # beside its face
    ((5.1, 2.5, 3.0), 1.0, (0.0, 0.0, 1.0)),                                   # above the canopy
    ((4.4, 5.3, 1.0), math.hypot(0.6, 0.3), (-0.6 / math.hypot(0.6, 0.3), 0.3 / math.hypot(0.6, 0.3), 0.0)),
])
def test_row_room_is_the_distance_less_the_clearance_along_the_normal(p, d, n):
    room, nrm = _guard().row_room(p)
    assert room == pytest.approx(d - REQ, abs=1e-9)
    # central differences of 2 cm: exact beside a face; round a corner 0.67 m away the
    # distance is curved and the difference errs by about (0.02 / 0.67)^2 / 6, 1.5e-4
    assert nrm == pytest.approx(n, abs=1e-3)


def test_the_approach_to_a_row_is_the_stopping_law_the_rest_is_kept():
    rp = _replanner(_guard())
    a, t = 1.0, GOVERNOR_LAG_S
    allow = math.sqrt((a * t) ** 2 + 2 * a * (1.0 - REQ - GOVERNOR_MARGIN_M)) - a * t
    assert allow == pytest.approx(0.0782, abs=1e-4)
    v = rp._govern_rows(np.array([4.0, 2.5, 1.0]), np.array([1.0, 0.3, -0.2]))
    assert v == pytest.approx([allow, 0.3, -0.2], abs=1e-6)           # along the row and down: untouched
    away = np.array([-1.0, 0.3, 0.0])
    assert rp._govern_rows(np.array([4.0, 2.5, 1.0]), away) == pytest.approx(away)
    # inside the clearance (0.7 m < 0.85 m): no approach at all, leaving is free
    assert rp._govern_rows(np.array([4.3, 2.5, 1.0]), np.array([0.5, 0.0, 0.0])) == pytest.approx([0.0, 0.0, 0.0])
    # far from it: untouched
    assert rp._govern_rows(np.array([1.0, 2.5, 1.0]), np.array([1.0, 0.0, 0.0])) == pytest.approx([1.0, 0.0, 0.0])


def test_without_a_guard_nothing_is_governed():
    rp = _replanner(None)
    v = np.array([1.0, 0.0, 0.0])
    assert rp._govern_rows(np.array([4.9, 2.5, 1.0]), v) is v
