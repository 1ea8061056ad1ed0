"""The persistent obstacle map (companion/replan/voxmap.py): cleared only along
beams, never by time, memory bounded by the area flown, exact distances."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.replan.perception import BeamEvidence
from companion.replan.voxmap import (CANDIDATE_LIFETIME_S, L_CANDIDATE, L_HIT, L_MAX, L_MISS, ObstacleMap,
                                     _box_distance)

V = 0.1


def _beam(origin, axis, free_m, half_rad=0.0):
    """A beam along ``axis`` (unit, horizontal) with its fields opening horizontally (h) and vertically (v)."""
    u = np.asarray(axis, dtype=float)
    h = np.array([-u[1], u[0], 0.0])
    return BeamEvidence(tuple(origin), tuple(u), tuple(h), (0.0, 0.0, 1.0), half_rad, half_rad, float(free_m),
                        None, float("nan"))


def _one_voxel():
    m = ObstacleMap(V, clear_margin_m=0.15)
    m.add((3.05, 0.05, 1.05))            # the voxel [3.0, 3.1] x [0.0, 0.1] x [1.0, 1.1]
    return m


def test_a_beam_through_the_voxel_clears_it():
    m = _one_voxel()
    assert m.clear_beam(_beam((0.0, 0.05, 1.05), (1, 0, 0), 5.0)) == 1
    assert len(m) == 0 and m.log_odds((3.05, 0.05, 1.05)) == 0.0


def test_a_beam_beside_the_voxel_clears_nothing():
    m = _one_voxel()
    # a narrow beam 0.2 m to the side: its axis never enters [0, 0.1] in y
    assert m.clear_beam(_beam((0.0, 0.25, 1.05), (1, 0, 0), 5.0)) == 0
    assert len(m) == 1


def test_a_beam_clears_only_short_of_its_return_minus_the_margin():
    m = _one_voxel()
    # return at 3.1 m: free only to 3.1 - 0.15 = 2.95 m, short of the voxel's face at 3.0 m
    assert m.clear_beam(_beam((0.0, 0.05, 1.05), (1, 0, 0), 3.1)) == 0
    # return at 3.3 m: free to 3.15 m, through the voxel
    assert m.clear_beam(_beam((0.0, 0.05, 1.05), (1, 0, 0), 3.3)) == 1


def test_a_wide_beam_clears_only_its_inner_cone():
    # 22.5 deg field: the inner cone is half of the 11.25 deg half-angle, tan(5.625 deg) = 0.0985,
    # 0.300 m to the side at the voxel's point 3.05 m along the axis, widened by half a voxel: 0.350 m
    half = math.radians(11.25)
    m = _one_voxel()
    assert m.clear_beam(_beam((0.0, 0.05 + 0.40, 1.05), (1, 0, 0), 6.0, half)) == 0    # 0.40 m off
    assert m.clear_beam(_beam((0.0, 0.05 + 0.30, 1.05), (1, 0, 0), 6.0, half)) == 1    # 0.30 m off


def test_a_candidate_is_cleared_by_the_whole_cone_and_lapses_unless_confirmed():
    half = math.radians(11.25)                        # the whole cone: 0.60 + 0.05 m off at 3.05 m
    m = ObstacleMap(V)
    m.add((3.05, 0.05, 1.05), L_CANDIDATE, t_s=0.0)
    assert m.clear_beam(_beam((0.0, 0.05 + 0.40, 1.05), (1, 0, 0), 6.0, half)) == 1
    m.add((3.05, 0.05, 1.05), L_CANDIDATE, t_s=0.0)
    assert m.expire_candidates(CANDIDATE_LIFETIME_S - 0.01) == 0 and len(m) == 1
    assert m.expire_candidates(CANDIDATE_LIFETIME_S + 0.01) == 1 and len(m) == 0
    m.add((3.05, 0.05, 1.05), L_CANDIDATE, t_s=0.0)
    m.add((3.06, 0.04, 1.02), L_HIT)                  # an axis hit in the same voxel confirms it
    assert m.expire_candidates(1e6) == 0 and len(m) == 1


def test_a_voxel_seen_often_needs_as_many_beams():
    m = ObstacleMap(V)
    for _ in range(5):
        m.add((3.05, 0.05, 1.05))
    n = int(math.ceil(L_MAX / L_MISS))                 # clamped at L_MAX
    b = _beam((0.0, 0.05, 1.05), (1, 0, 0), 5.0)
    for _ in range(n - 1):
        m.clear_beam(b)
    assert len(m) == 1
    m.clear_beam(b)
    assert len(m) == 0


def test_nothing_but_beams_clears_the_map():
    # the map has no clock: queries, distance and other voxels' updates leave a voxel as it is
    m = _one_voxel()
    for k in range(1000):
        m.distance(np.array([[0.0, 0.0, 1.0]]))
        m.add((10.0 + 0.1 * k, 5.0, 1.0))
    assert m.log_odds((3.05, 0.05, 1.05)) == L_HIT


def test_memory_is_bounded_by_the_area_flown_not_the_time():
    # a vehicle circles a post (r 0.3 m, 2 m tall) for 40 laps, noisy returns (2 cm, seeded):
    # the voxels are those within the noise of its surface, whatever the number of laps
    rng = np.random.default_rng(7)
    m = ObstacleMap(V)
    r_post, noise = 0.3, 0.02
    sizes = []
    for lap in range(40):
        for a in np.linspace(0.0, 2 * math.pi, 72, endpoint=False):
            for z in np.arange(0.05, 2.0, 0.1):
                rr = r_post + rng.uniform(-noise, noise)
                m.add((rr * math.cos(a), rr * math.sin(a), z))
        sizes.append(len(m))
    # independent bound: the voxels whose box meets the shell r_post +- noise, 0 <= z <= 2
    k = np.arange(-5, 5)
    cx, cy = np.meshgrid((k + 0.5) * V, (k + 0.5) * V, indexing="ij")
    dx, dy = np.maximum(np.abs(cx) - V / 2, 0.0), np.maximum(np.abs(cy) - V / 2, 0.0)
    near = np.hypot(dx, dy) <= r_post + noise                                     # box's nearest point
    far = np.hypot(np.abs(cx) + V / 2, np.abs(cy) + V / 2) >= r_post - noise      # box's farthest point
    bound = int((near & far).sum()) * 20
    assert max(sizes) <= bound                        # the bound does not depend on the laps flown
    assert sizes[19] > 0.8 * bound                     # (the bound is not loose: the shell fills up)


def test_distance_hand_worked():
    m = ObstacleMap(V)
    assert np.all(np.isinf(m.distance(np.zeros((3, 3)))))
    m.add((0.05, 0.05, 0.05))                         # the box [0, 0.1]^3
    d = m.distance(np.array([[0.5, 0.05, 0.05], [0.4, 0.4, 0.05], [0.05, 0.05, 0.05], [-0.3, -0.4, 0.05]]))
    np.testing.assert_allclose(d, [0.4, math.hypot(0.3, 0.3), 0.0, 0.5], atol=1e-12)


def test_distance_never_exceeds_the_true_one_and_exact_mode_is_exact():
    rng = np.random.default_rng(3)
    m = ObstacleMap(V)
    for y in np.arange(0.05, 6.0, 0.1):               # a wall: the k nearest centres do not settle it
        for z in np.arange(0.05, 1.5, 0.1):
            m.add((2.05, y, z))
    for p in rng.uniform(0.0, 4.0, (60, 3)):
        m.add(p)
    q = rng.uniform(-1.0, 5.0, (200, 3))
    centres = (m.keys() + 0.5) * V
    truth = _box_distance(q[:, None, :], centres[None], V / 2).min(axis=1)
    np.testing.assert_allclose(m.distance(q, exact=True), truth, atol=1e-12)
    fast = m.distance(q)
    assert np.all(fast <= truth + 1e-12)
    assert np.all(fast >= truth - math.sqrt(3.0) * V / 2 - 1e-12)


def test_a_small_query_is_brute_force_and_gives_the_k_d_trees_numbers():
    """Few (point, voxel) pairs (the guard's two points a frame) skip the k-d tree; the
    answer is the same number, bit for bit, as the tree's (a batch too large for the
    brute path), within the true distance's bounds, and exact for a hand-worked box."""
    from companion.replan.voxmap import K_NEAR, SMALL_PAIRS

    rng = np.random.default_rng(11)
    for n in (1, K_NEAR, K_NEAR + 1, 40, SMALL_PAIRS // 2):
        m = ObstacleMap(V)
        while len(m) < n:
            a, z = rng.uniform(0.0, 2.0 * math.pi), rng.uniform(0.0, 2.0)
            m.add((10.0 + 0.4 * math.cos(a), 5.0 + 0.4 * math.sin(a), z))
        q = rng.uniform([8.0, 3.0, -0.5], [12.0, 7.0, 2.5], (SMALL_PAIRS + 1, 3))   # tree: > SMALL_PAIRS pairs
        tree = m.distance(q)
        small = np.concatenate([m.distance(q[i:i + 2]) for i in range(0, len(q), 2)])
        assert len(m) * 2 <= SMALL_PAIRS
        np.testing.assert_array_equal(small, tree)
        centres = (m.keys() + 0.5) * V
        truth = _box_distance(q[:, None, :], centres[None], V / 2).min(axis=1)
        assert np.all(small <= truth + 1e-12)
        assert np.all(small >= truth - math.sqrt(3.0) * V / 2 - 1e-12)
    # a few points against a map too large for SMALL_PAIRS, while the tree is not built (the
    # map changed): brute force, the tree's numbers, and no tree built for them
    from companion.replan.voxmap import FEW_POINTS
    m = ObstacleMap(V)
    while len(m) < SMALL_PAIRS:
        m.add(tuple(rng.uniform([9.0, 4.0, 0.0], [11.0, 6.0, 2.0])))
    q = rng.uniform([8.0, 3.0, -0.5], [12.0, 7.0, 2.5], (40, 3))
    few = np.concatenate([m.distance(q[i:i + FEW_POINTS]) for i in range(0, len(q), FEW_POINTS)])
    assert m._tree is None
    np.testing.assert_array_equal(few, m.distance(q))        # 40 points: the tree
    assert m._tree is not None
    m = ObstacleMap(V)
    m.add((0.05, 0.05, 0.05))                         # the box [0, 0.1]^3, brute path
    np.testing.assert_allclose(m.distance(np.array([[0.5, 0.05, 0.05], [-0.3, -0.4, 0.05]])), [0.4, 0.5],
                               atol=1e-12)


def test_points_lower_bound_never_exceeds_a_points_distance():
    """The bounding box's distance (the replanner skips its per-point threat and
    closest-range scans with it): hand-worked outside the box, 0 inside, inf empty,
    and never above the distance to any point, however the distance is summed."""
    m = ObstacleMap(V)
    assert m.points_lower_bound((0.0, 0.0, 0.0)) == math.inf
    m.add((1.05, 2.05, 1.05))
    m.add((3.05, 2.55, 1.45))
    # the box of the points: x 1.05..3.05, y 2.05..2.55, z 1.05..1.45
    assert m.points_lower_bound((0.05, 2.3, 1.2)) == pytest.approx(1.0, abs=1e-8)
    assert m.points_lower_bound((4.05, 0.05, 2.45)) == pytest.approx(math.sqrt(1.0 + 4.0 + 1.0), abs=1e-8)
    assert m.points_lower_bound((2.0, 2.3, 1.2)) < 0.0           # inside the box
    rng = np.random.default_rng(2)
    for _ in range(30):
        m.add(rng.uniform(0.0, 3.0, 3))
    pts = m.points()
    for p in rng.uniform(-3.0, 6.0, (500, 3)):
        rel = pts - p
        assert m.points_lower_bound(p) <= np.sqrt(np.einsum("ki,ki->k", rel, rel)).min()
        assert m.points_lower_bound(p) <= np.linalg.norm(rel, axis=1).min()


def test_the_grouped_broad_phase_clears_what_one_box_clears(monkeypatch):
    """``clear_beam`` skips a beam that reaches no box of the points stored in a GROUP_M
    square; beams through a map of three obstacles far apart clear exactly what the same
    beams clear with the whole map as one square (the box test alone), and the squares'
    boxes stay a cover of the points as voxels come and go."""
    import companion.replan.voxmap as vm

    rng = np.random.default_rng(8)

    def build(group_m):
        monkeypatch.setattr(vm, "GROUP_M", group_m)
        m = ObstacleMap(V, clear_margin_m=0.15)
        for cx, cy in ((2.0, 2.0), (9.0, 2.5), (5.5, 8.0)):
            for _ in range(40):
                m.add((cx + rng.uniform(-0.3, 0.3), cy + rng.uniform(-0.3, 0.3), rng.uniform(0.5, 2.0)))
        return m

    state = rng.bit_generator.state
    grouped = build(1.0)
    rng.bit_generator.state = state
    whole = build(1e9)
    assert len(grouped._groups) >= 3 and len(whole._groups) == 1
    gone_g = gone_w = 0
    for k in range(600):
        o = (rng.uniform(0.0, 11.0), rng.uniform(0.0, 10.0), rng.uniform(0.8, 1.8))
        a = rng.uniform(0.0, 2.0 * math.pi)
        ev = _beam(o, (math.cos(a), math.sin(a), 0.0), rng.uniform(0.5, 5.0), rng.choice([0.0, 0.2]))
        gone_g += grouped.clear_beam(ev)
        gone_w += whole.clear_beam(ev)
        assert grouped._l == whole._l
        if k % 50 == 0:                     # new voxels between beams: both maps alike
            q = (rng.uniform(0.0, 11.0), rng.uniform(0.0, 10.0), rng.uniform(0.5, 2.0))
            monkeypatch.setattr(vm, "GROUP_M", 1.0)
            grouped.add(q)
            monkeypatch.setattr(vm, "GROUP_M", 1e9)
            whole.add(q)
    assert gone_g == gone_w > 0
    for p in grouped.points():              # every point lies in its square's box
        b = grouped._groups[(math.floor(p[0] / 1.0), math.floor(p[1] / 1.0))]
        assert all(b[i] <= p[i] <= b[3 + i] for i in range(3))
