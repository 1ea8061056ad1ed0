"""The side a give-way backs away to (``Replanner._give_way_side``, docs/replan.md "Movers"):
away, along the corridor, from where the mover was last measured coming closer
(``ClosingSpeed.mover_at``).

Scene, worked by hand: the corridor runs along +x (u = (1, 0, 0)), the vehicle is still at
the origin, 1.5 m up, and one level beam points at (X, -3). A worker walks down that beam
toward the vehicle at 1.0 m/s, from (X, -3); the beam returns it on its axis every 0.05 s.
At rest every displacement of a return counts (``closing``): after the 0.3 s baseline the
approach reads 1.0 m/s, and the mover is at the newest return, whose x is X (r0 - t) / r0
(r0 = |(X, -3)|): its sign is X's. Backing away from it along the corridor means sign(-X):
forward (+1) when the worker comes from behind (X < 0), back (-1) from ahead. Mix seed 20261200, flight 194: the worker crossed 1.06 m ahead, the governor's
push (from obstacles 2.3 m to the side) leaned under 0.01 m/s along the corridor, forward, and
the old rule took the lean: the vehicle backed into the worker's line and was walked into.
"""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

from companion.replan.closing import BASELINE_S, HOLD_S, ClosingSpeed
from companion.replan.replanner import MOVER_GAP_MIN_M, Replanner

U = np.array([1.0, 0.0, 0.0])
P = np.array([0.0, 0.0, 1.5])
DT = 0.05


def _walk(closing: ClosingSpeed, x: float, t0: float = 0.0, seconds: float = 0.6, spread_m: float = 0.05) -> float:
    """Feed ``closing`` the worker's returns, coming from (``x``, -3) from ``t0``; the last time fed."""
    r0 = math.hypot(x, 3.0)
    axis = (x / r0, -3.0 / r0, 0.0)
    t = t0
    for k in range(int(round(seconds / DT)) + 1):
        t = t0 + k * DT
        r = r0 - 1.0 * (t - t0)
        hit = (axis[0] * r, axis[1] * r, 1.5)
        closing.on_hit(t, 1, hit, axis, still=True, origin_enu_m=(0.0, 0.0, 1.5), spread_m=spread_m)
    return t


def _replanner(closing: ClosingSpeed, t_s: float):
    rp = types.SimpleNamespace(closing=closing, _give_way_sign=None, _t_s=t_s)
    rp._give_way_side = types.MethodType(Replanner._give_way_side, rp)
    return rp


def test_the_mover_is_where_its_last_approach_was_measured():
    c = ClosingSpeed()
    assert c.mover_at(0.0) is None                             # nothing measured yet
    t = _walk(c, -1.0)
    assert t >= BASELINE_S
    assert c.approach_m_s(t) == pytest.approx(1.0, abs=0.02)
    r0 = math.hypot(1.0, 3.0)
    x, y, spread = c.mover_at(t)
    assert (x, y, spread) == pytest.approx((-1.0 * (r0 - t) / r0, -3.0 * (r0 - t) / r0, 0.05))
    assert c.mover_at(t + HOLD_S + 0.01) is None               # no approach counts any more


@pytest.mark.parametrize("x, side", [(-1.0, 1.0), (1.0, -1.0)])
@pytest.mark.parametrize("lean", [-0.3, 0.0, 0.3])
def test_the_vehicle_backs_away_from_where_the_mover_crosses_whatever_the_lean(x, side, lean):
    c = ClosingSpeed()
    rp = _replanner(c, _walk(c, x))
    assert rp._give_way_side(P, U, lean) == side


def test_a_mover_within_its_returns_spread_leaves_the_side_to_the_lean_then_keeps_it():
    # a wide beam at 3 m: its return may lie 0.6 m across the axis; the worker 0.4 m ahead
    # along the corridor is within that, so where it crosses is not known from it
    c = ClosingSpeed()
    t = _walk(c, 0.4, spread_m=0.6)
    rp = _replanner(c, t)
    assert rp._give_way_side(P, U, 0.2) == 1.0                 # the lean's, the first time
    assert rp._give_way_side(P, U, -0.2) == 1.0                # kept: a flipping lean moves nothing
    # nearer returns place it better: 0.4 m ahead, spread 0.05 m, decides (away: back)
    rp._t_s = _walk(c, 0.4, t0=t + DT, spread_m=0.05)
    assert rp._give_way_side(P, U, 0.2) == -1.0
    rp._t_s = _walk(c, -0.4, t0=rp._t_s + DT, spread_m=0.05)  # ... and then behind: forward
    assert rp._give_way_side(P, U, -0.2) == 1.0


def test_the_least_gap_that_decides_is_the_floor():
    c = ClosingSpeed()
    rp = _replanner(c, _walk(c, -0.5 * MOVER_GAP_MIN_M, spread_m=0.0))
    assert rp._give_way_side(P, U, -0.1) == -1.0               # nearer than the floor: the lean
    c2 = ClosingSpeed()
    rp2 = _replanner(c2, _walk(c2, -2.0 * MOVER_GAP_MIN_M, spread_m=0.0))
    assert rp2._give_way_side(P, U, -0.1) == 1.0
