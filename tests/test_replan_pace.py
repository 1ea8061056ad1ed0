"""Pacing a re-route or rejoin to the guard's stopping law (companion.replan.pace, issue 15).

The stretch arithmetic is worked by hand. The paced flight is judged by the
stopping law itself, v toward the obstacle <= sqrt(2 a room + (a tau)^2) - a tau,
evaluated here from the box's exact distance (not through the guard), at
every sample of the paced trajectory.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavcore.maps.grid import ElevationModel, OccupancyGrid
from mavcore.mission.schema import FlightConfig
from companion.replan.globalplan import GlobalPlan
from companion.replan.pace import HEADROOM, MAX_TOTAL_STRETCH, pace, planned_stretch, stretch
from companion.safety import Guard, GuardConfig, SafetyScene
from companion.trajectory import generate_trajectory
from mavcore.mission.trajectory import TrajectoryConfig

R, C = 0.4, 0.5
REQ = R + C                  # the centre keeps 0.9 m from the obstacle and the ground
A_BRAKE, TAU = 1.0, 0.5
BOX_LO, BOX_HI = np.array([8.0, 7.0, 0.0]), np.array([8.5, 8.0, 3.0])


def box_distance(points) -> np.ndarray:
    p = np.asarray(points, float).reshape(-1, 3)
    e = np.maximum(np.maximum(BOX_LO - p, p - BOX_HI), 0.0)
    return np.sqrt((e * e).sum(axis=1))


def _guard() -> Guard:
    occ = np.zeros((150, 150), bool)
    grid = OccupancyGrid(occ, ~occ, 0.1)
    dem = ElevationModel(np.zeros((16, 16)), 0.0, 0.0, 1.0)
    cfg = GuardConfig(airframe_radius_m=R, terrain_clearance_m=C, row_clearance_m=C, obstacle_clearance_m=C,
                      accel_m_s2=A_BRAKE, delay_s=TAU)
    return Guard(cfg, SafetyScene.from_maps(grid, dem, 2.0), box_distance)


def _plan(x_end: float) -> tuple[GlobalPlan, np.ndarray]:
    """Along y = 7.5 at 1.5 m height from x = 0 toward the box at 1 m/s, way-points
    every 1 m (1 s), stopping at x_end; the LQR from rest at the first."""
    xs = np.arange(0.0, x_end + 1e-9, 1.0)
    if xs[-1] < x_end - 1e-9:
        xs = np.append(xs, x_end)
    P = np.column_stack([xs, np.full(len(xs), 7.5), np.full(len(xs), 1.5)])
    t = np.concatenate([[0.0], 1.0 + np.cumsum(np.diff(xs))])       # 1 s to get going
    V = np.zeros_like(P)
    V[1:-1, 0] = 1.0
    A = np.zeros_like(P)
    x0 = np.array([P[0], [0, 0, 0], [0, 0, 0], [0, 0, 0]], float)
    cfg = TrajectoryConfig()
    traj = generate_trajectory(t, P, V, A, cfg, initial_state=x0)
    corner = np.zeros(len(P), bool)
    corner[[0, -1]] = True
    plan = GlobalPlan.from_waypoints(traj, t, P, V, A, corner, None, None, FlightConfig(), cfg, 0.5)
    return plan, x0


def test_stretch_hand_worked():
    t = np.array([0.0, 1.0, 3.0, 4.0])
    v = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [0.0, 0, 0]])
    a = np.array([[0.0, 0, 0], [4.0, 0, 0], [4.0, 0, 0], [0.0, 0, 0]])
    t2, v2, a2 = stretch(t, v, a, np.array([1.0, 2.0, 1.0]))
    # the middle interval (2 s) doubles: 0, 1, 5, 6
    assert t2.tolist() == [0.0, 1.0, 5.0, 6.0]
    # way-points 1 and 2 join the doubled interval: velocity / 2, acceleration / 4; 0 and 3 keep theirs
    assert v2[:, 0].tolist() == [0.0, 0.5, 1.0, 0.0]
    assert a2[:, 0].tolist() == [0.0, 1.0, 1.0, 0.0]


def test_planned_stretch_hand_worked():
    # 4 m in 4 s (1 m/s) where 0.5 m/s is allowed: 1 / (HEADROOM * 0.5) times longer
    t = np.array([0.0, 4.0, 8.0])
    p = np.array([[0.0, 0, 1], [4.0, 0, 1], [8.0, 0, 1]])

    def limits(points, u):
        return np.where(np.asarray(points)[:, 0] <= 4.0, 0.5, np.inf)
    k = planned_stretch(t, p, limits)
    assert k[0] == pytest.approx(1.0 / (HEADROOM * 0.5))
    assert k[1] == pytest.approx(1.0 / (HEADROOM * 0.5))     # its first sample (x = 4) is limited too
    assert planned_stretch(t, p, lambda q, u: np.full(len(q), 5.0)).tolist() == [1.0, 1.0]


def test_speed_limits_follow_the_stopping_law():
    g = _guard()
    # 2 m from the box's face (x = 8), flying straight at it: room 2 - 0.9 = 1.1 m
    lim = g.speed_limits(np.array([[6.0, 7.5, 1.5]]), np.array([[1.0, 0.0, 0.0]]))[0]
    assert lim == pytest.approx(math.sqrt(2 * A_BRAKE * 1.1 + (A_BRAKE * TAU) ** 2) - A_BRAKE * TAU, abs=1e-6)
    # flying away from it, or along the ground at a height with room: no limit
    assert np.isinf(g.speed_limits(np.array([[6.0, 7.5, 1.5]]), np.array([[-1.0, 0.0, 0.0]]))[0])
    # 0.95 m from the face: room 0.05 m, a small limit; 0.85 m (inside the clearance): none,
    # no pace mends a path that closes there (the margin rule judges it)
    near = g.speed_limits(np.array([[7.05, 7.5, 1.5]]), np.array([[1.0, 0.0, 0.0]]))[0]
    assert near == pytest.approx(math.sqrt(2 * A_BRAKE * 0.05 + (A_BRAKE * TAU) ** 2) - A_BRAKE * TAU, abs=1e-6)
    assert np.isinf(g.speed_limits(np.array([[7.15, 7.5, 1.5]]), np.array([[1.0, 0.0, 0.0]]))[0])


def _worst_law_excess(traj, t0: float) -> float:
    """Largest (approach speed - stopping law) over the trajectory, from the box's exact distance."""
    t = np.arange(t0, traj.tf, 0.01)
    s = traj.sample(t)
    p, v = np.asarray(s.p), np.asarray(s.v)
    d = box_distance(p)
    approach = -np.gradient(d, t)
    allowed = np.sqrt(2 * A_BRAKE * np.maximum(d - REQ, 0.0) + (A_BRAKE * TAU) ** 2) - A_BRAKE * TAU
    return float(np.max(approach - allowed))


