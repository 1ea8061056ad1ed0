"""Re-routes lifted over the obstacles the vehicle knows (companion.replan.lift, issue 15).

A flat field (z = 0), a route along y = 0 at 1.5 m, one 0.1 m voxel centred at
(5, 0, 0.75): its box is x, y in 5 -+ 0.05, z in [0.7, 0.8]. The centre keeps
R = 0.942 + 0.2 = 1.142 m (airframe 0.442 + clearance 0.5, and the margin),
ramps at 0.5 (0.5 m/s up at 1 m/s on). Worked by hand:

- over the box the route flies at 0.8 + 1.142 = 1.942 m: a lift of 0.442 m;
- nothing is required where the box is farther than R + half a sample (0.05 m)
  horizontally, |x - 5| >= 0.05 + 1.142 + 0.05 = 1.242 m, and the ramps reach at
  most 0.442 / 0.5 = 0.884 m beyond that: no lift for |x - 5| >= 2.126 m;
- the route clears the box by R: checked with the box's exact 3-D distance.
"""

from __future__ import annotations

import numpy as np
import pytest

from companion.replan.lift import SIMPLIFY_M, STEP_M, Over, lift


class Flat:
    def height_at(self, x, y):
        return np.zeros_like(np.asarray(x, float))


AGL, KEEP, MARGIN, VOX = 1.5, 0.942, 0.2, 0.1
PATH = np.array([[0.0, 0.0], [10.0, 0.0]])


def _over(voxels, ceiling=3.0):
    return Over(np.asarray(voxels, float).reshape(-1, 3), VOX, KEEP, MARGIN, 0.5, ceiling)


def _box_distance(p, lo, hi):
    e = np.maximum(np.maximum(np.asarray(lo) - p, p - np.asarray(hi)), 0.0)
    return np.sqrt((e * e).sum(axis=1))


def test_a_route_over_a_low_crate_climbs_it_with_ramps():
    path, terrain = lift(PATH, Flat(), AGL, _over([[5.0, 0.0, 0.75]]))
    x = np.arange(0.0, 10.0001, 0.01)
    lift_m = terrain.height_at(x, np.zeros_like(x))
    # over the box: 0.442 m, no more than the simplification above it
    top = np.abs(x - 5.0) <= 0.05
    assert lift_m[top].min() >= 0.442 - 1e-9 and lift_m.max() <= 0.442 + SIMPLIFY_M + 1e-9
    # no lift beyond the requirement's reach and the ramps
    # (the piecewise-linear simplification may stand up to SIMPLIFY_M over the sampled lift)
    assert np.all(lift_m[np.abs(x - 5.0) >= 2.126 + STEP_M] <= SIMPLIFY_M)
    # ramps no steeper than 0.5 (plus the simplification over a piece)
    assert np.max(np.abs(np.diff(lift_m)) / 0.01) <= 0.5 + 0.1
    # the route clears the box by R everywhere
    route = np.column_stack([x, 0 * x, AGL + lift_m])
    assert _box_distance(route, [4.95, -0.05, 0.7], [5.05, 0.05, 0.8]).min() >= KEEP + MARGIN - 1e-9
    # the breakpoints are way-points of the path, on it, in order, both ends kept
    xs = path[:, 0]
    assert xs[0] == 0.0 and xs[-1] == 10.0 and np.all(np.diff(xs) > 0) and np.all(path[:, 1] == 0.0)
    assert len(path) > 2


def test_a_tall_post_beside_the_route_outside_the_clearance_is_left_to_the_guard():
    dem = Flat()
    # a post 1.0 m from the route (box edge; >= 0.942, < 1.142), its top at 2.95 m: no height
    # under the ceiling clears it, and flying higher gains nothing beside it
    path, terrain = lift(PATH, dem, AGL, _over([[5.0, 1.1, 2.9]]))
    assert terrain is dem
    # 0.8 m from the route (< 0.942): no route
    assert lift(PATH, dem, AGL, _over([[5.0, 0.9, 2.9]])) is None
    # 0.95 m from it (the distance a stopped vehicle keeps, just outside 0.942): left to the guard
    path, terrain = lift(PATH, dem, AGL, _over([[5.0, 1.0, 2.9]]))
    assert terrain is dem


def test_a_crate_just_under_the_climb_limit_is_flown_at_the_cap():
    # top 1.8 m: 1.8 + 1.142 = 2.942 m is over the 2.9 m cap, 1.8 + 0.942 = 2.742 m is under
    # it: the route flies at the cap over it, a lift of 2.9 - 1.5 = 1.4 m, and keeps 1.1 m
    path, terrain = lift(PATH, Flat(), AGL, _over([[5.0, 0.0, 1.75]]))
    x = np.arange(0.0, 10.0001, 0.01)
    lift_m = terrain.height_at(x, np.zeros_like(x))
    assert lift_m.max() == pytest.approx(1.4, abs=1e-9)
    route = np.column_stack([x, 0 * x, AGL + lift_m])
    assert _box_distance(route, [4.95, -0.05, 1.7], [5.05, 0.05, 1.8]).min() >= KEEP - 1e-9


def test_nothing_near_the_route_leaves_it_as_it_was():
    dem = Flat()
    path, terrain = lift(PATH, dem, AGL, _over([[5.0, 3.0, 0.75]]))     # 3 m aside: out of reach
    assert terrain is dem and np.array_equal(path, PATH)


def test_a_top_that_needs_more_than_the_ceiling_is_no_route():
    # top 2.45 m: 2.45 + 1.142 = 3.592 m over the route, above 3 - 0.1 = 2.9 m
    assert lift(PATH, Flat(), AGL, _over([[5.0, 0.0, 2.4]])) is None
    # the same crate under a 4 m ceiling: lifted to 3.592 <= 3.9
    assert lift(PATH, Flat(), AGL, _over([[5.0, 0.0, 2.4]], ceiling=4.0)) is not None
