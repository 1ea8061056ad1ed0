"""Tests of the LQR trajectory (Section 2.3.2) and the pointing direction (eq. 21).

Every expected value is derived independently of the code under test:
an integration of the paper's 12-state Riccati/costate equations with
scipy's ODE solvers, a first-variation check of the cost by quadrature,
closed-form optimal polynomials derived by hand from the natural boundary
conditions, scipy's algebraic Riccati solver, and finite differences.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.linalg import expm, solve_continuous_are

from mavcore.errors import PlanError
from mavcore.mission.trajectory import TrajectoryConfig
from companion.trajectory import (
    generate_trajectory,
    pointing_derivatives,
    pointing_directions,
)

# ----------------------------------------------------------------------------- helpers


def _paper_matrices():
    """A (12x12), B (12x3), C (9x12) exactly as printed in eq. (5): state [b, b', b'', b''']."""
    A = np.zeros((12, 12))
    A[:9, 3:] = np.eye(9)
    B = np.zeros((12, 3))
    B[9:, :] = np.eye(3)
    C = np.zeros((9, 12))
    C[:, :9] = np.eye(9)
    return A, B, C


def _reference_riccati(times, y, x0, cfg, t_eval):
    """Independent solution on the coupled 12-state system with scipy.integrate.solve_ivp.

    Backward sweep of -P' = PA + A'P + Q - P B R^-1 B' P and
    -eta' = (A - B R^-1 B' P)' eta with P(t_N) = 2 C'SC, eta(t_N) = -2 C'S y_N
    and the jumps P += 2 C'SC, eta -= 2 C'S y_i at interior way-points (the
    stationarity conditions of the cost with the S term carrying no 1/2);
    then the state forward with u = -R^-1 B' (P x + eta).

    Returns x (len(t_eval), 12) and u (len(t_eval), 3).
    """
    A, B, C = _paper_matrices()
    S = np.kron(np.diag(cfg.s_diag), np.eye(3))
    Q = np.kron(np.diag(cfg.q_diag), np.eye(3))
    Rinv = np.eye(3) / cfg.r_snap
    BRB = B @ Rinv @ B.T
    tol = dict(rtol=1e-12, atol=1e-12, method="DOP853", dense_output=True)

    def backward(t, z):
        P = z[:144].reshape(12, 12)
        eta = z[144:]
        dP = -(P @ A + A.T @ P + Q - P @ BRB @ P)
        deta = -(A - BRB @ P).T @ eta
        return np.concatenate([dP.ravel(), deta])

    P = 2 * C.T @ S @ C
    eta = -2 * C.T @ S @ y[-1]
    sweeps = []
    for i in range(len(times) - 1, 0, -1):
        sol = solve_ivp(backward, (times[i], times[i - 1]), np.concatenate([P.ravel(), eta]), **tol)
        sweeps.append(sol)
        P = sol.y[:144, -1].reshape(12, 12)
        eta = sol.y[144:, -1]
        if i - 1 > 0:
            P = P + 2 * C.T @ S @ C
            eta = eta - 2 * C.T @ S @ y[i - 1]
    sweeps = sweeps[::-1]                              # sweeps[k] covers [t_k, t_{k+1}]

    def gain(k, t):
        z = sweeps[k].sol(t)
        return z[:144].reshape(12, 12), z[144:]

    xs = np.empty((len(t_eval), 12))
    us = np.empty((len(t_eval), 3))
    x = x0.copy()
    for k in range(len(times) - 1):
        def forward(t, x, k=k):
            P, eta = gain(k, t)
            return A @ x - BRB @ (P @ x + eta)
        sol = solve_ivp(forward, (times[k], times[k + 1]), x, **tol)
        sel = (t_eval >= times[k]) & (t_eval <= times[k + 1])
        for j in np.flatnonzero(sel):
            xs[j] = sol.sol(t_eval[j])
            P, eta = gain(k, t_eval[j])
            us[j] = -Rinv @ B.T @ (P @ xs[j] + eta)
        x = sol.y[:, -1]
    return xs, us


def _small_case():
    times = np.array([0.0, 1.5, 2.7, 4.0])
    pos = np.array([[0.0, 0.0, 1.0], [2.0, 0.5, 1.2], [3.0, 2.0, 1.1], [3.5, 4.0, 1.5]])
    vel = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.1], [0.5, 1.5, 0.0], [0.0, 0.0, 0.0]])
    acc = np.array([[0.0, 0.0, 0.0], [0.2, -0.1, 0.0], [0.0, 0.3, 0.1], [0.0, 0.0, 0.0]])
    x0 = np.array([[0.0, 0.0, 1.0], [0.3, -0.2, 0.0], [0.1, 0.0, 0.05], [0.0, 0.2, -0.1]])
    return times, pos, vel, acc, x0


def _boustrophedon(n_rows=6, row_length_m=42.0, spacing_m=2.5, speed_m_s=1.0, interval_s=4.0,
                   height_m=1.5):
    """Vineyard way-points: rows along x, corners at rest, 4 m / 4 s between points.

    Times follow distance / speed (also for the 2.5 m cross-over between rows).
    Returns times (N,), pos (N, 3), vel (N, 3), corner mask (N,).
    """
    times, pos, vel, corner = [], [], [], []
    t = 0.0
    for r in range(n_rows):
        xs = np.append(np.arange(0.0, row_length_m, speed_m_s * interval_s), row_length_m)
        direction = 1.0
        if r % 2:
            xs = row_length_m - xs
            direction = -1.0
        for k, x in enumerate(xs):
            p = np.array([x, r * spacing_m, height_m])
            if pos:
                t += np.linalg.norm(p - pos[-1]) / speed_m_s
            is_corner = k in (0, len(xs) - 1)
            times.append(t)
            pos.append(p)
            vel.append(np.zeros(3) if is_corner else np.array([direction * speed_m_s, 0.0, 0.0]))
            corner.append(is_corner)
    return np.array(times), np.array(pos), np.array(vel), np.array(corner)


def _cost(traj, times, pos, vel, acc, cfg, x_extra=None, u_extra=None, n_gauss=40):
    """J of eq. (4) by Gauss-Legendre quadrature on each interval.

    x_extra(t) -> (n, 4, 3) and u_extra(t) -> (n, 3) are added to the
    trajectory's state and snap (a perturbation that keeps x(t_0) fixed).
    """
    S = np.diag(cfg.s_diag)
    Q = np.diag(cfg.q_diag)
    nodes, weights = np.polynomial.legendre.leggauss(n_gauss)
    J = 0.0
    for a, b in zip(times[:-1], times[1:]):
        t = 0.5 * (b - a) * nodes + 0.5 * (a + b)
        smp = traj.sample(t)
        x = np.stack([smp.p, smp.v, smp.a, smp.jerk], axis=1)          # (n, 4, 3)
        u = smp.snap
        if x_extra is not None:
            x = x + x_extra(t)
            u = u + u_extra(t)
        integrand = 0.5 * (np.einsum("nia,ij,nja->n", x, Q, x) + cfg.r_snap * np.sum(u * u, axis=1))
        J += 0.5 * (b - a) * np.dot(weights, integrand)
    smp = traj.sample(times[1:])
    x = np.stack([smp.p, smp.v, smp.a], axis=1)
    if x_extra is not None:
        x = x + x_extra(times[1:])[:, :3]
    r = x - np.stack([pos, vel, acc], axis=1)[1:]
    return J + float(np.einsum("nia,ij,nja->", r, S, r))


# ------------------------------------------------------------------- (1) exact vs reference


@pytest.mark.parametrize("cfg", [
    TrajectoryConfig(s_position=50.0, s_velocity=5.0, s_acceleration=1.0, q_position=0.3,
                     q_velocity=0.2, q_acceleration=0.1, q_jerk=0.5, r_snap=0.7),
    TrajectoryConfig(s_position=200.0, s_velocity=20.0, s_acceleration=2.0, r_snap=2.0),
], ids=["Q-nonzero", "Q-zero"])
def test_matches_coupled_riccati_reference(cfg):
    times, pos, vel, acc, x0 = _small_case()
    traj = generate_trajectory(times, pos, vel, acc, config=cfg, initial_state=x0)
    t_eval = np.concatenate([np.linspace(0.0, 4.0, 23), times])
    y = np.concatenate([pos, vel, acc], axis=1)                   # (N, 9): [b, v, a]
    xs, us = _reference_riccati(times, y, x0.reshape(12), cfg, t_eval)
    smp = traj.sample(t_eval)
    mine = np.concatenate([smp.p, smp.v, smp.a, smp.jerk], axis=1)
    np.testing.assert_allclose(mine, xs, atol=1e-6, rtol=0)
    np.testing.assert_allclose(smp.snap, us, atol=1e-6, rtol=0)


def test_matches_reference_with_very_short_and_long_intervals():
    """A 1 ms interval between long ones (a way-point remainder) and a 9 s one.

    Both are hard for naive formulations (stiffness ~ 1/dt^7 vs transition
    growth ~ dt^7); the exact solution must still match the reference.
    """
    times, pos, vel, acc, x0 = _small_case()
    times = np.array([0.0, 1.5, 1.501, 10.5])
    pos[2] = pos[1] + 0.001 * vel[1]
    t_eval = np.concatenate([np.linspace(0.0, 10.5, 31), [1.5005]])
    y = np.concatenate([pos, vel, acc], axis=1)
    for cfg in (TrajectoryConfig(), TrajectoryConfig(q_velocity=0.5, q_jerk=1.0, r_snap=0.5)):
        traj = generate_trajectory(times, pos, vel, acc, config=cfg, initial_state=x0)
        xs, us = _reference_riccati(times, y, x0.reshape(12), cfg, t_eval)
        smp = traj.sample(t_eval)
        np.testing.assert_allclose(np.concatenate([smp.p, smp.v, smp.a, smp.jerk], axis=1), xs,
                                   atol=1e-6, rtol=0)
        np.testing.assert_allclose(smp.snap, us, atol=1e-6, rtol=0)


# ----------------------------------------------------------------------- (2) optimality


def test_cost_is_stationary_and_minimal_under_perturbations():
    times, pos, vel, acc, x0 = _small_case()
    cfg = TrajectoryConfig(s_position=30.0, s_velocity=3.0, s_acceleration=0.5, q_velocity=0.2,
                           q_jerk=0.1, r_snap=1.0)
    traj = generate_trajectory(times, pos, vel, acc, config=cfg, initial_state=x0)
    J0 = _cost(traj, times, pos, vel, acc, cfg)
    rng = np.random.default_rng(7)
    for _ in range(3):
        amp = rng.normal(size=(3, 3))
        freq = rng.uniform(0.5, 3.0, size=3)
        phase = rng.uniform(0, 2 * np.pi, size=3)

        def delta_u(t):
            t = np.atleast_1d(t)
            return np.sin(np.outer(t, freq) + phase) @ amp        # (n, 3) snap perturbation

        # state perturbation from x' = A x + B du, x(t0) = 0 (integrated independently)
        A = np.diag(np.ones(3), 1)
        e4 = np.array([0.0, 0.0, 0.0, 1.0])

        def rhs(t, z):
            return (A @ z.reshape(4, 3) + np.outer(e4, delta_u(t)[0])).ravel()

        sol = solve_ivp(rhs, (times[0], times[-1]), np.zeros(12), rtol=1e-12, atol=1e-13,
                        method="DOP853", dense_output=True)

        def delta_x(t):
            return sol.sol(np.atleast_1d(t)).T.reshape(-1, 4, 3)

        J = {}
        for eps in (-1e-3, 1e-3, -0.1, 0.1):
            J[eps] = _cost(traj, times, pos, vel, acc, cfg,
                           x_extra=lambda t, e=eps: e * delta_x(t),
                           u_extra=lambda t, e=eps: e * delta_u(t))
            assert J[eps] > J0
        # J(eps) = J0 + g eps + h eps^2: the first variation g must vanish
        g = (J[1e-3] - J[-1e-3]) / 2e-3
        h = (J[1e-3] + J[-1e-3] - 2 * J0) / 1e-6
        assert h > 0
        assert abs(g) < 1e-6 * max(1.0, h)


# -------------------------------------------------------------------- (3) closed forms


def test_position_only_limit_matches_natural_boundary_polynomial():
    """S on position only, S -> infinity, Q = 0, from rest at p0 to p1 in T.

    Hand derivation: u = -lambda_4 / R with lambda' = -A' lambda, so u is a
    cubic; after the last way-point lambda = 0 and only lambda_1 jumps
    (S weighs position only), so lambda_2 = lambda_3 = lambda_4 = 0 at T:
    u(T) = u'(T) = u''(T) = 0, u = c (T - t)^3. From rest,
    p(t) = p0 + c/6 int_0^t (t - s)^3 (T - s)^3 ds, and p(T) = p1 gives
    c = 42 (p1 - p0) / T^7.
    """
    T = 2.0
    p0 = np.array([1.0, -2.0, 0.5])
    p1 = np.array([4.0, 1.0, 2.5])
    cfg = TrajectoryConfig(s_position=1e10, s_velocity=0.0, s_acceleration=0.0)
    traj = generate_trajectory([0.0, T], [p0, p1], config=cfg)
    c = 42.0 * (p1 - p0) / T**7
    for t in (0.3, 0.9, 1.4, 2.0):
        integral = quad(lambda s: (t - s) ** 3 * (T - s) ** 3, 0.0, t, epsabs=1e-14)[0]
        expected = p0 + c / 6.0 * integral
        np.testing.assert_allclose(traj.sample(t).p, expected, atol=1e-7)
        np.testing.assert_allclose(traj.sample(t).snap, c * (T - t) ** 3, atol=1e-6)


def test_rest_to_rest_limit_matches_hand_polynomial():
    """S on p, v, a -> infinity, Q = 0, rest to rest over T (jerk free at T).

    With x(0) = 0 the optimal p is sum_{k=4..7} c_k tau^k (snap is a cubic).
    The end conditions are p(1) = D, p'(1) = p''(1) = 0 and, since the jerk
    is not weighed, lambda_4(T) = 0, i.e. snap(T) = 0. (With the jerk also
    fixed this would be 35 tau^4 - 84 tau^5 + 70 tau^6 - 20 tau^7; here
    the fourth condition is the natural one.)
    """
    T = 3.0
    D = np.array([2.0, -1.0, 0.5])
    k = np.arange(4, 8)
    rows = np.array([
        np.ones(4),                                   # p(1)
        k,                                            # p'(1)
        k * (k - 1),                                  # p''(1)
        k * (k - 1) * (k - 2) * (k - 3),              # p''''(1)
    ], dtype=float)
    coef = np.linalg.solve(rows, [1.0, 0.0, 0.0, 0.0])
    cfg = TrajectoryConfig(s_position=1e12, s_velocity=1e12, s_acceleration=1e12)
    traj = generate_trajectory([0.0, T], [np.zeros(3), D], config=cfg)
    tau = np.linspace(0.0, 1.0, 11)
    shape = (tau[:, None] ** k[None, :]) @ coef
    np.testing.assert_allclose(traj.sample(tau * T).p, shape[:, None] * D[None, :], atol=1e-6)
    assert np.allclose(traj.sample(T).snap, 0.0, atol=1e-5)


def test_long_horizon_gain_matches_algebraic_riccati():
    """Far from the end, u = -R^-1 B' P x with P from the algebraic Riccati equation."""
    cfg = TrajectoryConfig(s_position=10.0, s_velocity=1.0, s_acceleration=1.0, q_position=1.0,
                           q_velocity=2.0, q_acceleration=1.5, q_jerk=0.5, r_snap=0.8)
    A = np.diag(np.ones(3), 1)
    B = np.array([[0.0], [0.0], [0.0], [1.0]])
    Q = np.diag(cfg.q_diag)
    P = solve_continuous_are(A, B, Q, np.array([[cfg.r_snap]]))
    K = (B.T @ P / cfg.r_snap).ravel()                  # u = -K x
    rng = np.random.default_rng(3)
    x0 = rng.normal(size=(4, 3))
    traj = generate_trajectory([0.0, 60.0], np.zeros((2, 3)), config=cfg, initial_state=x0)
    np.testing.assert_allclose(traj.sample(0.0).snap, -K @ x0, rtol=1e-8, atol=1e-10)
    # and the closed loop x(t) = exp((A - B K) t) x0 well before the end
    for t in (1.0, 5.0, 12.0):
        expected = expm((A - B @ K[None, :]) * t) @ x0
        smp = traj.sample(t)
        np.testing.assert_allclose(np.stack([smp.p, smp.v, smp.a, smp.jerk]), expected, atol=1e-9)