def test_a_route_ending_near_an_obstacle_is_paced_to_the_stopping_law():
    g = _guard()
    # stop 1.4 m before the box: 0.5 m of room. At 1 m/s the stopping law (0.62 m/s at 0.5 m
    # of room, 0.84 m/s at 0.9 m) is broken in the last metres: the guard refuses the plan.
    plan, x0 = _plan(6.6)
    assert _worst_law_excess(plan.trajectory, 0.0) > 0.05
    assert not g.check_trajectory(plan.trajectory, 0.0).ok
    paced, verdict = pace(plan, x0, g)
    assert verdict.ok, verdict.detail
    # the same path: the same way-points, the same end
    assert np.array_equal(paced.p_enu_m, plan.p_enu_m)
    end = np.asarray(paced.trajectory.sample(np.array([paced.trajectory.tf])).p)[0]
    assert end == pytest.approx([6.6, 7.5, 1.5], abs=0.02)
    # slower, but not slower than the bound on any interval
    assert paced.t_s[-1] > plan.t_s[-1]
    assert np.all(np.diff(paced.t_s) <= MAX_TOTAL_STRETCH * np.diff(plan.t_s) + 1e-9)
    # the stopping law holds at every sample, within the guard's 0.05 m/s tolerance
    assert _worst_law_excess(paced.trajectory, 0.0) <= 0.05
    # the first metres, far from the box, keep their cruise timing
    assert paced.t_s[2] == pytest.approx(plan.t_s[2])


def test_a_route_into_the_clearance_is_refused_not_paced_for_ever():
    g = _guard()
    plan, x0 = _plan(7.5)                 # ends 0.5 m from the box's face, inside the 0.9 m
    paced, verdict = pace(plan, x0, g)
    assert not verdict.ok                 # no pace gets it there: refused, in bounded tries
    assert np.all(np.diff(paced.t_s) <= MAX_TOTAL_STRETCH * np.diff(plan.t_s) + 1e-9)


def _long_plan(x0_state) -> tuple[GlobalPlan, np.ndarray]:
    """Along y = 7.5 at 1.5 m, x = 0 .. 7, 1 m/s, the LQR from ``x0_state``."""
    xs = np.arange(0.0, 7.0 + 1e-9, 1.0)
    P = np.column_stack([xs, np.full(len(xs), 7.5), np.full(len(xs), 1.5)])
    t = np.concatenate([[0.0], 1.0 + np.cumsum(np.diff(xs))])
    V = np.zeros_like(P)
    V[1:-1, 0] = 1.0
    A = np.zeros_like(P)
    cfg = TrajectoryConfig()
    traj = generate_trajectory(t, P, V, A, cfg, initial_state=x0_state)
    corner = np.zeros(len(P), bool)
    corner[[0, -1]] = True
    return GlobalPlan.from_waypoints(traj, t, P, V, A, corner, None, None, FlightConfig(), cfg, 0.5), t


