"""The trajectory cursor and the rejoin (LQR re-solved from the current state)."""

from __future__ import annotations

from dataclasses import replace

import math

import numpy as np
import pytest

from mavcore.mission.schema import FlightConfig
from companion.replan import GlobalPlan, ShapedState, rejoin
from companion.replan.rejoin import CHECK_S, first_time_s
from companion.trajectory import generate_trajectory
from mavcore.mission.trajectory import TrajectoryConfig
from companion.trajectory.cursor import TrajectoryCursor

T_WP = np.array([0.0, 4.85, 8.85, 12.85, 16.85, 21.7, 27.0, 31.9])
P_WP = np.array([[0, 0, 1.5], [3, 0, 1.5], [7, 0, 1.5], [11, 0, 1.5], [15, 0, 1.5], [18, 0, 1.5],
                 [18, 2.5, 1.5], [15, 2.5, 1.5]], dtype=float)
V_WP = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 0, 0], [1, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]], float)
CORNER = np.array([True, False, False, False, False, True, True, True])
TARGET = np.array([9.0, 5.0, 1.5])


def _plan() -> GlobalPlan:
    traj = generate_trajectory(T_WP, P_WP, V_WP, None, TrajectoryConfig(), target_enu_m=TARGET)
    segs = np.array([[[0, 0], [18, 0]], [[18, 2.5], [15, 2.5]]], dtype=float)
    return GlobalPlan.from_waypoints(traj, T_WP, P_WP, V_WP, np.zeros_like(P_WP), CORNER, segs, TARGET,
                                     FlightConfig(), TrajectoryConfig(), 1.0, (15.0, 2.5))


# --- cursor -----------------------------------------------------------------------------------


@pytest.mark.parametrize("q_jerk", [0.0, 3.0])
def test_cursor_equals_vectorised_sampling(q_jerk):
    cfg = replace(TrajectoryConfig(), q_acceleration=1.0 if q_jerk else 0.0, q_jerk=q_jerk)
    traj = generate_trajectory(T_WP, P_WP, V_WP, None, cfg)
    cur = TrajectoryCursor(traj)
    rng = np.random.default_rng(5)
    forward = np.sort(rng.uniform(-1.0, 33.0, 400))
    back = rng.uniform(0.0, 31.9, 50)                       # time going back works too
    times = np.concatenate([forward, back, [traj.t0, traj.tf]])
    ref = traj.sample(times)
    got = [cur.sample(float(t)) for t in times]
    for name in ("p", "v", "a", "jerk", "snap"):
        np.testing.assert_allclose([getattr(s, name) for s in got], getattr(ref, name), atol=1e-9, rtol=1e-9)
    assert cur.sample(-5.0).t_s == traj.t0 and cur.sample(99.0).t_s == traj.tf


# --- rejoin -----------------------------------------------------------------------------------


def _off_path_state():
    # 0.4 m to the side, 0.8 m up, slowed, still accelerating and with jerk
    return ShapedState(p=(8.0, 0.4, 2.3), v=(0.6, -0.05, -0.1), a=(0.2, -0.1, -0.3), jerk=(0.1, 0.05, 0.2),
                       snap=(0.0, 0.0, 0.0))