# --------------------------------------------------------------------- (4) S monotone


def test_residuals_shrink_monotonically_as_S_grows():
    times, pos, vel, _ = _boustrophedon(n_rows=2, row_length_m=12.0)
    # position-only S: the squared position residual is non-increasing in S
    # (trade-off of a convex quadratic); with a fixed S shape, the S-weighted residual
    previous_pos = previous_weighted = np.inf
    for scale in np.geomspace(1e-2, 1e6, 9):
        cfg = TrajectoryConfig(s_position=scale, s_velocity=0.0, s_acceleration=0.0)
        res = generate_trajectory(times, pos, vel, config=cfg).waypoint_residual_m
        assert np.sum(res**2) < previous_pos
        previous_pos = np.sum(res**2)
        cfg = TrajectoryConfig(s_position=scale, s_velocity=0.1 * scale, s_acceleration=0.01 * scale)
        traj = generate_trajectory(times, pos, vel, config=cfg)
        r = traj.waypoint_states[:, :3, :] - traj.waypoint_targets
        weighted = float(np.sum(r**2 * np.array([1.0, 0.1, 0.01])[None, :, None]))
        assert weighted < previous_weighted
        previous_weighted = weighted


# -------------------------------------------------------------------- (5) continuity


@pytest.mark.parametrize("cfg", [TrajectoryConfig(), TrajectoryConfig(q_velocity=0.3, q_jerk=2.0)],
                         ids=["default", "Q-nonzero"])
