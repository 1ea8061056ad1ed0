"""Rejoin the plan after an avoidance without a jump: re-solve the LQR from the
current reference state through the remaining way-points, time-shifted.

The new trajectory starts at ``t_now`` in the exact state the reference is
in (p, v, a and jerk: ``generate_trajectory``'s ``initial_state``), so the
setpoint is continuous up to the jerk; only the snap may step. The first
kept way-point is given the time a smooth move needs to reach it::

    T = max(d_h / V + t_ramp, 1.875 |dz| / v_z)       (quintic rest-to-rest peak speed)

(d_h horizontal and dz vertical distance, V the cruise speed, t_ramp the
speed ramp of ``companion.coverage.waypoints``); the later way-points keep
their intervals. A candidate is accepted only if, over its first
``CHECK_S`` seconds, the jerk stays within the limit (per axis) and the path
keeps the clearance from the remembered obstacle points (farther on, the
replanner meets them again as it follows). A remembered point stands for
the column below it down to the ground: obstacles stand on the ground, and
the beams may see a low one's top edge and not its sides below, so a
candidate that comes down past the points must keep the clearance from
what stands under them too. And over its **whole** length,
it stays below the ceiling and over the map's free cells: the map's rows are
not in the obstacle memory, so nothing else would stop a candidate that cuts
across them later (a rejoin through a way-point 13 m away across two rows,
checked over 6 s only, climbed to 5 m and came down into a row in the
randomized SITL benchmark). Too much jerk or height stretches T by
``STRETCH`` (up to ``MAX_TRIES`` times).

**What is new.** The LQR is stable: the difference the new initial state
makes dies out over a few way-points, and from then on the candidate flies
its parent's trajectory (the same way-points, times shifted by one constant)
to within float and re-solve noise. ``converged_from`` finds the time after
which it stays within ``CONVERGED_M`` (and ``CONVERGED_M_S``) of it; the
plan carries it as ``new_until_s``, and the guard and the pacing
(``companion.replan.pace``) judge the candidate up to there. Beyond it is
the installed plan the guard accepted, met by the avoidance like the base
plan. (Judged whole, a rejoin was refused for what lay 80 s ahead on the
plan being flown anyway: a post seen since, or a row 1.2 cm inside the
margin after the pacing slowed that far part down. The vehicle climbed on
for 20 s, then held: 5 of the 13 holds of the obstacles-wide campaign.)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..coverage.waypoints import A_REF_M_S2
from mavcore.errors import PlanError
from ..polyline import segment_distances
from ..trajectory import generate_trajectory
from .globalplan import GlobalPlan, Segment

#: Horizon (s) over which a candidate is checked.
CHECK_S = 6.0
#: Sampling step (s) of the check.
CHECK_DT_S = 0.05
#: Sampling step (s) of the map check beyond ``CHECK_S`` (0.1 m at 1 m/s: a cell).
MAP_CHECK_DT_S = 0.1
STRETCH = 1.5
MAX_TRIES = 4
#: A candidate within this distance (m) of its parent's trajectory from some time on flies
#: the parent's from there (``converged_from``): far below every clearance (0.5 m) and
#: the rows' known resolution (a 0.1 m cell).
CONVERGED_M = 0.005
#: ... and within this speed difference (m/s): the guard's speed tolerance is 0.05 m/s.
CONVERGED_M_S = 0.01
#: A candidate may exceed the ceiling by this much (m).
CEILING_TOL_M = 0.05
_QUINTIC_PEAK_V = 1.875


@dataclass(frozen=True)
class RejoinResult:
    """Outcome of ``rejoin``.

    Attributes
    ----------
    plan : GlobalPlan or None
        The re-solved plan (None: no acceptable candidate).
    reason : str
        "" when accepted, else why not ("jerk", "clearance", "ceiling", "floor", "path", "solver").
    max_jerk_m_s3 : float
        Largest |jerk| over the checked horizon of the last candidate.
    min_clearance_m : float
        Smallest distance to an obstacle point over that horizon (inf without points).
    """

    plan: GlobalPlan | None
    reason: str
    max_jerk_m_s3: float
    min_clearance_m: float


def first_time_s(p0, p1, speed_m_s: float, vertical_speed_m_s: float) -> float:
    """Duration (s) allotted to reach way-point ``p1`` from ``p0`` (ENU m; module doc)."""
    d = np.asarray(p1, dtype=float) - np.asarray(p0, dtype=float)
    t_ramp = 0.5 * _QUINTIC_PEAK_V * speed_m_s / A_REF_M_S2
    return max(float(np.hypot(d[0], d[1])) / speed_m_s + t_ramp,
               _QUINTIC_PEAK_V * abs(float(d[2])) / vertical_speed_m_s, 1.0)


@dataclass(frozen=True)
class CandidateCheck:
    """Figures of a candidate over [t0, t0 + CHECK_S]: largest per-axis |jerk| (m/s^3),
    smallest distance to an obstacle point (m, inf without points), largest height
    above the ceiling (m, -inf without a ceiling); over all of it, the deepest it goes
    below the floor (m, -inf without a floor)."""

    max_jerk_m_s3: float
    min_clearance_m: float
    above_ceiling_m: float
    below_floor_m: float = -math.inf


def check_candidate(trajectory, t0_s: float, obstacles_enu_m: np.ndarray,
                    ceiling_z: Callable[[float, float], float] | None = None,
                    free_xy: Callable[[float, float], bool] | None = None,
                    floor_z: Callable[[float, float], float] | None = None) -> CandidateCheck:
    """Check a candidate (``CandidateCheck``): jerk and obstacle clearance over its first
    ``CHECK_S`` seconds, ceiling, floor and free cells over all of it (a sample over a
    cell ``free_xy`` refuses counts as infinitely above the ceiling)."""
    t_end = min(t0_s + CHECK_S, trajectory.tf)
    t = np.arange(t0_s, t_end + 1e-9, CHECK_DT_S)
    s = trajectory.sample(t)
    jerk = float(np.max(np.abs(s.jerk)))
    above = below = -math.inf
    if ceiling_z is not None or free_xy is not None or floor_z is not None:
        rest = np.arange(t_end, trajectory.tf, MAP_CHECK_DT_S)
        pts = np.vstack([s.p, trajectory.sample(np.append(rest, trajectory.tf)).p]) if len(rest) else s.p
        if ceiling_z is not None:
            above = max(float(z) - ceiling_z(float(x), float(y)) for x, y, z in pts)
        if free_xy is not None and not all(free_xy(float(x), float(y)) for x, y, _ in pts):
            above = math.inf
        if floor_z is not None:
            below = max(floor_z(float(x), float(y)) - float(z) for x, y, z in pts)
    obs = np.asarray(obstacles_enu_m, dtype=float).reshape(-1, 3)
    if len(obs) == 0:
        return CandidateCheck(jerk, math.inf, above, below)
    return CandidateCheck(jerk, column_clearance_m(s.p, obs), above, below)


def chord_offset_m(trajectory, t0_s: float, t1_s: float, dt_s: float = CHECK_DT_S) -> float:
    """Largest horizontal distance (m) of ``trajectory`` over [t0_s, t1_s] from the chord
    between its positions at the two ends (sampled every ``dt_s``, both ends included)."""
    t = np.append(np.arange(t0_s, t1_s, dt_s), t1_s)
    xy = trajectory.sample(t).p[:, :2]
    return float(segment_distances(xy, xy[:1], xy[-1:]).max())


def converged_from(trajectory, parent, t_from_s: float, dt_s: float = CHECK_DT_S) -> float | None:
    """The time (``trajectory``'s clock) after which ``trajectory`` flies ``parent``'s
    trajectory shifted by the constant that maps their ends onto each other (a rejoin
    keeps the parent's last way-points and their intervals), to within ``CONVERGED_M``
    and ``CONVERGED_M_S``, sampled every ``dt_s`` from ``t_from_s``; None when it does
    not before its end (module doc, "What is new")."""
    shift = float(trajectory.tf) - float(parent.tf)
    t = np.arange(float(t_from_s), float(trajectory.tf), dt_s)
    t = t[t - shift >= float(parent.t0)]
    if not len(t):
        return None
    a, b = trajectory.sample(t), parent.sample(t - shift)
    dp = np.linalg.norm(np.asarray(a.p, float).reshape(-1, 3) - np.asarray(b.p, float).reshape(-1, 3), axis=1)
    dv = np.linalg.norm(np.asarray(a.v, float).reshape(-1, 3) - np.asarray(b.v, float).reshape(-1, 3), axis=1)
    off = np.flatnonzero((dp > CONVERGED_M) | (dv > CONVERGED_M_S))
    if not len(off):
        return float(t[0])
    if off[-1] == len(t) - 1:
        return None
    return float(t[off[-1] + 1])


def column_clearance_m(path_enu_m: np.ndarray, points_enu_m: np.ndarray) -> float:
    """Smallest distance from the path's samples ((n, 3)) to the vertical columns
    below the points ((k, 3)): horizontally beside a point's column, or above its
    top (module doc)."""
    d = path_enu_m[:, None, :] - points_enu_m[None]
    up = np.maximum(d[..., 2], 0.0)
    d2 = d[..., 0] ** 2 + d[..., 1] ** 2 + up * up
    return float(np.sqrt(d2.min()))


def rejoin(plan: GlobalPlan, state, t_now_s: float, first_kept: int, obstacles_enu_m: np.ndarray,
           clearance_m: float, jerk_limit_m_s3: float, vertical_speed_m_s: float,
           ceiling_z: Callable[[float, float], float] | None = None,
           free_xy: Callable[[float, float], bool] | None = None,
           floor_z: Callable[[float, float], float] | None = None,
           path_tol_m: float = math.inf) -> RejoinResult:
    """Re-solve ``plan`` from ``state`` at ``t_now_s`` through way-points ``first_kept..``.

    Parameters
    ----------
    plan : GlobalPlan
    state : ShapedState or any object with p, v, a, jerk (ENU 3-sequences)
        The reference state to continue from.
    t_now_s : float
        Plan-clock time of the switch.
    first_kept : int
        Index of the first remaining way-point (0 < first_kept < N).
    obstacles_enu_m : (k, 3) remembered obstacle points.
    clearance_m, jerk_limit_m_s3, vertical_speed_m_s : float
        Acceptance limits (clearance; per-axis jerk) and the vertical speed
        used for the time allocation.
    ceiling_z : callable (x, y) -> z, optional
        Highest allowed z (ENU m) over (x, y); a candidate going above it
        (by more than ``CEILING_TOL_M``) is stretched like one with too much jerk.
    free_xy : callable (x, y) -> bool, optional
        Where the candidate may fly (the map's free cells); one that leaves
        them is refused like one above the ceiling.
    floor_z : callable (x, y) -> z, optional
        Lowest allowed z (ENU m) over (x, y), checked over the whole candidate:
        one that dips below it (a rejoin started while descending re-solved into
        the ground, issue 15) is stretched like one above the ceiling, and
        refused as "floor".
    path_tol_m : float, optional
        How far (m, horizontally) the candidate may stray from the chord from the
        state to the first kept way-point on the way there (``chord_offset_m``): the LQR
        is free between way-points, and a start whose velocity and acceleration do
        not point along the chord bowed a rejoin 0.70 m off a straight corridor
        (obstacles-under seed 20261165 flight 10). Stretched like too much jerk, then
        refused as "path". The replanner passes its avoid modes' lateral limit.

    Returns
    -------
    RejoinResult
    """
    n = len(plan.t_s)
    if not 0 < first_kept < n:
        raise ValueError(f"first_kept must be in (0, {n}), got {first_kept}")
    kept = np.arange(first_kept, n)
    x0 = np.array([state.p, state.v, state.a, state.jerk], dtype=float)
    T = first_time_s(x0[0], plan.p_enu_m[first_kept], plan.flight.speed_m_s, vertical_speed_m_s)
    result = RejoinResult(None, "solver", float("nan"), float("nan"))
    for _ in range(MAX_TRIES):
        times = np.concatenate([[t_now_s], t_now_s + T + (plan.t_s[kept] - plan.t_s[first_kept])])
        P = np.vstack([x0[0], plan.p_enu_m[kept]])
        V = np.vstack([x0[1], plan.v_enu_m_s[kept]])
        A = np.vstack([x0[2], plan.a_enu_m_s2[kept]])
        try:
            traj = generate_trajectory(times, P, V, A, plan.trajectory_config, initial_state=x0,
                                       target_enu_m=plan.target_enu_m)
        except PlanError:
            return result
        chk = check_candidate(traj, t_now_s, obstacles_enu_m, ceiling_z, free_xy, floor_z)
        jerk, clear = chk.max_jerk_m_s3, chk.min_clearance_m
        if clear < clearance_m:
            return RejoinResult(None, "clearance", jerk, clear)
        # the chord's check samples the first piece: only for a candidate that passed the rest
        if (jerk <= jerk_limit_m_s3 and chk.above_ceiling_m <= CEILING_TOL_M and chk.below_floor_m <= 0.0
                and (not math.isfinite(path_tol_m) or chord_offset_m(traj, t_now_s, times[1]) <= path_tol_m)):
            corner = np.concatenate([[True], plan.corner[kept]])
            segs = tuple(replace(s, first_wp=max(0, s.first_wp - first_kept + 1),
                                 last_wp=s.last_wp - first_kept + 1)
                         for s in plan.segments if s.last_wp >= first_kept)
            new = replace(plan, trajectory=traj, t_s=times, p_enu_m=P, v_enu_m_s=V, a_enu_m_s2=A,
                          corner=corner, segments=segs)
            return RejoinResult(new, "", jerk, clear)
        why = ("jerk" if jerk > jerk_limit_m_s3 else "ceiling" if chk.above_ceiling_m > CEILING_TOL_M
               else "floor" if chk.below_floor_m > 0.0 else "path")
        result = RejoinResult(None, why, jerk, clear)
        T *= STRETCH
    return result
