"""3-D routes (companion/replan/route3d.py) and the independent check (routecheck.py):
over a climbable box, round a tall one, and the two agree on hand-built mazes."""

from __future__ import annotations

import numpy as np
import pytest

from companion.coverage.freespace import erode_free_space
from mavcore.maps.grid import ElevationModel, OccupancyGrid
from companion.replan.knownmap import KnownMap
from companion.replan.route3d import RouteScene, find_route
from companion.replan.routecheck import route_exists
from companion.replan.voxmap import ObstacleMap

V = 0.1
KEEP = 0.442 + 0.5            # airframe radius + clearance
CEIL = 3.0
STEP = 0.25


def _known(occupied=None):
    # a 24 m square field, (-6, -6) to (18, 18), flat
    occ = np.zeros((240, 240), dtype=bool) if occupied is None else occupied
    g = OccupancyGrid(occ, ~occ, 0.1, (-6.0, -6.0))
    dem = ElevationModel(np.zeros((6, 6)), -6.0, -6.0, 5.0)
    return KnownMap.build(g, dem, erode_free_space(g, 0.5), 2.0, 0.2)


def _box(m: ObstacleMap, x0, x1, y0, y1, top):
    for x in np.arange(x0 + V / 2, x1, V):
        for y in np.arange(y0 + V / 2, y1, V):
            for z in np.arange(V / 2, top, V):
                m.add((x, y, z))


def _scene(m, known=None):
    return RouteScene(known or _known(), m, KEEP, 0.5, CEIL, STEP)


def _dense(path, ds=0.02):
    out = [path[0]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / ds)))
        out.extend(a + (b - a) * t for t in np.linspace(0, 1, n + 1)[1:])
    return np.array(out)


def _box_clearance(p, x0, x1, y0, y1, top):
    """Distance (m) from points to the box [x0,x1]x[y0,y1]x[0,top] (its column)."""
    lo, hi = np.array([x0, y0, -1e9]), np.array([x1, y1, top])
    q = np.maximum(np.maximum(lo - p, p - hi), 0.0)
    return np.sqrt((q * q).sum(axis=1))


def test_route_goes_over_a_climbable_box():
    # a 1 m wall across the whole window: over it with the clearance from the airframe's
    # surface (centre at least 1 + 0.942 m), under the 3 m ceiling
    m = ObstacleMap(V)
    _box(m, 5.0, 5.3, -10.0, 20.0, 1.0)
    r = find_route(_scene(m), (2.0, 5.0, 1.5), [(8.0, 5.0, 1.5)])
    assert r is not None
    p = _dense(r.path_enu_m)
    assert p[:, 2].max() >= 1.0 + KEEP
    assert p[:, 2].max() <= CEIL + 1e-9
    assert _box_clearance(p, 5.0, 5.3, -10.0, 20.0, 1.0).min() >= KEEP
    assert route_exists(_scene(m), (2.0, 5.0, 1.5), [(8.0, 5.0, 1.5)]) == [True]


def test_route_goes_round_a_box_too_tall_to_climb():
    # 2.5 m tall: passing over needs a centre at 3.44 m, above the 3 m ceiling
    m = ObstacleMap(V)
    _box(m, 5.0, 5.5, 3.5, 6.5, 2.5)
    r = find_route(_scene(m), (2.0, 5.0, 1.5), [(8.0, 5.0, 1.5)])
    assert r is not None
    p = _dense(r.path_enu_m)
    assert p[:, 2].max() < 2.5 + KEEP
    assert _box_clearance(p, 5.0, 5.5, 3.5, 6.5, 2.5).min() >= KEEP
    side = p[np.abs(p[:, 0] - 5.25) < 0.25, 1]
    assert np.all((side <= 3.5 - KEEP + 1e-9) | (side >= 6.5 + KEEP - 1e-9))


def test_no_route_through_a_tall_wall_and_the_check_agrees():
    m = ObstacleMap(V)
    _box(m, 5.0, 5.3, -10.0, 20.0, 2.5)
    assert find_route(_scene(m), (2.0, 5.0, 1.5), [(8.0, 5.0, 1.5)]) is None
    assert route_exists(_scene(m), (2.0, 5.0, 1.5), [(8.0, 5.0, 1.5)]) == [False]


