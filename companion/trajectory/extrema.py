"""Exact largest speed of a trajectory between given times.

Pure. A piece m of ``companion.trajectory.Trajectory`` has velocity
v(s) = sum_j V[j] s^j on s = (t - t_m) / (t_{m+1} - t_m) in [0, 1]
(``coefficients[m, :, 1, :]``, ENU m/s), so its squared speed
q(s) = |v(s)|^2 is a polynomial of degree 2 deg (the auto-correlation of the
coefficients). On any interval [s_a, s_b] inside one piece the largest of q
is at s_a, at s_b or at a zero of q'(s) between them: evaluating the speed at
those points gives the exact maximum. The zeros are the eigenvalues of q's
companion matrix (``numpy.polynomial.polynomial.polyroots``, all pieces of a degree at once); a zero found
with error delta changes the value by O(delta^2) (q' = 0 there), and
near-real ones are evaluated too (a real point of the interval never
over-states the maximum).
"""

from __future__ import annotations

import numpy as np

#: Imaginary part (relative to 1 in s) under which a zero of q' counts as real.
_REAL_TOL = 1e-6


def _squared_speed_derivatives(V: np.ndarray) -> np.ndarray:
    """(M, 2 deg) coefficients in s of d|v|^2/ds for (M, 3, deg + 1) velocity coefficients (axis, power).

    Each piece's q = |v|^2 is summed from ``np.convolve`` of its own axes, as
    before this was batched: NumPy's convolution sums through a BLAS dot
    product, whose rounding a vectorised sum of products does not reproduce
    bit for bit (the zeros, and so the flights, are kept exactly). The
    derivative is ``P.polyder``'s ``j * c[j]``, for all pieces at once.
    """
    # np.convolve keeps every length at 2 deg + 1 (P.polymul trims trailing zeros)
    q = np.array([sum(np.convolve(row, row) for row in piece) for piece in V])
    q = q.reshape(V.shape[0], 2 * V.shape[2] - 1)     # (0, 2 deg + 1) for no pieces
    return q[:, 1:] * np.arange(1, q.shape[1])


def _roots_by_length(dq: np.ndarray):
    """Yield (pieces, roots) for the pieces of ``dq`` (M, n) grouped by their length
    without trailing zeros: ``P.polyroots`` of every piece of a group at once.

    The same companion matrices as ``polyroots`` (``polycompanion``; NumPy 2.x
    no longer rotates them),
    and ``np.linalg.eigvals`` of their stack, which runs LAPACK's ``dgeev`` on
    each matrix as a single call would: the same roots bit for bit
    (tests/test_trajectory_extrema.py). Pieces of length < 2 (constant speed)
    yield nothing; roots are complex, (pieces, length - 1).
    """
    nz = dq != 0.0
    length = np.where(nz.any(axis=1), dq.shape[1] - np.argmax(nz[:, ::-1], axis=1), 0)
    for L in np.unique(length[length >= 2]):
        idx = np.flatnonzero(length == L)
        c = dq[idx, :L]
        if L == 2:
            yield idx, (-c[:, 0] / c[:, 1])[:, None].astype(complex)
            continue
        n = L - 1
        mat = np.zeros((idx.size, n, n))
        mat[:, np.arange(1, n), np.arange(n - 1)] = 1.0
        mat[:, :, -1] -= c[:, :-1] / c[:, -1:]
        yield idx, np.linalg.eigvals(mat).astype(complex)


def stationary_times(trajectory) -> np.ndarray:
    """Times (s) inside the pieces where |v|^2 is stationary (zeros of its derivative), sorted."""
    knots = np.asarray(trajectory.knot_times_s, dtype=float)
    V = np.asarray(trajectory.coefficients, dtype=float)[:, :, 1, :]      # (M, deg + 1, 3)
    dq = _squared_speed_derivatives(np.ascontiguousarray(V.transpose(0, 2, 1)))
    out = []
    for idx, r in _roots_by_length(dq):
        real = (np.abs(r.imag) <= _REAL_TOL) & (r.real > 0.0) & (r.real < 1.0)
        m = np.broadcast_to(idx[:, None], r.shape)[real]
        out.append(knots[m] + r.real[real] * (knots[m + 1] - knots[m]))
    return np.sort(np.concatenate(out)) if out else np.empty(0)


def max_speed_on_intervals(trajectory, t_s, v_enu_m_s=None) -> np.ndarray:
    """Largest speed |v| (m/s) of ``trajectory`` on each [t_i, t_{i+1}].

    Parameters
    ----------
    trajectory : companion.trajectory.Trajectory
    t_s : (n,) array
        Times (s), increasing, n >= 2, within [t0, tf].
    v_enu_m_s : (n, 3) array, optional
        ``trajectory.sample(t_s).v`` where the caller has it already (else
        evaluated here, without the pointing directions).

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
    v = trajectory.derivatives(t)[:, 1, :] if v_enu_m_s is None else np.asarray(v_enu_m_s, dtype=float)
    speed_ends = np.linalg.norm(v, axis=1)
    best = np.maximum(speed_ends[:-1], speed_ends[1:])
    if cand.size:
        idx = np.clip(np.searchsorted(t, cand, side="right") - 1, 0, t.size - 2)
        np.maximum.at(best, idx, np.linalg.norm(trajectory.derivatives(cand)[:, 1, :], axis=1))
    return best
