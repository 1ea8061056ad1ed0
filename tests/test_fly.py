"""``companion fly`` helpers that need no vehicle: the ``--cut`` flight plan."""

from __future__ import annotations

import numpy as np
import pytest

from companion.bundled import missions_dir
from companion.flight_plan import FlightPlan
from mavcore.mission import load_mission
from companion.planner import plan_mission


@pytest.fixture(scope="module")
def flat():
    mission = load_mission(missions_dir() / "flat-rectangle" / "mission.yaml")
    return mission, FlightPlan.from_plan(plan_mission(mission))


@pytest.mark.parametrize("cut_s", [0.5, 8.0, 30.0, 1e6])
def test_cut_keeps_a_prefix_and_ends_at_rest(flat, cut_s):
    mission, fp = flat
    cut = fp.cut(cut_s, mission.trajectory)
    n = len(cut.waypoints_t_s)
    t = fp.waypoints_t_s
    # a prefix of the way-points, lasting at least cut_s (or the whole plan)
    assert 2 <= n <= len(t)
    np.testing.assert_array_equal(cut.waypoints_p_enu_m, fp.waypoints_p_enu_m[:n])
    assert cut.waypoints_t_s[-1] - t[0] >= min(cut_s, t[-1] - t[0])
    # ... and only one way-point past the cut
    assert n == len(t) or cut.waypoints_t_s[-2] - t[0] < cut_s
    # the re-solved trajectory stops at its last way-point: v and a vanish there
    end = cut.trajectory.sample(np.array([cut.waypoints_t_s[-1]]))
    assert np.linalg.norm(end.v[0]) < 0.02          # m/s, soft constraint with S_v = 60
    assert np.linalg.norm(end.p[0] - cut.waypoints_p_enu_m[-1]) < 0.01


def test_pointing_target_recovered_from_rays():
    from companion.commands.fly import pointing_target_from_rays

    rng = np.random.default_rng(3)
    target = np.array([4.0, -2.0, 1.5])
    p = rng.uniform(-10, 10, size=(50, 3))
    s = (target - p) / np.linalg.norm(target - p, axis=1, keepdims=True)
    np.testing.assert_allclose(pointing_target_from_rays(p, s, "x"), target, atol=1e-9)


def test_pointing_target_from_parallel_rays_is_an_error():
    from companion.commands.fly import pointing_target_from_rays
    from mavcore.errors import PlanError

    p = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
    s = np.tile([0.0, 1.0, 0.0], (3, 1))
    with pytest.raises(PlanError):
        pointing_target_from_rays(p, s, "plan.json")