def test_rejoin_starts_in_the_current_state_and_keeps_the_rest_time_shifted():
    plan = _plan()
    st = _off_path_state()
    t_now = 14.0
    res = rejoin(plan, st, t_now, 3, np.zeros((0, 3)), 0.5, 2.0, 0.5)
    assert res.reason == "" and res.plan is not None
    new = res.plan
    s0 = new.trajectory.sample(t_now)
    for name, want in (("p", st.p), ("v", st.v), ("a", st.a), ("jerk", st.jerk)):
        np.testing.assert_allclose(getattr(s0, name), want, atol=1e-9)      # no jump up to the jerk
    # the first kept way-point gets the allocated time; the rest keep their intervals
    T = first_time_s(st.p, P_WP[3], plan.flight.speed_m_s, 0.5)
    np.testing.assert_allclose(new.t_s, np.concatenate([[t_now], t_now + T + T_WP[3:] - T_WP[3]]))
    np.testing.assert_allclose(new.p_enu_m[1:], P_WP[3:])
    # and the trajectory passes them (soft constraints: within the LQR's few cm)
    assert np.max(np.linalg.norm(new.trajectory.sample(new.t_s[1:]).p - P_WP[3:], axis=1)) < 0.05
    assert res.max_jerk_m_s3 <= 2.0
    # the segments are re-indexed on the new way-points: the current one from 0, the next unchanged in space
    assert [(s.first_wp, s.last_wp) for s in new.segments] == [(0, 3), (4, 5)]
    assert new.segments[1].start_xy == (18.0, 2.5)


def test_rejoin_stretches_time_for_the_jerk_limit():
    plan = _plan()
    st = _off_path_state()
    loose = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 10.0, 0.5)
    tight = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 0.5 * loose.max_jerk_m_s3, 0.5)
    assert tight.plan is not None and tight.max_jerk_m_s3 <= 0.5 * loose.max_jerk_m_s3
    assert tight.plan.t_s[1] - 14.0 > loose.plan.t_s[1] - 14.0
    impossible = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 1e-4, 0.5)
    assert impossible.plan is None and impossible.reason == "jerk"


def test_rejoin_refused_when_the_path_would_pass_an_obstacle():
    plan = _plan()
    st = _off_path_state()
    ok = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 2.0, 0.5)
    # a point right on the candidate's path one second on
    on_path = ok.plan.trajectory.sample(15.0).p
    res = rejoin(plan, st, 14.0, 3, on_path[None], 0.5, 2.0, 0.5)
    assert res.plan is None and res.reason == "clearance" and res.min_clearance_m < 0.05
    # points farther than the horizon checked do not matter
    far = ok.plan.trajectory.sample(14.0 + CHECK_S + 3.0).p
    assert rejoin(plan, st, 14.0, 3, far[None], 0.5, 2.0, 0.5).plan is not None


def test_rejoin_respects_the_ceiling():
    plan = _plan()
    st = replace(_off_path_state(), v=(0.6, 0.0, 0.45), a=(0.0, 0.0, 0.6))   # still climbing hard
    free = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 50.0, 0.5)
    z = free.plan.trajectory.sample(np.arange(14.0, 14.0 + CHECK_S, 0.05)).p[:, 2]
    assert z.max() > 2.45 + 0.05                          # overshoots upward from this state
    res = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 50.0, 0.5, ceiling_z=lambda x, y: 2.45)
    assert res.plan is None and res.reason == "ceiling"
    ok = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 50.0, 0.5, ceiling_z=lambda x, y: z.max() + 0.01)
    assert ok.plan is not None


def test_rejoin_way_point_ahead_not_back_round_a_turn():
    from companion.replan.replanner import first_waypoint_ahead
    plan = _plan()          # east along y = 0 to the turn at (18, 0), then north to (18, 2.5), west to (15, 2.5)
    # on the first leg at x = 8.5 heading east: 11 is 2.5 m ahead (more than the 1 m lead)
    assert first_waypoint_ahead(plan, 2, (8.5, 0.0, 1.5), np.array([1.0, 0.0]), 1.0, 0.5) == 3
    # 1.2 m above the line: coming down at 0.5 m/s takes 4.5 s, so 4.5 m of lead: 15 (6.5 m ahead)
    assert first_waypoint_ahead(plan, 2, (8.5, 0.0, 2.7), np.array([1.0, 0.0]), 1.0, 0.5) == 4
    # near the turn: the turn itself, never cut
    assert first_waypoint_ahead(plan, 4, (17.5, 0.0, 1.5), np.array([1.0, 0.0]), 1.0, 0.5) == 5
    # the avoidance went round the turns at (18, 0) and (18, 2.5) and is heading west at x = 16.8:
    # the way-points behind it are skipped, the next ahead is the end (15, 2.5)
    assert first_waypoint_ahead(plan, 4, (16.8, 2.5, 1.5), np.array([-1.0, 0.0]), 1.0, 0.5) == 7