def test_sampling_is_continuous_across_knots(cfg):
    times, pos, vel, _ = _boustrophedon(n_rows=2, row_length_m=12.0)
    traj = generate_trajectory(times, pos, vel, config=cfg)
    knots = traj.knot_times_s[1:-1]                          # includes sub-knots when Q != 0
    h = 1e-7
    left, right = traj.sample(knots - h), traj.sample(knots + h)
    at = traj.sample(knots)
    # a C^4 function moves by at most max|next derivative| * 2h across the knot
    for name, bound in (("p", 10.0), ("v", 10.0), ("a", 50.0), ("jerk", 100.0), ("snap", 500.0)):
        assert np.max(np.abs(getattr(right, name) - getattr(left, name))) < 2 * h * bound, name
    # the sample at a knot is the solved knot state
    np.testing.assert_allclose(np.stack([at.p, at.v, at.a, at.jerk], axis=1),
                               traj.knot_states[1:-1], atol=1e-9)


# --------------------------------------------------------------------- (6) decoupling


def test_axes_solved_together_equal_axes_solved_separately():
    times, pos, vel, acc, x0 = _small_case()
    cfg = TrajectoryConfig(q_velocity=0.2, q_jerk=0.4)
    together = generate_trajectory(times, pos, vel, acc, config=cfg, initial_state=x0)
    t = np.linspace(0.0, 4.0, 41)
    smp = together.sample(t)
    for axis in range(3):
        keep = np.zeros(3)
        keep[axis] = 1.0
        alone = generate_trajectory(times, pos * keep, vel * keep, acc * keep, config=cfg,
                                    initial_state=x0 * keep).sample(t)
        for name in ("p", "v", "a", "jerk", "snap"):
            np.testing.assert_allclose(getattr(alone, name)[:, axis], getattr(smp, name)[:, axis],
                                       atol=1e-10)
            others = [k for k in range(3) if k != axis]
            assert np.all(getattr(alone, name)[:, others] == 0.0)


