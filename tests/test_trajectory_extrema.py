"""Exact largest speed between times (companion/trajectory/extrema.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.trajectory import Trajectory
from mavcore.mission.trajectory import TrajectoryConfig
from companion.trajectory.extrema import max_speed_on_intervals


def _one_piece(duration_s: float, cy: float) -> Trajectory:
    # x(s) = 2 s^2 - 4/3 s^3: dx/ds = 4 s (1 - s), largest 1 at s = 1/2, 0 at both ends;
    # y(s) = cy s: dy/ds = cy. Speeds are d/ds divided by the duration.
    pos = np.zeros((1, 8, 3))
    pos[0, 2, 0], pos[0, 3, 0] = 2.0, -4.0 / 3.0
    pos[0, 1, 1] = cy
    pos[0, 0, 2] = 1.5
    return Trajectory.from_pieces(np.array([0.0, duration_s]), pos, np.array([0, 1]), np.zeros((2, 3, 3)),
                                  TrajectoryConfig())


def test_hand_worked_piece_whose_samples_miss_the_peak():
    tr = _one_piece(2.0, 0.3)
    # [0, 2] sampled only at its ends: 0.15 m/s there, sqrt(0.5^2 + 0.15^2) at t = 1 s
    assert max_speed_on_intervals(tr, [0.0, 2.0])[0] == pytest.approx(math.hypot(0.5, 0.15), abs=1e-12)
    # [0, 0.7] rises all the way (s = 0.35: 4 0.35 0.65 / 2 = 0.455); [0.7, 2] holds the peak
    v = max_speed_on_intervals(tr, [0.0, 0.7, 2.0])
    assert v[0] == pytest.approx(math.hypot(0.455, 0.15), abs=1e-12)
    assert v[1] == pytest.approx(math.hypot(0.5, 0.15), abs=1e-12)


def test_every_piece_of_a_planned_trajectory_against_dense_samples_and_a_lipschitz_bound():
    from mavcore.mission import load_mission
    from companion.planner import plan_mission
    from pathlib import Path

    m = load_mission(Path(__file__).resolve().parents[1] / "missions" / "flat-rectangle" / "mission.yaml")
    tr = plan_mission(m).trajectory
    knots = tr.knot_times_s
    exact = max_speed_on_intervals(tr, knots)
    n = 400
    for k in range(knots.size - 1):
        t = np.linspace(knots[k], knots[k + 1], n)
        s = tr.sample(t)
        dense = np.linalg.norm(s.v, axis=1).max()
        # |d|v|/dt| <= |a|, so between dense samples |v| exceeds them by at most max|a| h / 2
        # (max|a| itself bounded the same way by the jerk)
        h = t[1] - t[0]
        a_max = np.linalg.norm(s.a, axis=1).max() + np.linalg.norm(s.jerk, axis=1).max() * h / 2
        assert dense - 1e-12 <= exact[k] <= dense + a_max * h / 2 + 1e-12


def _stationary_times_piece_by_piece(trajectory) -> np.ndarray:
    """The per-piece algorithm ``stationary_times`` batches: |v|^2 by ``np.convolve``,
    ``P.polyder``, trailing zeros trimmed, ``P.polyroots``, the real zeros in (0, 1)."""
    from numpy.polynomial import polynomial as P

    knots = trajectory.knot_times_s
    V = np.asarray(trajectory.coefficients, dtype=float)[:, :, 1, :]
    out = []
    for m in range(V.shape[0]):
        dq = np.trim_zeros(P.polyder(sum(np.convolve(V[m][:, a], V[m][:, a]) for a in range(3))), "b")
        if dq.size < 2 or not np.any(dq):
            continue
        r = P.polyroots(dq)
        s = r.real[(np.abs(r.imag) <= 1e-6) & (r.real > 0.0) & (r.real < 1.0)]
        out.append(knots[m] + s * (knots[m + 1] - knots[m]))
    return np.sort(np.concatenate(out)) if out else np.empty(0)


def test_batched_zeros_are_the_per_piece_polyroots_bit_for_bit():
    # a planned trajectory (degree-7 pieces: |v|^2' of length 14, trailing zero trimmed), plus pieces
    # of constant speed (no zero), a linear |v|^2' (polyroots' closed form) and a cubic one, so every
    # length group of the batch is exercised
    from mavcore.mission import load_mission
    from companion.planner import plan_mission
    from companion.trajectory.extrema import _roots_by_length, _squared_speed_derivatives, stationary_times
    from pathlib import Path

    m = load_mission(Path(__file__).resolve().parents[1] / "missions" / "flat-rectangle" / "mission.yaml")
    tr = plan_mission(m).trajectory
    pos = np.zeros((4, 8, 3))
    pos[0, 1, 0] = 0.7                                   # v = const: no zero
    pos[1, 2, 1] = 1.0                                   # v = 2 s: |v|^2' = 8 s, one zero at 0 (not inside)
    pos[2, 2, 0], pos[2, 3, 0] = 2.0, -4.0 / 3.0          # v = 4 s (1 - s): |v|^2' cubic, zeros at 0, 1/2, 1
    pos[3] = np.asarray(tr.coefficients)[3, :, 0, :]
    small = Trajectory.from_pieces(np.array([0.0, 1.0, 2.5, 4.0, 5.0]), pos, np.array([0, 4]),
                                   np.zeros((2, 3, 3)), TrajectoryConfig())
    for t in (tr, small):
        got, ref = stationary_times(t), _stationary_times_piece_by_piece(t)
        assert got.shape == ref.shape and np.array_equal(got.view(np.int64), ref.view(np.int64))
    # the hand-worked piece: |v|^2 = 16 s^2 (1 - s)^2 is stationary at s = 1/2 only, inside (0, 1)
    assert list(_roots_by_length(_squared_speed_derivatives(np.zeros((0, 3, 8))))) == []   # no pieces
    st = stationary_times(small)
    assert np.any(np.abs(st - (2.5 + 0.5 * 1.5)) < 1e-9) and not np.any((st > 1.0) & (st < 2.5))


def test_derivatives_are_sample_bit_for_bit_and_feed_the_speed_bound():
    """``Trajectory.derivatives`` (no pointing) gives ``sample``'s p, v, a, jerk, snap bit for bit,
    times outside [t0, tf] clamped alike, unsorted and past the gather threshold (> 4096 samples:
    the per-interval products); ``max_speed_on_intervals`` with the caller's velocities equals it
    without them."""
    from mavcore.mission import load_mission
    from companion.planner import plan_mission
    from pathlib import Path

    m = load_mission(Path(__file__).resolve().parents[1] / "missions" / "flat-rectangle" / "mission.yaml")
    tr = plan_mission(m).trajectory
    rng = np.random.default_rng(4)
    for t in (rng.uniform(tr.t0 - 5.0, tr.tf + 5.0, 300), np.linspace(tr.t0, tr.tf, 6000)):
        s, d = tr.sample(t), tr.derivatives(t)
        for k, x in enumerate((s.p, s.v, s.a, s.jerk, s.snap)):
            assert np.array_equal(x.view(np.int64), d[:, k, :].view(np.int64))
    t = np.linspace(tr.t0, tr.tf, 500)
    a = max_speed_on_intervals(tr, t)
    b = max_speed_on_intervals(tr, t, tr.sample(t).v)
    assert np.array_equal(a.view(np.int64), b.view(np.int64))
