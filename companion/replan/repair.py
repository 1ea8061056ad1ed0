"""Repairing a re-route the guard refused (pure; docs/replan.md "One picture, and a repair").

A re-route's search keeps the clearance along its route's polyline (the 2-D
route on the eroded free space, the 3-D route on the lattice); what the
vehicle flies is the LQR fitted through way-points along that polyline
(``coverage.waypoints``, ``reroute3d.prefix_waypoints``), which tracks them
softly: where the way-points are sparse and the route turns, the fit cuts the
corner the polyline went round. The guard judges the fit, so a route the search
found clear could be refused, and the vehicle held although the route existed.

``repair`` answers a refusal of the guard (its ``Verdict``, first failing
sample ``t_s``) on a candidate plan:

1. The way-point intervals round the refused sample, ``REACH`` either side of
   the interval holding it, are the piece to repair.
2. The piece's *polyline* (its way-points joined by straight segments, sampled
   every ``STEP_M``) is judged against the same guard: the margin rule of its
   path (``Guard.check_path``: never closer than it has been inside a
   clearance, never within the airframe radius, out of a clearance it stays
   out). If it fails, the route itself is too close (the search did not see
   what the guard sees): no repair here, ``None`` (the caller adds the
   conflict to the search's obstacles, or gives up); unless it only grazes
   it, by at most ``NUDGE_MAX_M`` (a 3-D lattice route keeps its clearance
   from the blocked nodes, not from the surfaces: one passed a row's end at
   its clearance to the tenth of a millimetre, and the margin rule refused
   it): then the piece's way-points that keep less than the clearance plus
   ``NUDGE_MARGIN_M`` are moved off that surface (``nudge``) and judged again.
3. Else the fit cut what the polyline kept: the piece gets way-points every
   ``DENSE_M`` along its straight segments (moving along each as a cubic
   Hermite between its end way-points' speeds: into a turn at rest it slows
   down instead of arriving at the mean speed) and is flown ``SLOWER`` times
   slower; the LQR is re-solved from the same initial state. The result is
   checked again by the caller (paced and judged whole like the first).

Each call densifies and slows one piece; the caller repeats it at most
``MAX_REPAIRS`` times before it gives up on the candidate.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..polyline import densify
from ..trajectory import generate_trajectory
from .globalplan import GlobalPlan

#: Repairs of one candidate before it is given up.
MAX_REPAIRS = 3
#: Way-point intervals repaired either side of the one holding the refused sample.
REACH = 1
#: Spacing (m) of the way-points put into a repaired piece.
DENSE_M = 0.25
#: A repaired piece is flown this many times slower.
SLOWER = 1.5
#: A route that grazes a clearance by at most this (m) (a lattice route's node at the
#: clearance itself) has the piece's way-points moved off it (``nudge``) ...
NUDGE_MAX_M = 0.02
#: ... to keep this much (m) more than the clearance.
NUDGE_MARGIN_M = 0.02
#: Spacing (m) of the samples of a piece's polyline.
STEP_M = 0.05


@dataclass(frozen=True)
class Repair:
    """Outcome of ``repair``.

    Attributes
    ----------
    plan : GlobalPlan or None
        The repaired candidate (None: not repairable by the fit).
    reason : str
        What was done, or why not (one line).
    piece : tuple of int
        The way-point interval range [j0, j1) repaired or judged.
    """

    plan: GlobalPlan | None
    reason: str
    piece: tuple = ()


def _piece(plan: GlobalPlan, t_s: float) -> tuple[int, int]:
    """[j0, j1): the way-point intervals within ``REACH`` of the one holding ``t_s``."""
    n = len(plan.t_s) - 1
    j = int(np.clip(np.searchsorted(plan.t_s, t_s, side="right") - 1, 0, n - 1))
    return max(0, j - REACH), min(n, j + REACH + 1)


def densified(t_s, p_enu_m, v_enu_m_s, a_enu_m_s2, corner, j0: int, j1: int,
              dense_m: float = DENSE_M, slower: float = SLOWER) -> tuple:
    """(t, p, v, a, corner) with the intervals [j0, j1) flown ``slower`` times longer and
    cut into pieces of at most ``dense_m``: way-points inserted on the straight segment,
    moving along it as the cubic Hermite s(tau) from the segment's start to its end
    with the end way-points' speeds along it (so that an interval ending at rest, a
    turn, slows down into it instead of arriving at the mean speed), not corners. The
    way-points inside the piece and at its ends keep their positions, their velocities
    divided by ``slower``, their accelerations by its square; later times shifted."""
    t = np.asarray(t_s, float)
    P, V, A = (np.asarray(x, float) for x in (p_enu_m, v_enu_m_s, a_enu_m_s2))
    C = np.asarray(corner, bool)
    piece = [j0 <= j < j1 for j in range(len(t) - 1)]
    # way-point i joins intervals i - 1 and i: slower where either is in the piece
    scale = np.array([slower if (i > 0 and piece[i - 1]) or (i < len(piece) and piece[i]) else 1.0
                      for i in range(len(t))])
    nt, nP, nV, nA, nC = [t[0]], [P[0]], [V[0] / scale[0]], [A[0] / scale[0] ** 2], [C[0]]
    shift = 0.0
    for j in range(len(t) - 1):
        dt = float(t[j + 1] - t[j])
        if piece[j]:
            d = P[j + 1] - P[j]
            L = float(np.linalg.norm(d))
            T = slower * dt
            n = max(1, int(np.ceil(L / dense_m)))
            if L > 1e-9:
                u = d / L
                w0, w1 = float(V[j] @ u) / scale[j], float(V[j + 1] @ u) / scale[j + 1]
                for k in range(1, n):
                    tau = k / n
                    s = (tau ** 3 - 2 * tau ** 2 + tau) * T * w0 + (-2 * tau ** 3 + 3 * tau ** 2) * L \
                        + (tau ** 3 - tau ** 2) * T * w1
                    ds = ((3 * tau ** 2 - 4 * tau + 1) * T * w0 + (-6 * tau ** 2 + 6 * tau) * L
                          + (3 * tau ** 2 - 2 * tau) * T * w1) / T
                    dds = ((6 * tau - 4) * T * w0 + (-12 * tau + 6) * L + (6 * tau - 2) * T * w1) / (T * T)
                    nt.append(t[j] + shift + tau * T)
                    nP.append(P[j] + s * u)
                    nV.append(ds * u)
                    nA.append(dds * u)
                    nC.append(False)
            shift += T - dt
        nt.append(t[j + 1] + shift)
        nP.append(P[j + 1])
        nV.append(V[j + 1] / scale[j + 1])
        nA.append(A[j + 1] / scale[j + 1] ** 2)
        nC.append(C[j + 1])
    return np.array(nt), np.array(nP), np.array(nV), np.array(nA), np.array(nC)


def repair(plan: GlobalPlan, x0: np.ndarray, verdict, guard) -> Repair:
    """The candidate ``plan`` (its trajectory from state ``x0``, (4, 3)) repaired where the
    guard's ``verdict`` refused it (module doc)."""
    if verdict is None or verdict.ok or verdict.t_s is None or len(plan.t_s) < 2:
        return Repair(None, "nothing to repair")
    j0, j1 = _piece(plan, float(verdict.t_s))
    P = np.asarray(plan.p_enu_m, float).copy()
    P[0] = np.asarray(x0, float)[0]
    t, p, v, a, corner = densified(plan.t_s, P, plan.v_enu_m_s, plan.a_enu_m_s2, plan.corner, j0, j1)
    d1 = j1 + len(t) - len(plan.t_s)                 # the piece's last way-point, densified
    line = guard.check_path(densify(p[j0:d1 + 1], STEP_M))
    nudged = ""
    if not line.ok and line.distance_m is not None and line.distance_m >= line.required_m - NUDGE_MAX_M:
        p = nudge(p, j0, d1, line.surface, guard)
        line = guard.check_path(densify(p[j0:d1 + 1], STEP_M))
        nudged = f", moved off the {line.surface or 'surface'}s by up to {NUDGE_MAX_M + NUDGE_MARGIN_M:g} m"
    if not line.ok:
        return Repair(None, f"the route itself breaks the {line.surface} clearance between way-points "
                            f"{j0} and {j1}", (j0, j1))
    traj = generate_trajectory(t, p, v, a, plan.trajectory_config, initial_state=np.asarray(x0, float),
                               target_enu_m=plan.target_enu_m)
    segs = np.array([[s.start_xy, s.end_xy] for s in plan.segments], dtype=float).reshape(-1, 2, 2)
    new = GlobalPlan.from_waypoints(traj, t, p, v, a, corner, segs, plan.target_enu_m, plan.flight,
                                    plan.trajectory_config, plan.min_segment_m, plan.final_xy)
    new = replace(new, new_until_s=plan.new_until_s)
    return Repair(new, f"way-points {j0}-{j1} every {DENSE_M:g} m, {SLOWER:g} x slower{nudged}", (j0, j1))


def nudge(P: np.ndarray, j0: int, j1: int, kind: str, guard) -> np.ndarray:
    """(N, 3) the way-points with those of the piece [j0, j1] (not the first of the plan, the
    vehicle's state, nor its last) that keep less than the clearance of ``kind`` plus
    ``NUDGE_MARGIN_M`` moved that far along the direction the distance grows fastest
    (``Guard.normal``), by at most ``NUDGE_MAX_M + NUDGE_MARGIN_M``."""
    P = np.array(P, float)
    req = guard.required_m(kind) + NUDGE_MARGIN_M
    for k in range(max(j0, 1), min(j1, len(P) - 2) + 1):
        d = float(guard.distances(P[k][None])[kind][0])
        if d < req:
            P[k] = P[k] + min(req - d, NUDGE_MAX_M + NUDGE_MARGIN_M) * guard.normal(kind, P[k])
    return P
