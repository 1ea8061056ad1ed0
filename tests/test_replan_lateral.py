"""The lateral deviation the report gives (``replanner.lateral_offset``): the offset across
the legs being avoided, hand-worked. A stop that gives way reverses down the corridor, past
the leg's start (obstacles-wide seed 20261150 flight 5: 0.75 m "lateral" that was along the
row); that is not a swerve toward the rows."""

from __future__ import annotations

import math

import pytest

from companion.replan.replanner import lateral_offset

LEG = (((22.0, 8.75), (1.0, 8.75)),)                   # one leg, flown toward -x


@pytest.mark.parametrize("p, want", [
    ((10.0, 9.25), 0.5),                               # beside the leg
    ((22.8, 8.75), 0.0),                               # 0.8 m behind its start, on its line
    ((22.8, 8.45), 0.3),                               # behind its start, 0.3 m off the line
    ((0.2, 8.95), 0.2),                                # past its end, 0.2 m off the line
])
def test_one_leg_is_a_line(p, want):
    assert lateral_offset(p, LEG) == pytest.approx(want, abs=1e-12)


def test_inner_ends_are_not_extended():
    """Two legs meeting at a corner (an L): past the first leg's end and before the second's
    start the point is measured to the corner, not to either line run on."""
    legs = (((0.0, 0.0), (10.0, 0.0)), ((10.0, 0.0), (10.0, 10.0)))
    # 1 m beyond the corner in +x and 1 m below it in -y: 1 m from the first leg's line,
    # but its distance to the corner is sqrt(2)
    assert lateral_offset((11.0, -1.0), legs) == pytest.approx(math.sqrt(2.0))
    # the last leg runs on past its end (10, 10): a point 2 m further on is on its line
    assert lateral_offset((10.0, 12.0), legs) == pytest.approx(0.0)
    # and the first runs on behind its start
    assert lateral_offset((-3.0, 0.4), legs) == pytest.approx(0.4)


def test_the_avoided_leg_runs_on_behind_the_corner_it_began_at():
    """The avoidance moved on to the second leg of an L (the corridor after the turn) and
    gives way by backing along it, past the corner (obstacles-wide seed 20261152 flight 14:
    1.74 m "lateral" that was along the leg). Measured with the avoided leg run on behind
    its start: 0.3 m, the offset from its line; without (the first leg only): the distance
    to the corner."""
    legs = (((0.0, 0.0), (10.0, 0.0)), ((10.0, 0.0), (10.0, 10.0)))
    p = (10.3, -1.5)                                    # 1.5 m back past the corner, 0.3 m off
    assert lateral_offset(p, legs, avoided=1) == pytest.approx(0.3)
    assert lateral_offset(p, legs) == pytest.approx(math.hypot(0.3, 1.5))
    # leaving the line is still lateral: beside the avoided leg's line behind the corner
    assert lateral_offset((11.2, -0.8), legs, avoided=1) == pytest.approx(1.2)
