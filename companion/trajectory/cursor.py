"""Evaluate a ``Trajectory`` one time at a time, cheaply, with a forward-moving cursor.

``Trajectory.sample`` is vectorised: right for many times at once, but for
one time per frame (250 Hz) its fixed cost dominates. The cursor keeps the
index of the current knot interval and moves it forward as time advances,
so one evaluation is a dot product of the interval's (15, deg + 1)
coefficient block with the powers of tau: the same numbers as
``Trajectory.sample`` (checked in the tests), no per-flight cache, memory
independent of the flight length.
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass

import numpy as np

from .sampling import Trajectory


@dataclass(frozen=True, slots=True)
class CursorSample:
    """One evaluation (ENU, SI; float 3-tuples): position, velocity,
    acceleration, jerk and snap at ``t_s`` (clamped to [t0, tf])."""

    t_s: float
    p: tuple
    v: tuple
    a: tuple
    jerk: tuple
    snap: tuple


class TrajectoryCursor:
    """Forward-moving evaluator of one ``Trajectory`` (times in the trajectory's clock).

    Parameters
    ----------
    trajectory : Trajectory
    """

    def __init__(self, trajectory: Trajectory) -> None:
        self.trajectory = trajectory
        knots = np.asarray(trajectory.knot_times_s, dtype=float)
        self._knots = knots.tolist()
        self._M = len(self._knots) - 1
        c = np.asarray(trajectory.coefficients, dtype=float)
        deg1 = c.shape[1]
        # (M, 15, deg + 1): channel (k, axis) -> polynomial coefficients in tau
        self._blocks = np.ascontiguousarray(c.reshape(self._M, deg1, 15).transpose(0, 2, 1))
        self._deg1 = deg1
        self._m = 0
        self._t0, self._tf = self._knots[0], self._knots[-1]

    @property
    def t0(self) -> float:
        return self._t0

    @property
    def tf(self) -> float:
        return self._tf

    def interval(self, t_s: float) -> int:
        """Index of the knot interval holding ``t_s`` (clamped); moves the cursor."""
        k = self._knots
        m = self._m
        if t_s < k[m]:                       # time went back: search (rare)
            m = max(0, min(self._M - 1, bisect_right(k, t_s) - 1))
        else:
            M1 = self._M - 1
            while m < M1 and t_s >= k[m + 1]:
                m += 1
        self._m = m
        return m

    def sample(self, t_s: float) -> CursorSample:
        """p, v, a, jerk, snap at ``t_s`` (s, the trajectory's clock; clamped to [t0, tf])."""
        t = self._t0 if t_s < self._t0 else (self._tf if t_s > self._tf else t_s)
        m = self.interval(t)
        k0, k1 = self._knots[m], self._knots[m + 1]
        tau = (t - k0) / (k1 - k0)
        if self._deg1 == 8:
            t2 = tau * tau
            t4 = t2 * t2
            pw = np.array((1.0, tau, t2, t2 * tau, t4, t4 * tau, t4 * t2, t4 * t2 * tau))
        else:
            pw = tau ** np.arange(self._deg1)
        v = self._blocks[m].dot(pw).tolist()
        return CursorSample(t, tuple(v[0:3]), tuple(v[3:6]), tuple(v[6:9]), tuple(v[9:12]), tuple(v[12:15]))