def test_isotropic_weights_make_the_solution_rotation_equivariant():
    times, pos, vel, _ = _boustrophedon(n_rows=2, row_length_m=12.0)
    c, s = math.cos(0.7), math.sin(0.7)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    t = np.linspace(times[0], times[-1], 57)
    a = generate_trajectory(times, pos, vel).sample(t)
    b = generate_trajectory(times, pos @ Rz.T, vel @ Rz.T).sample(t)
    np.testing.assert_allclose(b.p, a.p @ Rz.T, atol=1e-9)
    np.testing.assert_allclose(b.a, a.a @ Rz.T, atol=1e-9)


# -------------------------------------------------------------------- default quality


def test_default_weights_meet_the_vineyard_requirements():
    """Residual <= 5 cm (issue 2) and no excursion toward the vine rows.

    The rows are 2.5 m apart, so the vines are 1.25 m from the corridor
    centre line; 0.15 m lateral deviation leaves > 0.6 m to a 0.5 m margin.
    """
    times, pos, vel, corner = _boustrophedon()
    traj = generate_trajectory(times, pos, vel)
    assert traj.waypoint_residual_m.max() <= 0.05
    t = np.arange(times[0], times[-1], 0.01)
    smp = traj.sample(t)
    seg = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
    in_run = pos[seg, 1] == pos[seg + 1, 1]
    assert np.max(np.abs(smp.p[in_run, 1] - pos[seg[in_run], 1])) < 0.15
    np.testing.assert_allclose(smp.p[:, 2], 1.5, atol=1e-9)   # flat field: z never moves


