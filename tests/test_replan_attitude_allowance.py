"""The attitude allowance: a return is the ground when the beam, placed by an attitude
within the estimate's accuracy of the estimate, explains it (``replan.tilt_tolerance_deg`` and
``heading_tolerance_deg``: the estimate tilted about the east and north axes by half and all of
the first, turned about the vertical in 1 deg steps up to the second).

Geometry (the beam and field of ``tests/test_replan_attitude_wait.py``): a beam 20 deg
down, 0.02 rad (1.146 deg) wide, 1.5 m over flat ground, returns the ground at
1.5 / sin 20 deg = 4.39 m. The estimate has the nose 4 deg up, so the beam is placed
16 deg down: its axis point is 1.5 - 4.39 sin 16 = 0.29 m up, its lower edge
(16.573 deg) 0.25 m up, both above the 0.2 m tolerance: without the allowance, a phantom.
The vehicle heads east, so the pitch error is a turn about the world's north axis; the
allowance's largest such turn, a, brings the lower edge to 16.573 + a deg down and its
point to 1.5 - 4.39 sin(16.573 + a):

    a = 0.5 deg: 0.211 m  (still unexplained)
    a = 1   deg: 0.175 m  (the ground)
    a = 2   deg: 0.102 m  (the ground)

A real obstacle 3 m away on the same beam stays unknown with a = 2 deg: the turned edge
point is 1.5 - 3 sin 18.573 = 0.545 m up and the nearest ground in the turned field,
1.5 / sin 18.573 = 4.71 m away, is farther than 3 m + 0.2 m.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from companion.replan.perception import attitude_perturbations

from tests.test_replan_attitude_wait import D_CM, EYE, H, P, _pitch_up, _reading, _replanner

DOWN_DEG = 20.0
HALF_FOV_DEG = math.degrees(0.01)


def _edge_z(distance_m, a_deg):
    return H - distance_m * math.sin(math.radians(DOWN_DEG - 4.0 + HALF_FOV_DEG + a_deg))


@pytest.mark.parametrize("a_deg, phantom", [(0.0, True), (0.5, True), (1.0, False), (2.0, False)])
def test_the_ground_is_the_ground_within_the_attitude_tolerance(a_deg, phantom):
    z = _edge_z(D_CM / 100, a_deg)
    assert (z > 0.2) == phantom                                  # the hand-worked table above
    rp = _replanner(tilt_tolerance_deg=a_deg)
    rp.on_pose(1.15, P, _pitch_up(4.0))                          # the companion's observer: no wait
    rp.on_range(1.15, _reading(1150, D_CM))
    assert rp.n_readings == 1
    assert rp.n_unknown == (1 if phantom else 0)
    assert (len(rp.memory) > 0) == phantom


def test_an_obstacle_nearer_than_the_widened_ground_stays_unknown():
    assert _edge_z(3.0, 2.0) == pytest.approx(0.545, abs=0.005)
    assert H / math.sin(math.radians(DOWN_DEG - 4.0 + HALF_FOV_DEG + 2.0)) == pytest.approx(4.71, abs=0.01)
    rp = _replanner(tilt_tolerance_deg=2.0, heading_tolerance_deg=5.0)
    rp.on_pose(1.15, P, _pitch_up(4.0))
    rp.on_range(1.15, _reading(1150, 300))
    assert rp.n_unknown == 1 and len(rp.memory) > 0


def test_a_true_attitude_needs_no_allowance():
    rp = _replanner()
    rp.on_pose(1.15, P, EYE)
    rp.on_range(1.15, _reading(1150, D_CM))
    assert rp.n_unknown == 0


def test_the_perturbations_are_turns_about_the_world_axes():
    """Tilt 2 deg, heading 3.5 deg: the vertical at 1, 2, 3 and 3.5 deg, east and north at 1
    and 2 deg, each both ways (16), nearest first; against scipy's rotations."""
    R0 = Rotation.from_euler("zyx", [30.0, 5.0, -3.0], degrees=True).as_matrix()
    got = attitude_perturbations(tuple(R0.ravel()), math.radians(2.0), math.radians(3.5))
    want = {(ax, a) for a in (1.0, 2.0, 3.0, 3.5) for ax in "z"} | {(ax, a) for a in (1.0, 2.0) for ax in "xy"}
    want = {(ax, s * a) for ax, a in want for s in (1.0, -1.0)}
    assert len(got) == len(want) == 16
    mats = {k: Rotation.from_euler(k[0], k[1], degrees=True).as_matrix() @ R0 for k in want}
    seen = set()
    for g in got:
        G = np.asarray(g).reshape(3, 3)
        hit = [k for k, M in mats.items() if np.allclose(G, M, atol=1e-12)]
        assert len(hit) == 1
        seen.add(hit[0])
    assert seen == want
    # nearest first: the angle to R0 never decreases along the list
    ang = [np.degrees(np.arccos(np.clip((np.trace(R0.T @ np.asarray(g).reshape(3, 3)) - 1) / 2, -1, 1))) for g in got]
    assert all(b >= a - 1e-9 for a, b in zip(ang, ang[1:]))
