"""A leg's end where the path turns is a wall of the avoiding modes' corridor
(``companion.replan.corner``, docs/replan.md "The corridor walls").

Hand-worked geometry for the wall's place, and a closed-loop flight (the
analytic world of ``test_replan_closedloop``) where a climb over a low post
reaches a 90 degree corner at 2 m/s: without the wall the shaped reference ran
0.83 m past the corner into the headland (the issue's bound on the lateral
deviation is 0.5 m)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from test_replan_closedloop import CORRIDOR_Y, PATH, Cylinder, build_field, fly

from companion.replan import corner
from companion.replan import replanner as replanner_mod
from mavcore.mission.replan import ReplanConfig

L = 0.4


@pytest.mark.parametrize("turn_deg, want", [
    (90.0, L),                     # overshoot x is x off the next leg's line
    (30.0, L / 0.5),               # x sin 30 = x / 2 off it
    (60.0, L / math.sqrt(0.75)),
    (120.0, L),                    # behind the next leg's start: x from it
    (180.0, L),
    (0.0, math.inf),               # straight on: no wall
])
def test_the_wall_is_where_the_next_legs_side_wall_crosses_the_line(turn_deg, want):
    u = np.array([1.0, 0.0])
    a = math.radians(turn_deg)
    u_next = np.array([math.cos(a), math.sin(a)])
    got = corner.end_room_m(u, u_next, L)
    assert got == pytest.approx(want, rel=1e-12) if math.isfinite(want) else got == math.inf
    # and for the other hand of the turn
    got_r = corner.end_room_m(u, np.array([u_next[0], -u_next[1]]), L)
    assert got_r == got or (got_r == pytest.approx(got, rel=1e-12))


def test_the_distance_to_the_wall_along_the_leg():
    field = build_field()
    plan = field.plan
    # leg 0 runs east along the corridor to (17, 3.75), then the path turns south (90 deg)
    A, B, u, _ = plan.leg_frame(0)
    assert np.allclose(u, [1.0, 0.0]) and np.allclose(B[:2], PATH[1])
    assert corner.leg_end_wall_m(plan, 0, (10.0, CORRIDOR_Y + 0.2), L) == pytest.approx(17.0 - 10.0 + L, abs=1e-6)
    # beyond the wall: negative
    assert corner.leg_end_wall_m(plan, 0, (17.6, CORRIDOR_Y), L) == pytest.approx(-0.2, abs=1e-6)
    # the last leg ends the plan: no wall
    n_legs = len(plan.turns_enu_m) - 1
    assert corner.leg_end_wall_m(plan, n_legs - 1, (5.0, 6.25), L) == math.inf


def _off_path_m(xy) -> float:
    """Horizontal distance (m) from the plan's path (the polyline ``PATH``), by hand."""
    best = math.inf
    for a, b in zip(PATH[:-1], PATH[1:]):
        d = b - a
        t = min(1.0, max(0.0, float((xy - a) @ d) / float(d @ d)))
        best = min(best, float(np.hypot(*(xy - a - t * d))))
    return best


#: Low posts across the first corridor, 3 m and 0.5 m before its end, climbed over at 2 m/s:
#: without the wall the climb reaches the 90 degree corners at (17, 3.75) and (17, 1.25) at
#: speed and runs 0.68 m and 0.58 m off the path there (the mutation test below); with it,
#: 0.15 m and 0.20 m.
POSTS = (Cylinder(14.0, CORRIDOR_Y, 0.25, 1.6), Cylinder(16.5, CORRIDOR_Y, 0.25, 1.6))


def _corner_flight(post):
    return fly(build_field(speed_m_s=2.0), [post], t_end_s=30.0)


@pytest.mark.parametrize("post", POSTS, ids=("3m-before", "0.5m-before"))
def test_a_climb_at_speed_turns_at_the_corner_within_the_corridor(post):
    f = _corner_flight(post)
    acts = [e.action for e in f.events]
    assert acts[:2] == ["avoid", "climb"], acts
    lim = ReplanConfig().lateral_limit_m
    off = np.array([_off_path_m(p) for p in f.ref[:, :2]])
    assert off.max() <= lim                                          # every frame, every mode
    assert f.replanner.stats.max_lateral_deviation_m <= lim


@pytest.mark.parametrize("post", POSTS, ids=("3m-before", "0.5m-before"))
def test_without_the_wall_the_climb_runs_off_the_path_at_the_corner(monkeypatch, post):
    """The mutation: no wall at the leg's end. The same flights leave the corridor."""
    monkeypatch.setattr(replanner_mod, "leg_end_wall_m", lambda *a, **k: math.inf)
    f = _corner_flight(post)
    off = np.array([_off_path_m(p) for p in f.ref[:, :2]])
    assert off.max() > ReplanConfig().lateral_limit_m