# ------------------------------------------------------------------------- sampling API


def test_sampling_api_scalar_unsorted_clamped_and_large():
    times, pos, vel, _ = _boustrophedon(n_rows=2, row_length_m=12.0)
    traj = generate_trajectory(times, pos, vel)
    one = traj.sample(3.3)
    assert one.p.shape == (3,) and isinstance(one.t, float) and one.pointing is None
    rng = np.random.default_rng(1)
    t = rng.uniform(times[0] - 5, times[-1] + 5, size=9000)     # > gather threshold, unsorted
    big = traj.sample(t)
    for i in rng.integers(0, t.size, size=20):
        ref = traj.sample(float(t[i]))
        np.testing.assert_allclose(big.p[i], ref.p, atol=1e-12)
        np.testing.assert_allclose(big.snap[i], ref.snap, atol=1e-9)
    before = traj.sample(times[0] - 1.0)
    np.testing.assert_allclose(before.p, traj.sample(times[0]).p)
    after = traj.sample(times[-1] + 1.0)
    np.testing.assert_allclose(after.v, traj.sample(times[-1]).v)


def test_bad_waypoints_are_plan_errors():
    with pytest.raises(PlanError):
        generate_trajectory([0.0], np.zeros((1, 3)))
    with pytest.raises(PlanError, match="increase"):
        generate_trajectory([0.0, 1.0, 1.0], np.zeros((3, 3)))
    with pytest.raises(PlanError):
        generate_trajectory([0.0, 1.0], [[0.0, 0.0, np.nan], [1.0, 0.0, 0.0]])
    with pytest.raises(ValueError):
        TrajectoryConfig(r_snap=0.0)
    with pytest.raises(ValueError):
        TrajectoryConfig(s_position=-1.0)


