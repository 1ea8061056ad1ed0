"""The optimal trajectory as exact piecewise polynomials, and its sampling.

``Trajectory`` is built by ``generate_trajectory`` (lqr.py). On knot interval
m (length dt_m) and s = (t - t_m) / dt_m in [0, 1], the k-th time
derivative of p is sum_j coefficients[m, j, k, axis] s^j (k = 0..4: p, v,
a, jerk, snap). With Q = 0 these are the exact degree-7 optimal pieces.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mavcore.mission.trajectory import TrajectoryConfig
from .pointing import pointing_derivatives

#: Below this many samples per non-empty interval a gather is cheaper than
#: the per-interval matrix products.
_GATHER_MAX_SAMPLES = 4096


def derivative_coefficients(position_coefficients: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
    """Coefficients of p and its first four time derivatives from those of p.

    Parameters
    ----------
    position_coefficients : (M, deg + 1, d) array
        On piece m, p(s) = sum_j c[m, j] s^j with s = (t - t_m) / dt_m.
    dt_s : (M,) array
        Piece lengths dt_m [s].

    Returns
    -------
    (M, deg + 1, 5, d) array
        Entry [m, j, k] is the coefficient of s^j in d^k p / dt^k (k = 0..4),
        d^k/dt^k sum_j c_j s^j = dt^-k sum_j c_{j+k} (j+k)!/j! s^j. The same
        arithmetic as the solver's, so a trajectory rebuilt from its position
        coefficients (plan.json) has bit-identical pieces.
    """
    c = np.asarray(position_coefficients, dtype=float)
    dt = np.asarray(dt_s, dtype=float)
    M, deg1, d = c.shape
    coeffs = np.zeros((M, deg1, 5, d))
    for k in range(5):
        if k >= deg1:
            break
        falling = np.array([math.perm(j + k, k) for j in range(deg1 - k)], dtype=float)
        coeffs[:, : deg1 - k, k, :] = c[:, k:, :] * falling[None, :, None] / (dt**k)[:, None, None]
    return coeffs


#: Two-point Hermite interpolation of degree 7 (``hermite_position_coefficients``):
#: row k, column j - 4 is j!/(j-k)!, the factor of c_j in d^k p/ds^k at s = 1 (j = 4..7).
_HERMITE_HIGH = np.array([[math.perm(j, k) for j in range(4, 8)] for k in range(4)], dtype=float)
_HERMITE_LOW = np.array([[math.perm(j, k) for j in range(4)] for k in range(4)], dtype=float)
_HERMITE_HIGH_INV = np.linalg.inv(_HERMITE_HIGH)
_FACTORIALS = np.array([1.0, 1.0, 2.0, 6.0])


def hermite_position_coefficients(knot_times_s: np.ndarray, knot_states: np.ndarray) -> np.ndarray:
    """Degree-7 position coefficients of the pieces fixed by the states at their ends.

    With Q = 0 the optimal position is a degree-7 polynomial on every knot
    interval (lqr.py) and the state x = [p, v, a, jerk] is continuous, so the
    knot states fix every piece: the one degree-7 polynomial with the given
    p, v, a and jerk at both ends (two-point Hermite interpolation). In
    s = (t - t_m) / dt_m: c_k = x_k(t_m) dt^k / k! for k <= 3, and c_4..c_7
    solve sum_j c_j j!/(j-k)! = x_k(t_m+1) dt^k, k = 0..3.

    Parameters
    ----------
    knot_times_s : (M + 1,) array
    knot_states : (M + 1, 4, d) array
        [p, v, a, jerk] at the knots (SI).

    Returns
    -------
    (M, 8, d) array
        As ``Trajectory.position_coefficients``; equal to the solver's up to
        rounding (1e-11 m in position over a 10 ha field, BENCHMARKS.md).
    """
    knots = np.asarray(knot_times_s, dtype=float)
    x = np.asarray(knot_states, dtype=float)
    pw = np.diff(knots)[:, None] ** np.arange(4)                  # dt^k, (M, 4)
    low = x[:-1] * (pw / _FACTORIALS)[:, :, None]                 # c_0..c_3
    rhs = x[1:] * pw[:, :, None] - np.einsum("kj,mjd->mkd", _HERMITE_LOW, low)
    high = np.einsum("jk,mkd->mjd", _HERMITE_HIGH_INV, rhs)      # c_4..c_7
    return np.concatenate([low, high], axis=1)


@dataclass(frozen=True, eq=False)
class TrajectorySample:
    """Reference trajectory sampled at times ``t`` (ENU, SI).

    For an array of n times every field is (n, 3) (``t`` is (n,)); for a
    scalar time, (3,) (``t`` a float).

    Attributes
    ----------
    t : array or float
        Sample times [s] as requested (before clamping to [t0, tf]).
    p, v, a, jerk, snap : arrays
        Position [m], velocity [m/s], acceleration [m/s^2], jerk [m/s^3] and
        snap [m/s^4] (the LQR input u).
    pointing, pointing_dot, pointing_ddot : arrays or None
        Unit pointing vector s(t) toward S_p (eq. 21) and its first and
        second time derivatives [1/s, 1/s^2]; None when the trajectory has no
        pointing target.
    """

    t: np.ndarray | float
    p: np.ndarray
    v: np.ndarray
    a: np.ndarray
    jerk: np.ndarray
    snap: np.ndarray
    pointing: np.ndarray | None = None
    pointing_dot: np.ndarray | None = None
    pointing_ddot: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Optimal LQR trajectory of Section 2.3.2 (three ENU axes).

    Attributes
    ----------
    knot_times_s : (M + 1,) array
        Knot times [s]: the way-point times, plus unweighted sub-knots on
        long intervals when Q != 0.
    knot_states : (M + 1, 4, 3) array
        Optimal x = [p, v, a, jerk] at the knots, per ENU axis (SI).
    waypoint_knots : (N,) int array
        Index of each way-point's knot.
    waypoint_targets : (N, 3, 3) array
        The requested y_i = [p, v, a] per way-point and axis.
    coefficients : (M, deg + 1, 5, 3) array
        Piece polynomials in s (see module docstring).
    config : TrajectoryConfig
        The weights used.
    target_enu_m : (3,) array or None
        Pointing target S_p (eq. 21), ENU metres.
    """

    knot_times_s: np.ndarray
    knot_states: np.ndarray
    waypoint_knots: np.ndarray
    waypoint_targets: np.ndarray
    coefficients: np.ndarray
    config: TrajectoryConfig
    target_enu_m: np.ndarray | None = None

    @classmethod
    def from_pieces(cls, knot_times_s: np.ndarray, position_coefficients: np.ndarray,
                    waypoint_knots: np.ndarray, waypoint_targets: np.ndarray, config: TrajectoryConfig,
                    target_enu_m: np.ndarray | None = None,
                    knot_states: np.ndarray | None = None) -> "Trajectory":
        """The trajectory from its pieces as stored in plan.json (docs/plan-json.md).

        Parameters
        ----------
        knot_times_s : (M + 1,) array
            Knot times [s], strictly increasing.
        position_coefficients : (M, deg + 1, 3) array
            ``coefficients[:, :, 0, :]`` of the solved trajectory (ENU m).
        waypoint_knots, waypoint_targets, config, target_enu_m
            As the attributes.
        knot_states : (M + 1, 4, 3) array, optional
            Default: the pieces evaluated at the knots (the solver's own knot
            states differ from them in the last bits only).

        Returns
        -------
        Trajectory
            Pieces bit-identical to those of the trajectory the coefficients
            came from (``derivative_coefficients``).
        """
        knots = np.asarray(knot_times_s, dtype=float)
        coeffs = derivative_coefficients(position_coefficients, np.diff(knots))
        if knot_states is not None:
            states = np.asarray(knot_states, dtype=float)
        else:
            states = np.empty((knots.shape[0], 4, coeffs.shape[3]))
            states[:-1] = coeffs[:, 0, :4, :]                # s = 0: the constant terms
            states[-1] = coeffs[-1, :, :4, :].sum(axis=0)    # s = 1 on the last piece
        return cls(knot_times_s=knots, knot_states=states,
                   waypoint_knots=np.asarray(waypoint_knots, dtype=np.intp),
                   waypoint_targets=np.asarray(waypoint_targets, dtype=float),
                   coefficients=coeffs, config=config,
                   target_enu_m=None if target_enu_m is None else np.asarray(target_enu_m, dtype=float).reshape(3))

    @property
    def position_coefficients(self) -> np.ndarray:
        """(M, deg + 1, 3) coefficients of p on each piece (what plan.json stores)."""
        return self.coefficients[:, :, 0, :]

    @property
    def t0(self) -> float:
        """Start time [s]."""
        return float(self.knot_times_s[0])

    @property
    def tf(self) -> float:
        """End time [s]."""
        return float(self.knot_times_s[-1])

    @property
    def duration_s(self) -> float:
        """tf - t0 [s]."""
        return self.tf - self.t0

    @property
    def waypoint_times_s(self) -> np.ndarray:
        """(N,) way-point times [s]."""
        return self.knot_times_s[self.waypoint_knots]

    @property
    def waypoint_states(self) -> np.ndarray:
        """(N, 4, 3) optimal [p, v, a, jerk] at the way-points."""
        return self.knot_states[self.waypoint_knots]

    @property
    def waypoint_residual_m(self) -> np.ndarray:
        """(N,) distance between the trajectory and each way-point's position [m]."""
        diff = self.waypoint_states[:, 0, :] - self.waypoint_targets[:, 0, :]
        return np.sqrt(np.einsum("ni,ni->n", diff, diff))

    def sample(self, t: np.ndarray | float) -> TrajectorySample:
        """Evaluate the trajectory at arbitrary times (exact, vectorised).

        Parameters
        ----------
        t : float or (n,) array
            Times [s], any order. Times outside [t0, tf] are clamped: the
            sample is the state at t0 (resp. tf), i.e. the trajectory does
            not extrapolate.

        Returns
        -------
        TrajectorySample
            p, v, a, jerk, snap (and pointing when ``target_enu_m`` is set).
        """
        t_arr = np.asarray(t, dtype=float)
        scalar = t_arr.ndim == 0
        times = np.clip(t_arr.reshape(-1), self.t0, self.tf)
        values = self._evaluate(times)                       # (n, 5, 3)
        p, v, a, jerk, snap = (values[:, k, :] for k in range(5))
        pointing = pointing_dot = pointing_ddot = None
        if self.target_enu_m is not None:
            pointing, pointing_dot, pointing_ddot = pointing_derivatives(p, v, a, self.target_enu_m)
        if scalar:
            def one(x):
                return None if x is None else x[0]
            return TrajectorySample(float(t_arr), p[0], v[0], a[0], jerk[0], snap[0],
                                    one(pointing), one(pointing_dot), one(pointing_ddot))
        return TrajectorySample(t_arr.reshape(-1), p, v, a, jerk, snap,
                                pointing, pointing_dot, pointing_ddot)

    def derivatives(self, t: np.ndarray) -> np.ndarray:
        """(n, 5, 3) p, v, a, jerk, snap (ENU m, m/s, ...) at times ``t`` (s, (n,), clamped to
        [t0, tf] as by :meth:`sample`): ``sample``'s values bit for bit, without the pointing
        directions (``pointing_derivatives``, as costly as the rest), for callers that need
        only positions or velocities."""
        return self._evaluate(np.clip(np.asarray(t, dtype=float).reshape(-1), self.t0, self.tf))

    def _evaluate(self, times: np.ndarray) -> np.ndarray:
        """(n, 5, 3) derivatives 0..4 of p at clamped ``times``."""
        knots = self.knot_times_s
        M = knots.shape[0] - 1
        deg1 = self.coefficients.shape[1]
        C = self.coefficients.reshape(M, deg1, 15)
        n = times.shape[0]
        order = None
        if n > 1 and np.any(times[1:] < times[:-1]):
            order = np.argsort(times, kind="stable")
            times = times[order]
        idx = np.clip(np.searchsorted(knots, times, side="right") - 1, 0, M - 1)
        tau = (times - knots[idx]) / (knots[idx + 1] - knots[idx])
        # powers of tau, (deg+1, n): rows contiguous for the products below
        powers = np.empty((deg1, n))
        powers[0] = 1.0
        for j in range(1, deg1):
            np.multiply(powers[j - 1], tau, out=powers[j])
        out = np.empty((n, 15))
        if n <= _GATHER_MAX_SAMPLES:
            out[:] = np.einsum("jn,njc->nc", powers, C[idx])
        else:
            # times are sorted, so each interval's samples are one slice:
            # one small matrix product per interval, no gather of coefficients
            bounds = np.searchsorted(idx, np.arange(M + 1), side="left")
            for m in np.flatnonzero(bounds[1:] > bounds[:-1]):
                lo, hi = bounds[m], bounds[m + 1]
                np.matmul(powers[:, lo:hi].T, C[m], out=out[lo:hi])
        if order is not None:
            unsorted = np.empty_like(out)
            unsorted[order] = out
            out = unsorted
        return out.reshape(n, 5, 3)
