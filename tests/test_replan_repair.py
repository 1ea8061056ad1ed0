"""A re-route is proposed only if the guard accepts what would be flown (issue 15, "every hold
justified by the independent route check"; docs/replan.md "One picture, and a repair").

- One picture: the columns a re-route adds for the blocking obstacle stand to its top,
  for the guard (companion.safety.obstacles), the 3-D route search (route3d) and the
  route check (routecheck) alike; their assumed depth extends away from where the
  vehicle saw the obstacle.
- The repair (companion.replan.repair): an LQR fit that cuts a corner its route kept
  comes back with denser way-points, slower, and clear by the guard's own numbers.
- The 3-D leave's last margin is the independent check's own question.

Distances are worked from the boxes' geometry, not read from the code under test.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from companion.coverage.freespace import erode_free_space
from companion.replan import repair as repair_mod
from companion.replan.globalplan import GlobalPlan
from companion.replan.knownmap import KnownMap
from companion.replan.pace import pace
from companion.polyline import densify
from companion.replan.repair import STEP_M, repair
from companion.replan.replanner import LEAVE_MARGINS_M, Replanner
from companion.replan.reroute import with_blocking
from companion.replan.route3d import RouteScene, find_route
from companion.replan.routecheck import route_exists
from companion.replan.voxmap import ObstacleMap
from companion.safety import Guard, GuardConfig, SafetyScene, known_obstacle_distance
from companion.trajectory import generate_trajectory
from mavcore.maps.grid import ElevationModel, OccupancyGrid
from mavcore.mission.replan import ReplanConfig
from mavcore.mission.schema import FlightConfig
from mavcore.mission.trajectory import TrajectoryConfig

V = 0.1                        # voxel (m)
R_BODY, CLEAR = 0.442, 0.5
KEEP = R_BODY + CLEAR          # the centre keeps 0.942 m from an obstacle
CEIL = 3.0


def _known():
    # a 24 m square field, (-6, -6) to (18, 18), flat, no rows
    occ = np.zeros((240, 240), dtype=bool)
    g = OccupancyGrid(occ, ~occ, 0.1, (-6.0, -6.0))
    dem = ElevationModel(np.zeros((6, 6)), -6.0, -6.0, 5.0)
    return KnownMap.build(g, dem, erode_free_space(g, 0.5), 2.0, 0.2)


# --- one picture: the added columns stand to the obstacle's top --------------------------

def _face(x: float, y0: float, y1: float, top: float) -> np.ndarray:
    """Points of an obstacle's seen face at x (voxel centres every 0.1 m up to ``top``)."""
    ys = np.arange(y0 + V / 2, y1, V)
    zs = np.arange(V / 2, top, V)
    return np.array([(x, y, z) for y in ys for z in zs])


def test_vehicle_stopped_over_the_obstacle_is_not_in_contact_with_its_added_column():
    # the held flights' case: a climb stopped 1 m over a 1.9 m post's top, 0.45 m beside
    # its face; the re-route adds the post (and 0.5 m of assumed depth away from the
    # vehicle) to the map. The face's points sit in the 0.1 m cells x 5.4..5.5, so the
    # nearest added square is 0.4 m away horizontally; the column's top is the upper
    # face of the highest voxel, 1.9 m: the guard reads hypot(0.4, 2.9 - 1.9) = 1.077 m.
    # (Of unknown height, the column was 0.4 m away: inside the 0.442 m airframe, "contact".)
    known = _known()
    face = _face(5.45, 4.7, 5.3, 1.9)
    P = np.array([[5.0, 5.0, 2.9]])
    added = with_blocking(known, face, P[0, :2], (1.0, 0.0), 0.5, KEEP, V)
    od = known_obstacle_distance(ObstacleMap(V), lambda: added)
    assert od(P)[0] == pytest.approx(math.hypot(0.4, 1.0), abs=1e-6)
    unknown_top = with_blocking(known, face, P[0, :2], (1.0, 0.0), 0.5, KEEP, None)
    assert known_obstacle_distance(ObstacleMap(V), lambda: unknown_top)(P)[0] == pytest.approx(0.4, abs=1e-6)
    # beside the column below its top: horizontal distance only
    assert od(np.array([[5.0, 5.0, 1.0]]))[0] == pytest.approx(0.4, abs=1e-6)