def test_a_rejoin_is_new_only_until_it_flies_its_parent_again():
    from companion.replan.rejoin import CONVERGED_M, CONVERGED_M_S, converged_from

    rest = np.array([[0.0, 7.5, 1.5], [0, 0, 0], [0, 0, 0], [0, 0, 0]], float)
    parent, t = _long_plan(rest)
    # the same way-points, all 5 s later, from a state 0.3 m off the line and moving across it
    off = np.array([[0.0, 7.8, 1.6], [0.2, -0.3, 0.1], [0, 0, 0], [0, 0, 0]], float)
    cfg = TrajectoryConfig()
    child = generate_trajectory(t + 5.0, parent.p_enu_m, parent.v_enu_m_s, parent.a_enu_m_s2, cfg,
                                initial_state=off)
    tc = converged_from(child, parent.trajectory, 5.0)
    assert tc is not None and 5.0 < tc < child.tf
    # judged independently, sampled ten times finer: within the bounds after tc, not just before
    ts = np.arange(tc, child.tf, 0.005)
    a, b = child.sample(ts), parent.trajectory.sample(ts - 5.0)
    assert np.linalg.norm(np.asarray(a.p) - np.asarray(b.p), axis=1).max() <= CONVERGED_M * 1.01
    assert np.linalg.norm(np.asarray(a.v) - np.asarray(b.v), axis=1).max() <= CONVERGED_M_S * 1.01
    before = tc - 0.05
    a, b = child.sample(np.array([before])), parent.trajectory.sample(np.array([before - 5.0]))
    dp, dv = np.linalg.norm(np.asarray(a.p) - np.asarray(b.p)), np.linalg.norm(np.asarray(a.v) - np.asarray(b.v))
    assert dp > CONVERGED_M or dv > CONVERGED_M_S
    # a trajectory that never comes back onto its parent (ends 0.3 m beside it) is new to its end
    P2 = parent.p_enu_m + np.array([0.0, 0.3, 0.0])
    other = generate_trajectory(t + 5.0, P2, parent.v_enu_m_s, parent.a_enu_m_s2, cfg, initial_state=off)
    assert converged_from(other, parent.trajectory, 5.0) is None


def test_pacing_judges_a_rejoin_up_to_its_horizon_only():
    # the plan of the test above: too fast for the stopping law in its last metres. Told
    # that it is new only for its first 2 s (a rejoin that has converged onto a plan
    # accepted before), the pacing leaves the rest alone and the check passes; told
    # nothing, it paces the end
    plan, x0 = _plan(6.6)
    g = _guard()
    whole, v_whole = pace(plan, x0, g)
    assert v_whole.ok and whole.t_s[-1] > plan.t_s[-1] and whole.new_until_s is None
    first, v_first = pace(plan, x0, g, horizon=lambda p: 2.0)
    assert v_first.ok and first.new_until_s == 2.0
    assert np.array_equal(first.t_s, plan.t_s)                   # nothing slowed down
    assert not g.check_trajectory(first.trajectory).ok            # its end alone would be refused


def test_a_rejoin_whose_rest_runs_into_a_known_obstacle_is_refused():
    # new only for its first 2 s, but the plan it goes on to fly ends 0.5 m from the
    # box's face, inside its 0.9 m: the rest is not re-paced, and it is still not flown
    plan, x0 = _plan(7.5)
    g = _guard()
    _, verdict = pace(plan, x0, g, horizon=lambda p: 2.0)
    assert not verdict.ok and verdict.surface == "obstacle" and verdict.rule == "clearance"
    assert verdict.distance_m < REQ and verdict.t_s > 2.0
    assert box_distance([verdict.point_enu_m])[0] == pytest.approx(verdict.distance_m, abs=1e-9)


def _sparse_rejoin(T: float) -> tuple[GlobalPlan, np.ndarray]:
    """Fresh seed 20261163 of obstacles-under, flight 16's rejoin, in this file's world: from
    (1, 7.5, 2.66) moving at (0.98, 0, -0.36) m/s and sinking at 0.4 m/s^2, through one
    way-point 8.1 m on at 1.5 m, reached after ``T`` s."""
    P = np.array([[1.0, 7.5, 2.663], [9.1, 7.5, 1.5]])
    x0 = np.array([P[0], [0.983, 0.0, -0.356], [0.0, 0.0, -0.4], [0.0, 0.0, 0.0]])
    t = np.array([0.0, T])
    V, A = np.zeros_like(P), np.zeros_like(P)
    cfg = TrajectoryConfig()
    traj = generate_trajectory(t, P, V, A, cfg, initial_state=x0)
    corner = np.ones(2, bool)
    return GlobalPlan.from_waypoints(traj, t, P, V, A, corner, None, None, FlightConfig(), cfg, 0.5), x0