# ----------------------------------------------------------------------------- pointing


def test_pointing_derivatives_match_finite_differences():
    times, pos, vel, _ = _boustrophedon(n_rows=2, row_length_m=12.0)
    target = np.array([6.0, 1.25, 0.0])
    traj = generate_trajectory(times, pos, vel, target_enu_m=target)
    t = np.linspace(times[0] + 0.5, times[-1] - 0.5, 31)
    h = 1e-4
    smp, plus, minus = traj.sample(t), traj.sample(t + h), traj.sample(t - h)
    np.testing.assert_allclose(np.linalg.norm(smp.pointing, axis=1), 1.0, atol=1e-12)
    offset = target - smp.p
    np.testing.assert_allclose(smp.pointing, offset / np.linalg.norm(offset, axis=1)[:, None])
    np.testing.assert_allclose(smp.pointing_dot, (plus.pointing - minus.pointing) / (2 * h), atol=1e-6)
    np.testing.assert_allclose(smp.pointing_ddot,
                               (plus.pointing - 2 * smp.pointing + minus.pointing) / h**2, atol=2e-4)
    # s is a unit vector: s . s' = 0 and s . s'' = -|s'|^2
    np.testing.assert_allclose(np.sum(smp.pointing * smp.pointing_dot, axis=1), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(smp.pointing * smp.pointing_ddot, axis=1),
                               -np.sum(smp.pointing_dot**2, axis=1), atol=1e-12)
    s, s_dot, s_ddot = pointing_derivatives(smp.p, smp.v, smp.a, target)
    np.testing.assert_array_equal(s, pointing_directions(smp.p, target))


def test_pointing_direction_hand_values_and_degenerate_target():
    p = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]])
    s = pointing_directions(p, np.array([3.0, 4.0, 12.0]))
    np.testing.assert_allclose(s, [[3 / 13, 4 / 13, 12 / 13], [0.0, 0.0, 1.0]])
    # moving straight away from the target at 1 m/s: s is constant
    d = pointing_derivatives(np.array([[0.0, 0.0, 0.0]]), np.array([[-1.0, 0.0, 0.0]]),
                             np.zeros((1, 3)), np.array([5.0, 0.0, 0.0]))
    np.testing.assert_allclose(d.s_dot, 0.0, atol=1e-15)
    # passing a target 2 m abeam at speed 1: |s'| = v / r = 0.5 rad/s
    d = pointing_derivatives(np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0]]), np.zeros((1, 3)),
                             np.array([0.0, 2.0, 0.0]))
    np.testing.assert_allclose(np.linalg.norm(d.s_dot), 0.5)
    with pytest.raises(PlanError):
        pointing_directions(p, p[1])