def test_assumed_depth_extends_away_from_where_the_obstacle_was_seen():
    # a face at x = 5.05 seen from the west gets 0.5 m of depth to the east (cells up to
    # x 5.5), none to the west; seen from the east (a 3-D route's far end is not where
    # it was seen from) the depth would grow toward a vehicle west of it
    known = _known()
    face = _face(5.05, 4.7, 5.3, 1.0)
    west = with_blocking(known, face, (3.0, 5.0), (1.0, 0.0), 0.5, KEEP, V)
    east = with_blocking(known, face, (8.0, 5.0), (1.0, 0.0), 0.5, KEEP, V)
    assert west.cell_of(5.45, 5.0) is not None
    assert west.added[west.cell_of(5.45, 5.0)] and not west.added[west.cell_of(4.95, 5.0)]
    assert east.added[east.cell_of(4.65, 5.0)] and not east.added[east.cell_of(5.25, 5.0)]


def test_route_search_and_check_read_the_added_columns_as_the_guard_does():
    # a wall of added cells across the whole window, 1.0 m tall (its voxels' top): the
    # search and the check go over it, the centre at least 1.0 + 0.942 m high where it
    # passes over; of unknown height (the old picture) neither finds a way under the
    # 3 m ceiling. No voxel is in the map: the added columns alone block.
    known = _known()
    wall = np.array([(5.05, y, 0.95) for y in np.arange(-5.95, 18.0, 0.1)])
    over = with_blocking(known, wall, (2.0, 5.0), (1.0, 0.0), 0.2, KEEP, V)
    scene = RouteScene(over, ObstacleMap(V), KEEP, 0.5, CEIL, 0.25)
    r = find_route(scene, (2.0, 5.0, 1.5), [(9.0, 5.0, 1.5)])
    assert r is not None
    p = densify(r.path_enu_m, 0.02)
    # the column: x 5.0..5.3 (the face's cells and 0.2 m of depth), from the ground to 1.0 m
    lo, hi = np.array([5.0, -6.0, -1e9]), np.array([5.3, 18.0, 1.0])
    e = np.maximum(np.maximum(lo - p, p - hi), 0.0)
    assert np.sqrt((e * e).sum(axis=1)).min() >= KEEP - 1e-9
    assert route_exists(scene, (2.0, 5.0, 1.5), [(9.0, 5.0, 1.5)]) == [True]
    tall = with_blocking(known, wall, (2.0, 5.0), (1.0, 0.0), 0.2, KEEP, None)
    scene_tall = RouteScene(tall, ObstacleMap(V), KEEP, 0.5, CEIL, 0.25)
    assert find_route(scene_tall, (2.0, 5.0, 1.5), [(9.0, 5.0, 1.5)]) is None
    assert route_exists(scene_tall, (2.0, 5.0, 1.5), [(9.0, 5.0, 1.5)]) == [False]


def test_added_column_explains_returns_up_to_its_top_only():
    # a return above the added column's top is something the map does not hold: unknown
    known = _known()
    added = with_blocking(known, _face(5.05, 4.7, 5.3, 1.0), (3.0, 5.0), (1.0, 0.0), 0.5, KEEP, V)
    assert added.classify(5.15, 5.0, 1.0 + 0.1) == "added"         # within the 0.2 m tolerance
    assert added.classify(5.15, 5.0, 1.0 + 0.5) == "unknown"


