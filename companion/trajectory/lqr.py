"""Exact LQR trajectory through way-points (Section 2.3.2, eqs. 1-13).

Problem (per axis; the three ENU axes share the diagonal weights S, Q, R and
so decouple, and are solved together as three right-hand sides)::

    x = [p, v, a, j]           (eq. 1)  chain of four integrators
    dx/dt = A x + B u          (eq. 5)  A = 4x4 shift, B = e4, u = snap
    y = C x = [p, v, a]        (eq. 2)
    J = sum_{i=1..N} (C x(t_i) - y_i)^T S (C x(t_i) - y_i)
        + int_{t_0}^{t_N} 1/2 (x^T Q x + R u^2) dt              (eq. 4)

Optimality (the convention used throughout: the way-point term has no 1/2,
the running cost has 1/2, H = 1/2 x^T Q x + 1/2 R u^2 + lambda^T (A x + B u),
eq. 6)::

    dx/dt = A x - B R^-1 B^T lambda,  dlambda/dt = -Q x - A^T lambda,
    u = -R^-1 B^T lambda                                        (eq. 7)
    lambda(t_i-) = lambda(t_i+) + 2 C^T S (C x(t_i) - y_i),  lambda(t_N+) = 0

With lambda = P x + eta this is the paper's sweep (eqs. 8-11) with
P(t_N) = 2 C^T S C, eta(t_N) = -2 C^T S y_N, P(t_i-) = P(t_i+) + 2 C^T S C,
eta(t_i-) = eta(t_i+) - 2 C^T S y_i (eqs. 12-13 as printed lost the factor 2
and the sign of the y_i term), -dP/dt = P A + A^T P + Q - P B R^-1 B^T P and
-deta/dt = (A - B R^-1 B^T P)^T eta (eq. 10 as printed has A^T for A).

Method: exact, O(N), one banded LU solve
----------------------------------------
The optimality conditions above are a linear multi-point boundary value
problem for z = [x; lambda]. On each knot interval the exact solution is
z(t_b-) = exp(H dt) z(t_a+) with the 8x8 Hamiltonian matrix H of eq. (7).
Writing these transitions, the costate jumps at the way-points, x(t_0) and
lambda(t_N+) = 0 as one linear system in the unknowns [x_i; lambda(t_i+)]
at all knots gives a banded matrix (bandwidths 7 and 4 for Q = 0), solved
by LAPACK's banded LU with partial pivoting (scipy.linalg.solve_banded) with
the three axes as three right-hand sides. This multiple-shooting form is
well conditioned whenever every interval's transition matrix is of order 1,
which is ensured by

- working in normalised units: time in tau = a typical interval (the
  median), state xi = diag(1, tau, tau^2, tau^3) x, cost divided by
  R / tau^7; with Q = 0 the normalised problem has no parameter left but S;
- splitting long intervals at unweighted sub-knots (normalised length <= 2,
  or <= 1 / max(1, sigma) with sigma the normalised rate of Q != 0).

Two alternatives were tried and rejected: sweeping the Riccati equation
through exp(H dt) amplifies rounding like exp(sigma dt) (Q != 0) or dt^7
(long intervals) after each jump of 2 S; eliminating the costate to get a
symmetric positive definite block-tridiagonal system in the knot states
(banded Cholesky) has condition number ~ (T/dt)^7 when a short interval dt
sits between intervals T (a 10 ms remainder between 4 s intervals gave 0.3 m
errors). Short intervals are harmless here: exp(H dt) ~ I.

With Q = 0, H is nilpotent (H^8 = 0): exp(H dt) is the exact degree-7
polynomial in H dt, the optimal snap is a cubic and p a degree-7 polynomial
on every interval; no matrix exponential is needed at all. With Q != 0 the
transitions come from scipy.linalg.expm, one batched call per distinct
interval length. Inside an interval the position is the Taylor series of
exp(H s) z(t_a+) in s: exact at degree 7 for Q = 0, truncated at degree 27
otherwise (normalised |H s| <= 2, so the remainder is below 1e-20 relative).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm, solve_banded

from mavcore.errors import PlanError
from mavcore.mission.trajectory import TrajectoryConfig
from .sampling import Trajectory, derivative_coefficients

#: Taylor degree of the in-interval polynomials when Q != 0 (see module doc).
TAYLOR_DEGREE_Q = 27
#: Longest normalised (sub-)interval: Q = 0, Q != 0.
MAX_STEP_Q0 = 2.0
MAX_STEP_Q = 1.0

_A = np.diag(np.ones(3), 1)          # 4x4 shift: d/dt [p, v, a, j] = [v, a, j, u]
_EXPONENTS = np.array([8.0, 6.0, 4.0, 2.0])   # q_k tau^(8-2k) / R is dimensionless
_SOURCE = "trajectory"
_U = 4                                # upper bandwidth of the shooting system


def _hamiltonian(q_norm: np.ndarray) -> np.ndarray:
    """Normalised Hamiltonian matrix of eq. (7), (8, 8), acting on [xi; mu].

    H = [[A, -B B^T], [-diag(q_norm), -A^T]] (unit time, R = 1).
    """
    H = np.zeros((8, 8))
    H[:4, :4] = _A
    H[3, 7] = -1.0
    H[4:, :4] = -np.diag(q_norm)
    H[4:, 4:] = -_A.T
    return H


def _split(times: np.ndarray, max_step: float) -> tuple[np.ndarray, np.ndarray]:
    """Knot times (way-points plus unweighted sub-knots) and the way-point knot indices."""
    dt = np.diff(times)
    splits = np.maximum(1, np.ceil(dt / max_step - 1e-9)).astype(int)
    wp_knots = np.concatenate([[0], np.cumsum(splits)])
    if np.all(splits == 1):
        return times, wp_knots
    offsets = np.concatenate([np.arange(n) / n for n in splits])
    knots = np.append(np.repeat(times[:-1], splits) + offsets * np.repeat(dt, splits), times[-1])
    return knots, wp_knots


def _transitions(H: np.ndarray, h: np.ndarray, nilpotent: bool) -> np.ndarray:
    """exp(H h) for every normalised interval length h, (M, 8, 8)."""
    if nilpotent:
        # H^8 = 0: the exponential series ends at degree 7 (exact)
        powers = np.empty((8, 8, 8))
        powers[0] = np.eye(8)
        for k in range(1, 8):
            powers[k] = powers[k - 1] @ H / k
        return np.tensordot(h[:, None] ** np.arange(8)[None, :], powers, axes=1)
    unique, inverse = np.unique(h, return_inverse=True)
    return expm(unique[:, None, None] * H[None])[inverse.reshape(-1)]


def generate_trajectory(
    times_s: np.ndarray,
    pos_enu_m: np.ndarray,
    vel_enu_m_s: np.ndarray | None = None,
    acc_enu_m_s2: np.ndarray | None = None,
    config: TrajectoryConfig | None = None,
    initial_state: np.ndarray | None = None,
    target_enu_m: np.ndarray | None = None,
) -> Trajectory:
    """Solve the paper's LQR trajectory problem exactly (eqs. 1-13).

    Parameters
    ----------
    times_s : (N,) array
        Way-point times t_0 < t_1 < ... < t_{N-1} [s]; t_0 starts the
        trajectory. N >= 2.
    pos_enu_m : (N, 3) array
        Desired positions b_i (ENU, m).
    vel_enu_m_s : (N, 3) array, optional
        Desired velocities v_i (ENU, m/s): 0 at corners, the cruise velocity
        along runs. Default zeros.
    acc_enu_m_s2 : (N, 3) array, optional
        Desired accelerations a_i (ENU, m/s^2). Default zeros (the paper).
    config : TrajectoryConfig, optional
        Weights S, Q, R. Default ``TrajectoryConfig()``.
    initial_state : (4, 3) array, optional
        x(t_0) = [p, v, a, jerk] per ENU axis (rows p, v, a, jerk; SI).
        Default: at rest at the first way-point, [b_0, 0, 0, 0] (the vehicle
        starts hovering). x(t_0) is fixed, so the first way-point's S term is
        a constant and does not enter the optimisation.
    target_enu_m : (3,) array, optional
        Pointing target S_p of eq. (21); when set, samples carry s(t).

    Returns
    -------
    Trajectory
        The optimal trajectory: knot states and exact piecewise polynomials.

    Raises
    ------
    PlanError
        Fewer than two way-points, non-finite values, or times not strictly
        increasing.
    """
    cfg = config if config is not None else TrajectoryConfig()
    times = np.asarray(times_s, dtype=float).reshape(-1)
    N = times.shape[0]
    if N < 2:
        raise PlanError(_SOURCE, f"need at least 2 way-points, got {N}")

    def _arr(value, name: str) -> np.ndarray:
        if value is None:
            return np.zeros((N, 3))
        out = np.asarray(value, dtype=float)
        if out.shape != (N, 3):
            raise ValueError(f"{name} must have shape ({N}, 3), got {out.shape}")
        if not np.all(np.isfinite(out)):
            raise PlanError(_SOURCE, f"{name} has non-finite values")
        return out

    pos = _arr(pos_enu_m, "pos_enu_m")
    vel = _arr(vel_enu_m_s, "vel_enu_m_s")
    acc = _arr(acc_enu_m_s2, "acc_enu_m_s2")
    if not np.all(np.isfinite(times)):
        raise PlanError(_SOURCE, "way-point times are not finite")
    dt_wp = np.diff(times)
    if np.any(dt_wp <= 0.0):
        i = int(np.flatnonzero(dt_wp <= 0.0)[0])
        raise PlanError(_SOURCE, f"way-point times must increase strictly (way-point {i + 1}: "
                                 f"{times[i + 1]} s after {times[i]} s)")
    if initial_state is None:
        x0 = np.zeros((4, 3))
        x0[0] = pos[0]
    else:
        x0 = np.asarray(initial_state, dtype=float)
        if x0.shape != (4, 3) or not np.all(np.isfinite(x0)):
            raise ValueError(f"initial_state must be a finite (4, 3) array, got shape {x0.shape}")

    targets = np.stack([pos, vel, acc], axis=1)
    solution = solve_knots(times, targets, x0, cfg)
    return Trajectory(
        knot_times_s=solution.knot_times_s,
        knot_states=solution.states,
        waypoint_knots=solution.waypoint_knots,
        waypoint_targets=targets,
        coefficients=solution.coefficients,
        config=cfg,
        target_enu_m=None if target_enu_m is None else np.asarray(target_enu_m, dtype=float).reshape(3),
    )


class KnotSolution:
    """Result of ``solve_knots`` (internal): see its Returns section."""

    __slots__ = ("knot_times_s", "waypoint_knots", "states", "costates", "coefficients")

    def __init__(self, knot_times_s, waypoint_knots, states, costates, coefficients) -> None:
        self.knot_times_s = knot_times_s
        self.waypoint_knots = waypoint_knots
        self.states = states
        self.costates = costates
        self.coefficients = coefficients


def solve_knots(times: np.ndarray, targets: np.ndarray, x0: np.ndarray,
                cfg: TrajectoryConfig) -> KnotSolution:
    """Optimal knot states and per-interval polynomials (the core solver).

    Parameters
    ----------
    times : (N,) array
        Strictly increasing way-point times [s].
    targets : (N, 3, d) array
        y_i = [p, v, a] per way-point for d independent axes.
    x0 : (4, d) array
        Fixed initial state [p, v, a, jerk] at times[0].
    cfg : TrajectoryConfig
        Weights.

    Returns
    -------
    KnotSolution
        ``knot_times_s`` (M + 1,) including any sub-knots;
        ``waypoint_knots`` (N,) knot index of each way-point;
        ``states`` (M + 1, 4, d) optimal x = [p, v, a, jerk] at the knots;
        ``costates`` (M + 1, 4, d) lambda(t_i+) of eq. (7) (physical units);
        ``coefficients`` (M, deg + 1, 5, d): on interval m with
        s = (t - t_m) / dt_m in [0, 1], derivative k (0..4: p, v, a, jerk,
        snap) of p is sum_j coefficients[m, j, k] s^j.
    """
    d = targets.shape[2]
    q = np.asarray(cfg.q_diag, dtype=float)
    s_w = np.asarray(cfg.s_diag, dtype=float)
    r = cfg.r_snap
    sigma = float(np.max((q / r) ** (1.0 / _EXPONENTS)))        # 1/s, 0 when Q = 0
    tau = float(np.median(np.diff(times)))
    if sigma > 0.0:
        tau = min(tau, 1.0 / sigma)                              # normalised rates <= 1
    scale = tau ** np.arange(4)                                  # xi = scale * x
    q_norm = q * tau**_EXPONENTS / r
    s_norm = s_w * tau ** (7.0 - 2.0 * np.arange(3)) / r         # S' = S tau^(7-2k) / R
    nilpotent = sigma == 0.0

    knot_times, wp_knots = _split(times, (MAX_STEP_Q0 if nilpotent else MAX_STEP_Q) * tau)
    M = knot_times.shape[0] - 1
    h = np.diff(knot_times) / tau
    H = _hamiltonian(q_norm)
    Phi = _transitions(H, h, nilpotent)                          # (M, 8, 8)

    # With q_position = 0 the problem is translation invariant: solve relative
    # to the first way-point (fewer rounding errors far from the ENU origin).
    shift = targets[0, 0].copy() if q[0] == 0.0 else np.zeros(d)
    y = targets.copy()
    y[:, 0] -= shift
    xi0 = x0 * scale[:, None]
    xi0[0] -= shift
    y_norm = y * scale[None, :3, None]

    # Banded system, unknowns z_i = [xi_i; mu_i+] (8 per knot), rows:
    #   xi_0 = xi0                                                   (4)
    #   xi_{i+1} - Phi11 xi_i - Phi12 mu_i = 0                       (4 per interval)
    #   mu_{i+1} + G_{i+1} xi_{i+1} - Phi21 xi_i - Phi22 mu_i = g     (4 per interval)
    #   mu_M = 0                                                     (4)
    # with G = 2 C'S'C, g = 2 C'S' y at way-point knots (0 at sub-knots).
    # Storage: ab[u + row - col, col]; row of interval i, line k: 4 + 8 i + k.
    # Row 4 + 8 i + k minus column 8 i + c is 4 + k - c, so the lower
    # bandwidth is 11, or 7 when Phi21 = 0 (Q = 0); the upper one is 4.
    n = 8 * (M + 1)
    lower = 7 if nilpotent else 11
    ab = np.zeros((lower + _U + 1, M + 1, 8))
    k_idx, c_idx = np.divmod(np.arange(64), 8)
    band = 4 + k_idx - c_idx <= lower
    ab[(_U + 4 + k_idx - c_idx)[band][None, :], np.arange(M)[:, None], c_idx[band][None, :]] = \
        -Phi.reshape(M, 64)[:, band]
    ab[_U - 4, 1:, :] = 1.0                                      # identity on z_{i+1}
    G = np.zeros((M + 1, 4))
    G[wp_knots[1:], :3] = 2.0 * s_norm
    ab[_U, 1:, :4] = G[1:]                                       # G on xi_{i+1} (diagonal)
    ab[_U, 0, :4] = 1.0                                          # xi_0 = xi0
    ab[_U, M, 4:] = 1.0                                          # mu_M = 0
    # Solve for the deviation z - z_ref from a reference z_ref = [xi_ref; 0]
    # that meets the weighted targets (xi_ref = [y_i; 0] at way-points, linear
    # in time in between, xi0 at t_0). Same matrix, smaller unknowns: a jump
    # row reads mu(t_i-) - mu(t_i+) = G xi_i - g_i, and for large S solving
    # it in absolute terms would cancel G xi_i against g_i (error ~ eps G |y|).
    n_wp = targets.shape[0]
    xi_ref_wp = np.zeros((n_wp, 4, d))
    xi_ref_wp[:, :3] = y_norm
    xi_ref_wp[0] = xi0
    xi_ref = np.empty((M + 1, 4, d))
    seg = np.clip(np.searchsorted(wp_knots, np.arange(M + 1), side="right") - 1, 0, n_wp - 2)
    t_wp = knot_times[wp_knots]
    frac = ((knot_times - t_wp[seg]) / (t_wp[seg + 1] - t_wp[seg]))[:, None, None]
    xi_ref[:] = (1.0 - frac) * xi_ref_wp[seg] + frac * xi_ref_wp[seg + 1]
    rhs = np.zeros((M + 1, 8, d))
    # xi-rows of interval i are block i, lines 4..7; mu-rows are block i+1, lines 0..3
    rhs[:-1, 4:] = Phi[:, :4, :4] @ xi_ref[:-1] - xi_ref[1:]
    rhs[1:, :4] = Phi[:, 4:, :4] @ xi_ref[:-1]
    z = solve_banded((lower, _U), ab.reshape(lower + _U + 1, n), rhs.reshape(n, d),
                     check_finite=False).reshape(M + 1, 8, d)
    z[:, :4] += xi_ref                                           # z = z_ref + (z - z_ref)

    # in-interval polynomials: p(s) = sum_k (e1' H^k z_a) (h s)^k / k!
    degree = 7 if nilpotent else TAYLOR_DEGREE_Q
    rows = np.empty((degree + 1, 8))
    row = np.zeros(8)
    row[0] = 1.0
    for k in range(degree + 1):
        rows[k] = row / math.factorial(k)
        row = row @ H
    c = np.einsum("kj,mjd->mkd", rows, z[:-1]) * (h[:, None] ** np.arange(degree + 1))[:, :, None]
    c[:, 0] += shift
    coeffs = derivative_coefficients(c, np.diff(knot_times))

    states = z[:, :4] / scale[None, :, None]
    states[:, 0] += shift
    costates = z[:, 4:] * (r / tau**7) * scale[None, :, None]   # lambda = (R/tau^7) D mu
    return KnotSolution(knot_times, wp_knots, states, costates, coeffs)
