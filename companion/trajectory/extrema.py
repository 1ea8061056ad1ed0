"""Exact largest speed of a trajectory between given times.

Pure. A piece m of ``companion.trajectory.Trajectory`` has velocity
v(s) = sum_j V[j] s^j on s = (t - t_m) / (t_{m+1} - t_m) in [0, 1]
(``coefficients[m, :, 1, :]``, ENU m/s), so its squared speed
q(s) = |v(s)|^2 is a polynomial of degree 2 deg (the auto-correlation of the
coefficients). On any interval [s_a, s_b] inside one piece the largest of q
is at s_a, at s_b or at a zero of q'(s) between them: evaluating the speed at
those points gives the exact maximum. The zeros are the eigenvalues of q's
companion matrix (``numpy.polynomial.polynomial.polyroots``); a zero found
with error delta changes the value by O(delta^2) (q' = 0 there), and
near-real ones are evaluated too (a real point of the interval never
over-states the maximum).
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial import polynomial as P

#: Imaginary part (relative to 1 in s) under which a zero of q' counts as real.
_REAL_TOL = 1e-6


def _squared_speed_derivative(V: np.ndarray) -> np.ndarray:
    """(2 deg,) coefficients in s of d|v|^2/ds for one piece's (deg + 1, 3) velocity coefficients."""
    # np.convolve keeps every length at 2 deg + 1 (P.polymul trims trailing zeros)
    q = sum(np.convolve(V[:, axis], V[:, axis]) for axis in range(V.shape[1]))
    return P.polyder(q)


def stationary_times(trajectory) -> np.ndarray:
    """Times (s) inside the pieces where |v|^2 is stationary (zeros of its derivative), sorted."""
    knots = np.asarray(trajectory.knot_times_s, dtype=float)
    V = np.asarray(trajectory.coefficients, dtype=float)[:, :, 1, :]      # (M, deg + 1, 3)
    out = []
    for m in range(V.shape[0]):
        dq = np.trim_zeros(_squared_speed_derivative(V[m]), "b")
        if dq.size < 2 or not np.any(dq):
            continue   # constant speed on the piece: its ends hold the maximum
        r = P.polyroots(dq)
        s = r.real[(np.abs(r.imag) <= _REAL_TOL) & (r.real > 0.0) & (r.real < 1.0)]
        out.append(knots[m] + s * (knots[m + 1] - knots[m]))
    return np.sort(np.concatenate(out)) if out else np.empty(0)


def max_speed_on_intervals(trajectory, t_s) -> np.ndarray:
    """Largest speed |v| (m/s) of ``trajectory`` on each [t_i, t_{i+1}].

    Parameters
    ----------
    trajectory : companion.trajectory.Trajectory
    t_s : (n,) array
        Times (s), increasing, n >= 2, within [t0, tf].

    Returns
    -------
    (n - 1,) array
        Exact maximum of |v| on each interval (module docstring): the larger
        of its ends and of every stationary point of |v|^2 inside it, the
        knots between them included (an interval may span pieces).
    """
    t = np.asarray(t_s, dtype=float).reshape(-1)
    knots = np.asarray(trajectory.knot_times_s, dtype=float)
    inner = knots[(knots > t[0]) & (knots < t[-1])]
    cand = np.concatenate([stationary_times(trajectory), inner])
    cand = cand[(cand > t[0]) & (cand < t[-1])]
    speed_ends = np.linalg.norm(trajectory.sample(t).v, axis=1)
    best = np.maximum(speed_ends[:-1], speed_ends[1:])
    if cand.size:
        idx = np.clip(np.searchsorted(t, cand, side="right") - 1, 0, t.size - 2)
        np.maximum.at(best, idx, np.linalg.norm(trajectory.sample(cand).v, axis=1))
    return best