def test_leave_ends_with_the_checks_own_question():
    # a 0.6 m thick wall taller than the ceiling across the window, with a gap between
    # y = 3.9 and 6.1: on the 0.25 m lattice the last blocked nodes are at y = 3.75 and
    # 6.25, so the one free passage (y = 5.0) keeps 1.25 m from them. With a 1.1 m keep
    # (a larger airframe) that is the keep and the half step (1.225 m) but not 0.1 m
    # more (1.325 m): the check, which asks the keep alone, finds the way; the search
    # with the governor's margin does not; the leave's last margin is the check's own.
    m = ObstacleMap(V)
    for y0, y1 in ((-6.0, 3.9), (6.1, 18.0)):
        for x in np.arange(4.7 + V / 2, 5.3, V):
            for y in np.arange(y0 + V / 2, y1, V):
                m.add((x, y, 3.5))
    known = _known()
    keep = 1.1
    start, goal = (2.0, 5.0, 1.5), [(9.0, 5.0, 1.5)]
    assert route_exists(RouteScene(known, m, keep, 0.5, CEIL, 0.25), start, goal) == [True]
    assert find_route(RouteScene(known, m, keep + 0.1, 0.5, CEIL, 0.25), start, goal) is None
    r = find_route(RouteScene(known, m, keep + min(LEAVE_MARGINS_M), 0.5, CEIL, 0.25), start, goal)
    assert r is not None
    assert np.abs(densify(r.path_enu_m, 0.02)[:, 1][np.abs(densify(r.path_enu_m, 0.02)[:, 0] - 5.0) < 0.3] - 5.0).max() < 1e-9
    assert LEAVE_MARGINS_M[-1] == 0.0


# --- the repair: a fit that cuts a corner its route kept ------------------------------------

R, C = 0.4, 0.5
REQ = R + C                    # the guard's centre distance to keep from the box
BOX_LO, BOX_HI = np.array([4.0, 5.0, 0.0]), np.array([6.0, 8.0, 3.0])


def box_distance(points) -> np.ndarray:
    p = np.asarray(points, float).reshape(-1, 3)
    e = np.maximum(np.maximum(BOX_LO - p, p - BOX_HI), 0.0)
    return np.sqrt((e * e).sum(axis=1))


def _guard() -> Guard:
    occ = np.zeros((150, 150), bool)
    grid = OccupancyGrid(occ, ~occ, 0.1)
    dem = ElevationModel(np.zeros((16, 16)), 0.0, 0.0, 1.0)
    cfg = GuardConfig(airframe_radius_m=R, terrain_clearance_m=C, row_clearance_m=C, obstacle_clearance_m=C,
                      accel_m_s2=1.0, delay_s=0.5)
    return Guard(cfg, SafetyScene.from_maps(grid, dem, 2.0), box_distance)