def test_rejoin_refused_when_the_path_leaves_the_free_cells_after_the_horizon():
    """The map's rows are not remembered obstacle points: a candidate must stay over
    free cells over its whole length, not only over the first CHECK_S seconds (the
    randomized SITL benchmark crashed into a row 10 s into an accepted rejoin)."""
    plan = _plan()
    st = _off_path_state()
    ok = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 2.0, 0.5)
    assert ok.plan is not None
    late = ok.plan.trajectory.sample(14.0 + CHECK_S + 3.0).p
    assert ok.plan.trajectory.tf > 14.0 + CHECK_S + 3.0

    def free(x, y):          # a "row" cell under the candidate 9 s on, nothing else
        return math.hypot(x - late[0], y - late[1]) > 0.2

    res = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 2.0, 0.5, free_xy=free)
    assert res.plan is None and res.reason == "ceiling"


def test_planned_length_in_chunks_is_the_length_and_the_polyline_bound():
    """The replanner's planned length (extra_path_m's reference), sampled in chunks
    so that a many-hour plan never holds all its samples: the chunk size does not
    change it, and it lies between the straight way-point polyline's length and
    a little above it (the trajectory passes near the way-points)."""
    from companion.replan.replanner import path_length_m

    plan = _plan()
    tr = plan.trajectory
    whole = path_length_m(tr)
    assert path_length_m(tr, chunk=7) == pytest.approx(whole, rel=1e-12)
    assert path_length_m(tr, chunk=1) == pytest.approx(whole, rel=1e-12)
    poly = float(np.sum(np.linalg.norm(np.diff(plan.p_enu_m, axis=0), axis=1)))
    assert 0.95 * poly <= whole <= 1.1 * poly


def test_a_remembered_point_is_the_top_of_a_grounded_column():
    """A point seen 0.6 m below the candidate's path: as a point it is 0.6 m away
    (clear of 0.5 m); as the top of a post standing on the ground it is 0.6 m
    away only above it, and a path passing 0.3 m beside the post's column at the
    point's height or below is refused (hand-worked distances)."""
    from companion.replan.rejoin import column_clearance_m

    path = np.array([[0.0, 0.0, 1.5], [1.0, 0.0, 1.5], [2.0, 0.0, 0.8]])
    top = np.array([[1.0, 0.0, 0.9]])
    assert column_clearance_m(path[:2], top) == pytest.approx(0.6)          # straight above the top
    beside = np.array([[2.0, 0.3, 1.2]])                                     # path at 0.8 m: below the top
    assert column_clearance_m(path[2:], beside) == pytest.approx(0.3)
    assert np.sqrt(((path[2] - beside[0]) ** 2).sum()) == pytest.approx(0.5)   # 0.5 m as a bare point
    # rejoin refuses a candidate that comes down past a post's top within the clearance
    plan = _plan()
    st = _off_path_state()
    ok = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 2.0, 0.5)
    p1 = ok.plan.trajectory.sample(15.0).p
    post_top = np.array([[p1[0], p1[1], p1[2] - 1.0]])                 # 1 m under the path, a point
    assert rejoin(plan, st, 14.0, 3, post_top, 0.5, 2.0, 0.5).plan is not None
    post_top_high = np.array([[p1[0], p1[1] + 0.3, p1[2] + 0.4]])     # column top above the path, 0.3 m aside
    res = rejoin(plan, st, 14.0, 3, post_top_high, 0.5, 2.0, 0.5)
    assert res.plan is None and res.reason == "clearance" and res.min_clearance_m <= 0.3 + 1e-9