def test_the_lqr_between_far_way_points_leaves_the_path_so_pacing_checks_it():
    from companion.replan.pace import PATH_TOL_M, kept_path, path_offsets_m

    # the polyline distance, by hand: a point 0.3 m above the segment's middle, one beyond its end
    seg = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    assert path_offsets_m(np.array([[1.0, 0.0, 0.3], [3.0, 0.0, 0.0]]), seg) == pytest.approx([0.3, 1.0])
    # the same two way-points flown over 10 s and stretched to 31.5 s (the flight's pacing):
    # the longer flight is free between them and sinks metres below the 10 s path
    short, x0 = _sparse_rejoin(10.0)
    long, _ = _sparse_rejoin(31.5)
    ts = np.linspace(long.trajectory.t0, long.trajectory.tf, 400)
    z = np.asarray(long.trajectory.sample(ts).p).reshape(-1, 3)[:, 2]
    assert z.min() < -5.0                                  # far below the ground
    v = kept_path(short.trajectory, long.trajectory, 0.0, None, _guard())
    assert v is not None and not v.ok and v.rule == "path"
    # retiming a dense plan keeps its path within the tolerance
    plan, x0d = _plan(6.0)
    slow = _plan(6.0)[0]
    from companion.replan.pace import _resolve
    stretched = _resolve(slow, x0d, np.full(len(slow.t_s) - 1, 2.0))
    assert kept_path(plan.trajectory, stretched.trajectory, 0.0, None, _guard()) is None
    assert PATH_TOL_M <= 0.5                               # inside the corridor's lateral bound


def test_a_candidate_above_the_ceiling_is_refused():
    # the flight's rejoin mirrored (rising at 0.356 m/s and 0.4 m/s^2) from 1.5 m to 1.5 m:
    # over 31.5 s it rises to 16 m, far above a 3 m ceiling over the flat ground at 0, and is
    # refused with the ceiling rule; over 5 s it peaks at 2.3 m and passes
    P = np.array([[1.0, 7.5, 1.5], [9.1, 7.5, 1.5]])
    x0 = np.array([P[0], [0.983, 0.0, 0.356], [0.0, 0.0, 0.4], [0.0, 0.0, 0.0]])
    cfg = TrajectoryConfig()
    g = _guard()
    for T, refused in ((31.5, True), (5.0, False)):
        t = np.array([0.0, T])
        traj = generate_trajectory(t, P, np.zeros_like(P), np.zeros_like(P), cfg, initial_state=x0)
        z = np.asarray(traj.sample(np.linspace(0.0, T, 400)).p).reshape(-1, 3)[:, 2]
        assert (z.max() > 3.1) == refused
        v = g.check_ceiling(traj, 0.0, None, 3.0, 0.1)
        assert (not v.ok) == refused
        if refused:
            assert v.rule == "ceiling" and v.point_enu_m[2] > 3.1


@pytest.mark.parametrize("seed", range(8))
def test_off_path_is_the_full_offset_test_exactly(seed):
    # off_path skips the points within tolerance of a segment beside their nearest vertex;
    # its verdict must be path_offsets_m(...) > tol for every point, whatever the path:
    # dense or sparse vertices, repeated vertices (zero-length segments), points on,
    # near and far from it, and points exactly at the tolerance from a vertex
    from companion.replan.pace import PATH_TOL_M, off_path, path_offsets_m

    rng = np.random.default_rng([2026_11_28, seed])
    n = int(rng.integers(3, 120))
    path = np.cumsum(rng.normal(0.0, rng.choice([0.05, 0.5, 3.0]), (n, 3)), axis=0)
    path[rng.integers(1, n)] = path[rng.integers(0, n)]             # a jump back
    path = np.insert(path, 1, path[1], axis=0)                       # a zero-length segment
    k = int(rng.integers(1, 400))
    base = path[rng.integers(0, len(path), k)]
    q = base + rng.normal(0.0, rng.choice([0.05, 0.3, 2.0]), (k, 3))
    u = rng.normal(size=(5, 3))
    q = np.vstack([q, path[:5] + PATH_TOL_M * u / np.linalg.norm(u, axis=1)[:, None]])
    want = path_offsets_m(q, path) > PATH_TOL_M
    np.testing.assert_array_equal(off_path(q, path, PATH_TOL_M), want)
    for tol in (0.0, 1e-3, 1.0):
        np.testing.assert_array_equal(off_path(q, path, tol), path_offsets_m(q, path) > tol)