def _l_turn(a: float, step_m: float = 1.0):
    """East along y = 5 - a, round the box's corner (6, 5) at (6 + a, 5 - a), north along
    x = 6 + a: the polyline keeps exactly a from the box (its south and east faces). Way-
    points every ``step_m`` at 1 m/s along each leg, at rest at the turn: the LQR's soft tracking
    rounds the turn inside, toward the box's corner."""
    K = np.array([6.0 + a, 5.0 - a, 1.5])
    legs = [np.array([0.0, 5.0 - a, 1.5]), K, np.array([6.0 + a, 11.0, 1.5])]
    P, Vw = [], []
    for p0, p1 in zip(legs[:-1], legs[1:]):
        n = max(1, int(round(np.linalg.norm(p1 - p0) / step_m)))
        u = (p1 - p0) / np.linalg.norm(p1 - p0)
        for k in range(n):
            P.append(p0 + (p1 - p0) * k / n)
            Vw.append(u)
    P.append(legs[-1])
    Vw.append(np.zeros(3))
    P, Vw = np.array(P), np.array(Vw)
    Vw[0] = 0.0
    turn = int(np.argmin(np.linalg.norm(P - K, axis=1)))
    Vw[turn] = 0.0
    t = np.concatenate([[0.0], 1.0 + np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    A = np.zeros_like(P)
    x0 = np.array([P[0], np.zeros(3), np.zeros(3), np.zeros(3)])
    cfg = TrajectoryConfig()
    traj = generate_trajectory(t, P, Vw, A, cfg, initial_state=x0)
    corner = np.zeros(len(P), bool)
    corner[[0, turn, -1]] = True
    return GlobalPlan.from_waypoints(traj, t, P, Vw, A, corner, None, None, FlightConfig(), cfg, 0.5), x0


def _min_box_distance(plan) -> float:
    tr = plan.trajectory
    return float(box_distance(tr.sample(np.arange(tr.t0, tr.tf, 0.01)).p).min())


def test_fit_that_cuts_a_corner_comes_back_repaired_and_clear():
    a = 0.91                   # the route keeps 0.91 m, 1 cm more than the guard asks
    plan, x0 = _l_turn(a, 3.0)
    g = _guard()
    assert box_distance(densify(plan.p_enu_m, STEP_M)).min() == pytest.approx(a, abs=1e-9)
    # the fit cuts the turn the route went round: inside the clearance
    assert _min_box_distance(plan) < REQ
    # paced to the stopping law, it still leaves the route toward the box (north of the
    # leg y = 5 - a) and closes on it faster than the law allows: the guard refuses it
    paced, verdict = pace(plan, x0, g)
    assert not verdict.ok and verdict.surface == "obstacle"
    assert verdict.point_enu_m[1] > 5.0 - a + 0.01
    fixed = repair(paced, x0, verdict, g)
    assert fixed.plan is not None
    # the repaired piece is the turn's: denser way-points, flown slower; the ends stay
    assert len(fixed.plan.t_s) > len(paced.t_s)
    assert fixed.plan.t_s[-1] - fixed.plan.t_s[0] > paced.t_s[-1] - paced.t_s[0]
    assert np.diff(fixed.plan.t_s).min() > 0.0
    assert np.allclose(fixed.plan.p_enu_m[-1], plan.p_enu_m[-1])
    # paced and judged whole again (the caller's loop): accepted by the guard's own check,
    # and by the box's exact distance every 0.01 s it keeps the clearance, no farther than
    # the route itself went (the fit now follows the polyline)
    again, v2 = pace(fixed.plan, x0, g)
    assert v2.ok and g.check_trajectory(again.trajectory).ok
    assert REQ <= _min_box_distance(again) <= a + 0.005


def test_route_itself_too_close_is_not_repaired_by_the_fit():
    # the polyline keeps 0.85 m < 0.9 m: no fit mends that; the caller must search again
    plan, x0 = _l_turn(0.85)
    g = _guard()
    verdict = g.check_trajectory(plan.trajectory)
    assert not verdict.ok
    fixed = repair(plan, x0, verdict, g)
    assert fixed.plan is None and "route itself" in fixed.reason


def test_checked_proposes_the_repaired_candidate_only():
    # the replanner's one place: paced, judged, refused, repaired, judged again. Way-points
    # every 3 m: pacing alone slows the approach to the turn, and the slowed fit still
    # closes on the box's corner faster than the stopping law allows there
    plan, x0 = _l_turn(0.91, 3.0)
    g = _guard()
    host = SimpleNamespace(guard=g, memory=ObstacleMap(V), _keep_m=REQ, cfg=ReplanConfig())
    st = SimpleNamespace(p=x0[0], v=x0[1], a=x0[2], jerk=x0[3])
    assert not pace(plan, x0, g)[1].ok
    out, verdict, added, note, conflict = Replanner._checked(host, plan, st)
    assert out is not None and verdict.ok and note.startswith("repaired")
    assert g.check_trajectory(out.trajectory).ok
    assert _min_box_distance(out) >= REQ
    # with no repair allowed, the same candidate is not proposed
    host0 = SimpleNamespace(guard=g, memory=ObstacleMap(V), _keep_m=REQ, cfg=ReplanConfig())
    orig = repair_mod.MAX_REPAIRS
    try:
        import companion.replan.replanner as rr
        rr.MAX_REPAIRS = 0
        assert Replanner._checked(host0, plan, st)[0] is None
    finally:
        rr.MAX_REPAIRS = orig


def test_densified_piece_hand_worked():
    # one interval of 1 m in 2 s from rest to rest, 0.25 m way-points, 1.5 x slower (3 s):
    # the cubic Hermite between speeds 0 and 0 is s = L (3 tau^2 - 2 tau^3): at tau = 1/4
    # 0.15625 m, at 1/2 0.5 m moving at 1.5 L / T = 0.5 m/s; the interval after it keeps
    # its 1 s, shifted by the 1 s added; way-point 1 (joining both) at rest still
    t = np.array([0.0, 2.0, 3.0])
    P = np.array([[0.0, 0, 1], [1.0, 0, 1], [2.0, 0, 1]])
    Vw = np.array([[0.0, 0, 0], [0.0, 0, 0], [0.0, 0, 0]])
    A = np.zeros_like(P)
    nt, nP, nV, nA, nC = repair_mod.densified(t, P, Vw, A, np.ones(3, bool), 0, 1, 0.25, 1.5)
    assert nt.tolist() == pytest.approx([0.0, 0.75, 1.5, 2.25, 3.0, 4.0])
    assert nP[:, 0].tolist() == pytest.approx([0.0, 0.15625, 0.5, 0.84375, 1.0, 2.0])
    assert nV[2, 0] == pytest.approx(0.5)
    assert nC.tolist() == [True, False, False, False, True, True]


def test_route_that_grazes_the_clearance_is_moved_off_it():
    # a route at the clearance itself, 1 mm inside (a lattice route's node on it): the
    # piece's way-points within the clearance + 2 cm are moved off the box by what they
    # lack (at most 4 cm), and the repaired, paced candidate keeps the clearance by the
    # box's exact distance; 0.85 m (5 cm inside, above) is not a graze
    a = REQ - 0.001
    plan, x0 = _l_turn(a, 3.0)
    g = _guard()
    paced, verdict = pace(plan, x0, g)
    assert not verdict.ok
    fixed = repair(paced, x0, verdict, g)
    assert fixed.plan is not None and "moved off" in fixed.reason
    # every way-point of the repair within 4 cm of the route's polyline (sampled every 5 mm)
    line = densify(paced.p_enu_m, 0.005)
    moved = np.linalg.norm(fixed.plan.p_enu_m[1:, None, :] - line[None, :, :], axis=2).min(axis=1)
    assert moved.max() <= repair_mod.NUDGE_MAX_M + repair_mod.NUDGE_MARGIN_M + 0.005
    again, v2 = pace(fixed.plan, x0, g)
    for _ in range(repair_mod.MAX_REPAIRS):
        if v2.ok:
            break
        again, v2 = pace(repair(again, x0, v2, g).plan, x0, g)
    assert v2.ok
    assert _min_box_distance(again) >= REQ


def test_vehicle_inside_a_clearance_finds_the_route_the_check_finds():
    # stopped 0.8 m from a box taller than the ceiling (inside its 0.942 m keep): the
    # vehicle's own node is not free; the search and the check both start from the
    # nearest free node within 1.5 m and both reach the goal beyond the box's side;
    # the search's first leg from the vehicle to that node is at most 1.5 m
    m = ObstacleMap(V)
    for x in np.arange(5.0 + V / 2, 5.5, V):
        for y in np.arange(4.0 + V / 2, 6.0, V):
            m.add((x, y, 3.5))
    known = _known()
    start, goal = np.array([4.2, 5.0, 1.5]), [(8.0, 5.0, 1.5)]
    scene = RouteScene(known, m, KEEP + min(LEAVE_MARGINS_M), 0.5, CEIL, 0.25)
    r = find_route(scene, start, goal)
    assert route_exists(scene, start, goal) == [True]
    assert r is not None
    assert np.linalg.norm(r.path_enu_m[1] - start) <= 1.5 + 1e-9
    p = densify(r.path_enu_m[1:], 0.02)
    lo, hi = np.array([5.0, 4.0, -1e9]), np.array([5.5, 6.0, 3.6])
    e = np.maximum(np.maximum(lo - p, p - hi), 0.0)
    assert np.sqrt((e * e).sum(axis=1)).min() >= KEEP - 1e-9