# --- the leg's start corner and the coverage a rejoin skips (issue 15) ----------------------------


def _back_track_plan() -> GlobalPlan:
    """A corridor out and back, then the same corner (10, 0) again (a re-route's back-track)."""
    P = np.array([[0, 0, 1.5], [5, 0, 1.5], [10, 0, 1.5], [10, 2.5, 1.5], [5, 2.5, 1.5], [0, 2.5, 1.5],
                  [0, 0.5, 1.5], [10, 0.5, 1.5], [10, 0, 1.5], [15, 0, 1.5]], dtype=float)
    t = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(P[:, :2], axis=0).T))])    # 1 m/s
    corner = np.array([True, False, True, True, False, True, True, True, True, True])
    traj = generate_trajectory(t, P, target_enu_m=TARGET)
    return GlobalPlan.from_waypoints(traj, t, P, np.zeros_like(P), np.zeros_like(P), corner, None, TARGET,
                                     FlightConfig(), TrajectoryConfig(), 1.0)


def test_leg_start_corner_is_this_passage_not_a_later_visit():
    from companion.replan.replanner import next_corner_visit
    plan = _back_track_plan()
    # left the plan at way-point 1 on the leg (0,0)-(10,0); turning onto the next leg at (10, 0):
    # its start is way-point 2, not the back-track's visit (8)
    assert next_corner_visit(plan, (10.0, 0.0), 1) == 2
    assert next_corner_visit(plan, (10.0, 0.0), 2) == 8
    assert next_corner_visit(plan, (3.0, 3.0), 1) == 1                # no corner there


def test_rejoin_skip_is_the_plan_not_flown_beyond_the_chord():
    from companion.replan.replanner import SKIP_REPORT_M, rejoin_skip
    plan = _back_track_plan()
    u = np.array([1.0, 0.0])
    P = (6.0, 0.3, 1.5)                    # 1 m along the leg from way-point 1, 0.3 m beside it
    # rejoining 4 m ahead on the same leg: path 5, progress 1, chord hypot(4, 0.3) = 4.011: nothing skipped
    assert rejoin_skip(plan, 1, 2, P, u) is None
    # rejoining at way-point 8 (the back-track's visit of (10, 0)): path 5 + 2.5 + 10 + 2 + 10 + 0.5 = 30,
    # progress 1, chord hypot(4, 0.3): 24.989 m of corridor skipped, plan 5 s to 35 s (1 m/s)
    f, t, L = rejoin_skip(plan, 1, 8, P, u)
    assert (f, t) == (pytest.approx(5.0), pytest.approx(35.0))
    assert L == pytest.approx(30.0 - 1.0 - math.hypot(4.0, 0.3)) and L > SKIP_REPORT_M


def test_skipped_coverage_is_an_event_and_in_the_stats():
    from companion.replan import Replanner, ReplanConfig
    from companion.replan.replanner import ReplanStats
    plan = _back_track_plan()
    from test_replan_perception import _known
    rp = Replanner(ReplanConfig(), _known(), plan)
    rp.start(0.0)
    rp._pos, rp._t_s = (6.0, 0.3, 1.5), 3.0
    events: list = []
    rp._skip(events, 5.0, 30.0, 24.99, "rejoin")
    assert [e.action for e in events] == ["skip"] and events[0].detail.startswith("25.0 m of plan skipped")
    d = rp.stats.to_dict()
    assert d["coverage_skipped"] == [{"from_s": 5.0, "to_s": 30.0, "length_m": 24.99, "reason": "rejoin"}]
    assert isinstance(rp.stats, ReplanStats)


