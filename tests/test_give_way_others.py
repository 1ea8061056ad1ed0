"""A give-way comes no nearer to another unknown obstacle than to the mover it backs away
from (``Replanner._govern_others``, docs/replan.md "Movers").

Scene, worked by hand: the vehicle at the origin, 1.5 m up, backs away along +x at 1.5 m/s
from a mover measured at (-2.4, 0) (returns spread 0.05 m). Another unknown obstacle point
stands on the x axis at X. The governor's stopping law (``Replanner._allowed_speed``): the
largest v with v^2 / (2 a_b) + v t_lag = room, a_b = half of ``replan.accel_m_s2`` (1 m/s^2)
and t_lag = ``GOVERNOR_LAG_S``; here the room is X - 2.4, the point's distance beyond the
mover's. Fresh seed 20261226 flight 0 and mix seed 20261200 flight 71: a false approach
behind sent the give-way toward a worker ahead, who then walked into the vehicle.
"""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

from companion.replan.closing import MATCH_M
from companion.replan.replanner import GOVERNOR_LAG_S, Replanner

P = np.array([0.0, 0.0, 1.5])
FLEE = np.array([1.5, 0.0, 0.0])
MOVER = (-2.4, 0.0, 0.05)
A_B = 0.5            # half the default 1 m/s^2


def _replanner(mover=MOVER):
    rp = types.SimpleNamespace(closing=types.SimpleNamespace(mover_at=lambda t: mover), _t_s=10.0, _brake=A_B)
    rp._allowed_speed = types.MethodType(Replanner._allowed_speed, rp)
    rp._govern_others = types.MethodType(Replanner._govern_others, rp)
    return rp


def _law(v: float) -> float:
    """The room (m) a speed v needs: the stopping law itself."""
    return v * v / (2.0 * A_B) + v * GOVERNOR_LAG_S


@pytest.mark.parametrize("x", [3.0, 3.4, 4.4, 5.0])
def test_the_approach_to_another_obstacle_stops_where_it_is_as_near_as_the_mover(x):
    v = _replanner()._govern_others(P, FLEE, np.array([[x, 0.0, 1.5]]))
    assert v[1] == v[2] == 0.0 and 0.0 < v[0] < FLEE[0]
    assert _law(v[0]) == pytest.approx(x - 2.4, rel=1e-9)


def test_no_approach_to_an_obstacle_nearer_than_the_mover_and_none_held_back_far_beyond():
    rp = _replanner()
    assert np.array_equal(rp._govern_others(P, FLEE, np.array([[2.0, 0.0, 1.5]])), np.zeros(3))
    assert np.array_equal(rp._govern_others(P, FLEE, np.array([[2.4, 0.0, 1.5]])), np.zeros(3))
    far = 2.4 + _law(FLEE[0]) + 0.01                        # room for the whole flee speed
    assert np.array_equal(rp._govern_others(P, FLEE, np.array([[far, 0.0, 1.5]])), FLEE)


def test_points_the_command_does_not_close_on_and_the_movers_own_do_not_hold_it_back():
    rp = _replanner()
    assert np.array_equal(rp._govern_others(P, FLEE, np.array([[0.0, 1.0, 1.5], [-1.0, -1.0, 1.5]])), FLEE)
    # a mover crossing ahead: its returns within MATCH_M (and their spread) of where it was
    # measured are the mover's, whatever the command closes on
    crossing = (0.3, -1.2, 0.05)
    own = np.array([[0.3 + 0.9 * MATCH_M, -1.2, 1.5]])
    assert np.array_equal(_replanner(crossing)._govern_others(P, FLEE, own), FLEE)
    beyond = np.array([[0.3 + 1.1 * MATCH_M + 0.05, -1.2, 1.5]])
    d_m = math.hypot(0.3, 1.2)
    v = _replanner(crossing)._govern_others(P, FLEE, beyond)
    off = beyond[0, :2] - P[:2]
    approach = float(off @ v[:2]) / float(np.hypot(*off))
    assert _law(approach) == pytest.approx(float(np.hypot(*off)) - d_m, rel=1e-9)


def test_no_mover_measured_leaves_the_command():
    assert np.array_equal(_replanner(None)._govern_others(P, FLEE, np.array([[3.0, 0.0, 1.5]])), FLEE)
