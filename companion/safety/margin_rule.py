"""The margin rule of a path: leaving a clearance is always allowed, closing inside it never
(pure; docs/replan.md "The guard", "Candidates that start inside").

A candidate (a re-route, a rejoin, the reference shaper's brake) is a sequence
of points along its path. For one surface, with ``d`` the centre's distance to
it at each point, ``req`` the distance to keep and ``floor`` the hard floor
(the airframe radius: closer is contact):

- a point closer than ``floor`` fails, wherever it is (absolute);
- until the first point that keeps ``req`` (the candidate starts inside the
  clearance: a vehicle stopped where the obstacle map grew round it), ``d``
  may not fall below the largest it has been (``tol`` for the distance's own
  noise): never closer than it starts, and non-decreasing until out, as
  PX4's collision prevention lets a vehicle move away from, and never
  toward, a surface inside ``CP_DIST``;
- from that point on, every point keeps ``req``.

The rule has no time limit: a candidate that moves along the surface inside
the clearance without closing passes, one that closes by more than ``tol``
anywhere fails.
"""

from __future__ import annotations

import numpy as np

#: Distance noise (m) allowed before a point counts as closing: the obstacle map's
#: distance is exact to the nearest voxel box, the rows' to the cell.
CLOSING_TOL_M = 0.005


class MarginRule:
    """The rule over a path given in chunks (module doc): ``step(d)`` takes the next
    distances and answers which of them fail; the state (out yet, the largest ``d``
    so far) carries from one chunk to the next.

    Parameters
    ----------
    req_m, floor_m : float
        Distance to keep, hard floor (m).
    tol_m : float
        Closing allowed inside the clearance (m).
    """

    def __init__(self, req_m: float, floor_m: float, tol_m: float = CLOSING_TOL_M) -> None:
        self.req = float(req_m)
        self.floor = float(floor_m)
        self.tol = float(tol_m)
        self.out = False
        self.best = -np.inf

    def step(self, d) -> np.ndarray:
        """(K,) bool: which of the next (K,) distances break the rule."""
        d = np.asarray(d, float).reshape(-1)
        bad = d < self.floor
        if not len(d):
            return bad
        if self.out:
            return bad | (d < self.req)
        kept = d >= self.req
        k_out = int(np.argmax(kept)) if kept.any() else len(d)
        inside = d[:k_out]
        run = np.maximum.accumulate(np.concatenate([[self.best], inside]))[:-1]
        bad[:k_out] |= inside < run - self.tol
        bad[k_out:] |= ~kept[k_out:]
        if k_out < len(d):
            self.out = True
        elif len(inside):
            self.best = max(self.best, float(inside.max()))
        return bad


def margin_violations(d, req_m: float, floor_m: float, tol_m: float = CLOSING_TOL_M) -> np.ndarray:
    """(K,) bool: the points of a whole path (distances ``d`` (K,) in path order) that
    break the rule (module doc)."""
    return MarginRule(req_m, floor_m, tol_m).step(d)
