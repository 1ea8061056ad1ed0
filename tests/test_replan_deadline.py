"""The trajectory phase's deadline follows the plan being flown (``companion.flight.core.
replan_deadline``, docs/replan.md "Modes and events"): 3 x its duration left + 120 s from
when it was installed, and a new plan never shortens it. Hand-worked times."""

from __future__ import annotations

import pytest

from companion.flight.core import replan_deadline


def test_the_first_plan_sets_it():
    # a 45 s cut started at t = 10 s: 10 + 3 x 45 + 120
    assert replan_deadline(10.0, 45.0) == pytest.approx(265.0)


def test_a_longer_re_route_extends_it_a_short_rejoin_does_not_shorten_it():
    d = replan_deadline(10.0, 45.0)
    # flight 10's shape: a re-route at t = 60 s leaves 210 s of plan: 60 + 630 + 120
    d = replan_deadline(60.0, 210.0, d)
    assert d == pytest.approx(810.0)
    # a rejoin at t = 100 s with 5 s left would give 235 s: the deadline stays
    assert replan_deadline(100.0, 5.0, d) == pytest.approx(810.0)
    # a plan already over (its end behind): the extra time alone, and still never earlier
    assert replan_deadline(900.0, -3.0, d) == pytest.approx(1020.0)