def _maze(kind: str) -> ObstacleMap:
    m = ObstacleMap(V)
    if kind == "gap wide":          # a tall wall with a 2.4 m gap: room for 2 x 0.942 + a step
        _box(m, 5.0, 5.3, -10.0, 3.8, 2.8)
        _box(m, 5.0, 5.3, 6.2, 20.0, 2.8)
    elif kind == "gap narrow":      # a 1.4 m gap: the airframe and its clearance need 1.88 m
        _box(m, 5.0, 5.3, -10.0, 4.3, 2.8)
        _box(m, 5.0, 5.3, 5.7, 20.0, 2.8)
    elif kind == "trap":            # a U open away from the goal: out and round
        _box(m, 4.0, 4.3, 2.0, 8.0, 2.8)
        _box(m, 0.5, 4.3, 2.0, 2.3, 2.8)
        _box(m, 0.5, 4.3, 7.7, 8.0, 2.8)
    elif kind == "low gap":         # a tall wall with a window too low to fly through, a low part to climb
        _box(m, 5.0, 5.3, -10.0, 3.7, 2.8)
        _box(m, 5.0, 5.3, 6.3, 20.0, 2.8)
        _box(m, 5.0, 5.3, 3.7, 6.3, 1.2)
    return m


@pytest.mark.parametrize("kind,expected", [("gap wide", True), ("gap narrow", False), ("trap", True),
                                           ("low gap", True)])
def test_route_search_and_independent_check_agree_on_mazes(kind, expected):
    sc = _scene(_maze(kind))
    start, goal = (2.5, 5.0, 1.5), (8.0, 5.0, 1.5)
    r = find_route(sc, start, [goal], margin_m=5.0)
    assert (r is not None) is expected
    assert route_exists(sc, start, [goal], margin_m=5.0) == [expected]


def test_route_search_and_check_agree_on_seeded_pillar_fields():
    rng = np.random.default_rng(11)
    for _ in range(6):
        m = ObstacleMap(V)
        for _ in range(int(rng.integers(4, 9))):
            x, y = rng.uniform(3.0, 7.0), rng.uniform(1.0, 9.0)
            w = rng.uniform(0.2, 1.5)
            _box(m, x, x + 0.3, y, y + w, float(rng.choice([1.0, 2.8])))
        sc = _scene(m)
        got = find_route(sc, (1.0, 5.0, 1.5), [(9.0, 5.0, 1.5), (9.0, 2.0, 1.5)]) is not None
        assert got == any(route_exists(sc, (1.0, 5.0, 1.5), [(9.0, 5.0, 1.5), (9.0, 2.0, 1.5)]))


def test_rows_are_walls_up_to_the_canopy():
    # a row (occupied cells) across the field, canopy 2 m: over it with the centre 0.942 m
    # above the canopy plus half a lattice step (module doc), under a 3.5 m ceiling
    occ = np.zeros((240, 240), dtype=bool)
    occ[:, 110:113] = True                     # x in [5.0, 5.3]
    sc = RouteScene(_known(occ), ObstacleMap(V), KEEP, 0.5, 3.5, STEP)
    r = find_route(sc, (2.0, 5.0, 1.5), [(8.0, 5.0, 1.5)])
    assert r is not None and _dense(r.path_enu_m)[:, 2].max() >= 2.0 + KEEP
    low = RouteScene(_known(occ), ObstacleMap(V), KEEP, 0.5, 2.8, STEP)
    assert find_route(low, (2.0, 5.0, 1.5), [(8.0, 5.0, 1.5)]) is None
    assert route_exists(low, (2.0, 5.0, 1.5), [(8.0, 5.0, 1.5)]) == [False]


# --- the guard's clearance in the search (route3d.guard_keeps, edge_keep_m) ---------------


def _diagonal_rows() -> np.ndarray:
    # three rows 0.3 m wide at 30 degrees to the lattice's axes: their boxes fall between
    # lattice nodes in every way the 0.25 m step allows
    occ = np.zeros((240, 240), dtype=bool)
    r, c = np.mgrid[0:240, 0:240]
    x, y = -6.0 + 0.1 * (c + 0.5), -6.0 + 0.1 * (r + 0.5)
    u = -np.sin(np.radians(30.0)) * x + np.cos(np.radians(30.0)) * y     # across the rows
    for u0 in (2.0, 4.5, 7.0):
        occ |= np.abs(u - u0) <= 0.15
    return occ


def _guarded_scene(keep=KEEP):
    from companion.safety import Guard, GuardConfig, SafetyScene, known_obstacle_distance

    known = _known(_diagonal_rows())
    m = ObstacleMap(V)
    _box(m, 7.05, 7.45, 1.05, 1.35, 1.3)             # a post, not on the lattice's axes
    cfg = GuardConfig(airframe_radius_m=0.442, terrain_clearance_m=0.058, row_clearance_m=0.5,
                      obstacle_clearance_m=0.5, accel_m_s2=1.0)
    guard = Guard(cfg, SafetyScene.from_known_map(known), known_obstacle_distance(m, lambda: known))
    return RouteScene(known, m, keep, 0.5, CEIL, STEP, guard=guard), guard