def test_climb_limit_stacks_no_margin_and_reads_the_top_from_axis_returns():
    from companion.replan.replanner import GOVERNOR_MARGIN_M, WALL_MARGIN_M, too_tall, unpassable_points
    keep = 0.5 + 0.442
    # the reference rises to the ceiling less the wall margin: 3 - 0.1 = 2.9 m, where the
    # governor must keep 0.942 + 0.1 = 1.042 m from the top: over 1.85 m it keeps 1.05 m,
    # over 1.87 m only 1.03 m (it would hover over the post, never pass)
    assert WALL_MARGIN_M == 0.1 and GOVERNOR_MARGIN_M == 0.1
    assert not too_tall(1.85, 3.0, keep) and too_tall(1.87, 3.0, keep)
    # a post whose axis returns top out at 1.8 m, and a wide beam's edge candidate reading 2.3 m
    pts = np.array([[5.0, 0.0, 1.0], [5.0, 0.0, 1.8], [5.05, 0.0, 2.3]])
    flat = lambda x, y: 0.0                                          # noqa: E731
    conf = np.array([True, True, False])
    assert len(unpassable_points(pts, flat, 3.0, keep, confirmed=conf)) == 0
    assert len(unpassable_points(pts, flat, 3.0, keep)) == 3           # the candidate taken as the top


def test_rejoin_refused_when_it_would_dip_below_the_floor():
    """Issue 15: a rejoin from a descending state re-solved into the ground. Low (0.8 m) and
    still descending hard, the candidate undershoots; with the floor just above its lowest
    sample it is refused ("floor"), with the floor just below it is accepted."""
    plan = _plan()
    st = replace(_off_path_state(), p=(8.0, 0.4, 0.8), v=(0.6, 0.0, -0.5), a=(0.0, 0.0, -0.8),
                 jerk=(0.0, 0.0, -0.98))
    free = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 50.0, 0.5)
    traj = free.plan.trajectory
    z = traj.sample(np.arange(14.0, traj.tf, 0.01)).p[:, 2]
    assert z.min() < 0.8 - 0.05                            # it undershoots from this state
    res = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 50.0, 0.5, floor_z=lambda x, y: z.min() + 0.05)
    assert res.plan is None and res.reason == "floor"
    ok = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 50.0, 0.5, floor_z=lambda x, y: z.min() - 0.05)
    assert ok.plan is not None


def test_a_rejoin_that_bows_off_its_chord_is_stretched_or_refused():
    """Started on the plan's line (y = 0) moving sideways at 0.6 m/s, the LQR is free
    until the first kept way-point (11, 0, 1.5): the candidate bows off the chord from
    the start to it, which here is the x axis, so the bow is max |y| over that piece
    (sampled here every 10 ms, independently of ``chord_offset_m``): 0.73 m. Held to half
    that bow, no stretch of the time to it keeps it (a slower rejoin has longer to drift
    sideways): refused as "path". Allowed twice the bow, it is the same candidate."""
    plan = _plan()
    st = ShapedState(p=(8.0, 0.0, 1.5), v=(0.6, 0.6, 0.0), a=(0.0, 0.0, 0.0), jerk=(0.0, 0.0, 0.0),
                     snap=(0.0, 0.0, 0.0))

    def bow(res):
        t = np.arange(res.plan.t_s[0], res.plan.t_s[1] + 1e-9, 0.01)
        return float(np.max(np.abs(res.plan.trajectory.sample(t).p[:, 1])))

    free = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 50.0, 0.5)
    assert free.plan is not None and free.plan.p_enu_m[1].tolist() == [11.0, 0.0, 1.5]
    b = bow(free)
    assert b > 0.3                                        # 0.6 m/s sideways: a bow, not a slip
    held = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 50.0, 0.5, path_tol_m=0.5 * b)
    assert held.plan is None and held.reason == "path"
    loose = rejoin(plan, st, 14.0, 3, np.zeros((0, 3)), 0.5, 50.0, 0.5, path_tol_m=2.0 * b)
    assert loose.plan is not None and loose.plan.t_s[1] == free.plan.t_s[1]