def _moves_between(free: np.ndarray, lat, n: int = 9) -> np.ndarray:
    """Points along every move (route3d.MOVES) between two free nodes, ends excluded."""
    from companion.replan.route3d import MOVES

    pts = []
    nx, ny, nz = free.shape
    tau = np.linspace(0.0, 1.0, n + 2)[1:-1, None]
    for dx, dy, dz in MOVES:
        a = free[max(0, -dx):nx - max(0, dx), max(0, -dy):ny - max(0, dy), max(0, -dz):nz - max(0, dz)]
        b = free[max(0, dx):nx + min(0, dx), max(0, dy):ny + min(0, dy), max(0, dz):nz + min(0, dz)]
        i, j, k = np.nonzero(a & b)
        i, j, k = i + max(0, -dx), j + max(0, -dy), k + max(0, -dz)
        p0 = np.stack([lat.x[i], lat.y[j], lat.z[k]], axis=1)
        p1 = np.stack([lat.x[i + dx], lat.y[j + dy], lat.z[k + dz]], axis=1)
        pts.append((p0[:, None, :] + tau[None] * (p1 - p0)[:, None, :]).reshape(-1, 3))
    return np.vstack(pts)


def test_without_the_guard_the_lattice_leaves_free_nodes_inside_the_guards_clearance():
    # the premise of the next test: the blocked nodes alone (the rows' cells sampled at the
    # lattice's nodes, the post's columns) leave nodes free that the guard, measuring to the
    # surfaces themselves, finds inside the row clearance (as in mix flights 137 and 168)
    from dataclasses import replace

    from companion.replan.route3d import free_nodes, lattice_for

    sc, guard = _guarded_scene(keep=0.442 + 0.4)
    bare = replace(sc, guard=None)
    lat = lattice_for(bare, [(0.0, 0.0, 1.5), (10.0, 8.0, 1.5)])
    free = free_nodes(bare, lat)
    i, j, k = np.nonzero(free)
    d = guard.distances(np.stack([lat.x[i], lat.y[j], lat.z[k]], axis=1), terrain=False)
    assert (d["row"] < guard.required_m("row")).any()


@pytest.mark.parametrize("keep", [0.442 + 0.4, KEEP])
def test_with_the_guard_every_move_between_free_nodes_keeps_the_guards_clearance(keep):
    # route3d.edge_keep_m: any point of a set at least k from both ends of a move of length
    # L is passed at sqrt(k^2 - L^2/4) or more; the moves are sampled here and measured by
    # the guard itself, rows and obstacles
    from companion.replan.route3d import free_nodes, lattice_for

    sc, guard = _guarded_scene(keep)
    lat = lattice_for(sc, [(0.0, 0.0, 1.5), (10.0, 8.0, 1.5)])
    free = free_nodes(sc, lat)
    assert free.sum() > 1000
    d = guard.distances(_moves_between(free, lat), terrain=False)
    for kind in ("row", "obstacle"):
        assert d[kind].min() >= guard.required_m(kind) - 1e-9, kind


def test_the_chord_allowance_is_the_closest_a_diagonal_move_passes_a_corner():
    # hand-worked: a corner point c, the diagonal move's ends both exactly k from it; the
    # move's midpoint is sqrt(k^2 - (s sqrt(2) / 2)^2) from c, which is the clearance
    from companion.replan.route3d import edge_keep_m

    req, s = 0.842, 0.25
    k = edge_keep_m(req, s)
    half = s * np.sqrt(2.0) / 2.0
    assert np.isclose(np.sqrt(k * k - half * half), req, rtol=0, atol=1e-12)
    assert k - req == pytest.approx(0.01836, abs=1e-5)     # sqrt(0.842^2 + 0.03125) - 0.842


def test_a_route_searched_with_the_guard_passes_the_guards_path_rule():
    # from beside the first row, over its canopy's edge (2 m; the ceiling 3 m leaves one
    # layer of nodes over it) into the next corridor: the route climbs past the box's edge
    sc, guard = _guarded_scene(keep=0.442 + 0.4)
    r = find_route(sc, (0.5, 0.0, 1.5), [(4.0, 6.06, 3.0)])
    assert r is not None and r.path_enu_m[:, 2].max() == pytest.approx(3.0)
    path = _dense(r.path_enu_m[1:-1])             # the start's and goal's legs are off the lattice
    verdict = guard.check_path(path)
    assert verdict.ok, verdict.detail
