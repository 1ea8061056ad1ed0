"""Pacing a candidate plan to the guard's stopping law (pure; docs/replan.md "Pacing").

A re-route or a rejoin is an LQR trajectory through way-points timed at the
cruise speed. Near an obstacle it knows, the guard's speed rule
(``companion.safety.guard``, PX4 collision prevention's law) may ask for less:
a route that ends its coverage piece 1.2 m short of a blocking post, flown at
0.91 m/s toward it, leaves too little room to stop. Such a candidate is not
flown as it is, and refusing it ends the flight.

``pace`` keeps the candidate's path and retimes it, in two passes.

1. **Plan the speed.** Each way-point interval is the straight segment
   between its way-points, sampled every ``STEP_M``; the guard's
   ``speed_limits`` gives the largest speed the stopping law allows at each
   sample along that segment's direction. An interval flown faster than
   ``HEADROOM`` times its least limit is stretched to it: its duration
   multiplied by ``k`` (at most ``MAX_STRETCH``), the way-point velocities at
   its ends divided by the larger ``k`` of the intervals they join and the
   accelerations by its square (the same path, flown slower there).
2. **Fly it.** The LQR is re-solved from the same initial state and sampled
   every ``SAMPLE_DT_S`` (the guard's own sampling). The LQR tracks its
   way-points softly, so its speed swings between them: every interval with
   a sample faster than the limit along its velocity (the limit itself, not
   the guard's tolerance above it) is stretched by the worst
   ratio over ``HEADROOM`` (at least ``MIN_STRETCH``), and so is the interval
   before it, where the deceleration starts. Repeated up to ``MAX_TRIES``
   times, until no sample is too fast.
3. **Check.** Retiming must keep the candidate's path (``kept_path``: every sample
   within ``PATH_TOL_M`` of it). The LQR tracks its way-points softly, and between
   way-points far apart in time it is free: a rejoin through one way-point 8 m away,
   stretched from 10 s to 31.5 s, rose to 41.6 m and came back (fresh seed 20261163 of
   obstacles-under, flight 16: the vehicle climbed to 8.8 m before the avoidance stopped
   it; neither the terrain nor any obstacle is up there, so the guard passed it). A
   candidate that leaves its path is refused, and so is one that rises above the
   ceiling (``ceiling_agl_m``: ``Guard.check_ceiling``; the climbs and the routes keep
   under it by construction). The guard checks the whole candidate (``check_trajectory``):
   its verdict is returned with the plan. A refused candidate is not
   installed; the mode treats it as no plan. Slowing down moves a path only
   by the LQR's soft tracking (up to about 1 cm, obstacles-wide scenario 10):
   a clearance or terrain refusal stays one.

A rejoin is new only up to the time it converges onto the plan it leaves
(``horizon``, ``rejoin.converged_from``): only that part is paced and
checked, and the result carries it as ``new_until_s`` (recomputed on every
re-solve: the stretches move it).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from ..polyline import pair_segment_distances, segment_distances
from ..trajectory import generate_trajectory

#: Retime to this fraction of the speed the guard allows (the LQR tracks its way-points softly).
HEADROOM = 0.85
#: Bounds of one stretch of an interval.
MIN_STRETCH, MAX_STRETCH = 1.2, 4.0
#: No interval is flown slower than this many times its plan's duration.
MAX_TOTAL_STRETCH = 8.0
#: Retimings of pass 2 tried before the candidate is given up.
MAX_TRIES = 8
#: Spacing (m) of the samples along a way-point interval in pass 1.
STEP_M = 0.05
#: Pass 2 samples the candidate this often (s): the guard's ``SAMPLE_DT_S``.
SAMPLE_DT_S = 0.05
#: The paced trajectory stays this close (m) to the candidate's path (``kept_path``): what
#: retiming may move it by the LQR's soft tracking is about 1 cm on way-points a second
#: apart, and the corridor's own bound is ``replan.lateral_limit_m`` (0.5 m by default).
PATH_TOL_M = 0.25
#: A replanner's candidate may rise this much (m) above the ceiling (an LQR from a climbing
#: state overshoots the level it is fitted to by centimetres).
CEILING_TOL_M = 0.1


def stretch(t_s: np.ndarray, v: np.ndarray, a: np.ndarray, k: np.ndarray) -> tuple:
    """Way-point times, velocities and accelerations with interval ``j`` (``t_s[j] ..
    t_s[j+1]``) ``k[j] >= 1`` times longer: the velocity at each way-point after the first
    divided by the larger ``k`` of the intervals it joins, the acceleration by its square,
    later times shifted by the time added."""
    t = np.asarray(t_s, float)
    k = np.maximum(np.asarray(k, float), 1.0)
    v = np.array(v, float)
    a = np.array(a, float)
    out_t = np.concatenate([[t[0]], t[0] + np.cumsum(np.diff(t) * k)])
    at_wp = np.maximum(k, np.append(k[1:], 1.0))        # way-point j + 1 joins intervals j and j + 1
    v[1:] /= at_wp[:, None]
    a[1:] /= (at_wp * at_wp)[:, None]
    return out_t, v, a


def planned_stretch(t_s: np.ndarray, p_enu_m: np.ndarray, speed_limits: Callable,
                    until_s: float | None = None) -> np.ndarray:
    """(N-1,) stretch of each way-point interval that flies its straight segment at no
    more than ``HEADROOM`` times the least of ``speed_limits(points, directions)`` along
    it (1 where it already does; pass 1 of the module doc); intervals that start at or
    after ``until_s`` are left as they are."""
    t = np.asarray(t_s, float)
    p = np.asarray(p_enu_m, float)
    k = np.ones(len(t) - 1)
    for j in range(len(t) - 1):
        if until_s is not None and t[j] >= until_s:
            break
        d = p[j + 1] - p[j]
        L = float(np.linalg.norm(d))
        dt = float(t[j + 1] - t[j])
        if L < 1e-6 or dt <= 0.0:
            continue
        m = max(2, int(np.ceil(L / STEP_M)) + 1)
        pts = p[j] + np.linspace(0.0, 1.0, m)[:, None] * d
        lim = float(np.min(speed_limits(pts, np.broadcast_to(d / L, (m, 3)))))
        k[j] = float(np.clip((L / dt) / max(HEADROOM * lim, 1e-3), 1.0, MAX_STRETCH))
    return k


def _resolve(plan, x0: np.ndarray, k: np.ndarray):
    t, v, a = stretch(plan.t_s, plan.v_enu_m_s, plan.a_enu_m_s2, k)
    traj = generate_trajectory(t, plan.p_enu_m, v, a, plan.trajectory_config, initial_state=x0,
                               target_enu_m=plan.target_enu_m)
    return replace(plan, trajectory=traj, t_s=t, v_enu_m_s=v, a_enu_m_s2=a)


def sampled_stretch(plan, speed_limits: Callable, dt_s: float = SAMPLE_DT_S,
                    until_s: float | None = None) -> np.ndarray:
    """(N-1,) stretch of each way-point interval whose trajectory samples (every ``dt_s``,
    up to ``until_s``) fly faster than ``speed_limits`` allows along their velocity:
    ``max(speed / limit) / HEADROOM`` over the interval (at least ``MIN_STRETCH``), the
    interval before it stretched as much (the deceleration starts there); 1 elsewhere
    (pass 2 of the module doc)."""
    tr = plan.trajectory
    t_wp = np.asarray(plan.t_s, float)
    t = np.arange(float(t_wp[0]), float(tr.tf if until_s is None else min(until_s, tr.tf)), dt_s)
    s = tr.sample(t)
    p, v = np.asarray(s.p, float).reshape(-1, 3), np.asarray(s.v, float).reshape(-1, 3)
    speed = np.linalg.norm(v, axis=1)
    moving = speed > 1e-3
    k = np.ones(len(t_wp) - 1)
    if not moving.any():
        return k
    lim = speed_limits(p[moving], v[moving] / speed[moving, None])
    ratio = speed[moving] / np.maximum(lim, 1e-6)
    j = np.clip(np.searchsorted(t_wp, t[moving], side="right") - 1, 0, len(k) - 1)
    over = ratio > 1.0
    if not over.any():
        return k
    worst = np.zeros(len(k))
    np.maximum.at(worst, j[over], ratio[over])
    hit = worst > 0.0
    k[hit] = np.clip(worst[hit] / HEADROOM, MIN_STRETCH, MAX_STRETCH)
    lead = np.append(k[1:], 1.0)
    return np.maximum(k, lead)


def pace(plan, x0: np.ndarray, guard, horizon: Callable | None = None,
         ceiling_agl_m: float | None = None) -> tuple:
    """(plan, verdict): ``plan`` (a ``GlobalPlan`` whose trajectory starts from state
    ``x0``, (4, 3) [p, v, a, jerk]) retimed to ``guard`` (its ``speed_limits`` and
    ``check_trajectory``), and the guard's last verdict on it (module doc).
    ``horizon(plan) -> float | None``: where the plan stops being new (a rejoin,
    ``rejoin.converged_from``; None: nowhere); only that part is paced and checked, and
    the plan returned carries it as ``new_until_s``. ``ceiling_agl_m``: the new part stays
    under it (``Guard.check_ceiling``, with ``CEILING_TOL_M``)."""
    original = plan
    until = None if horizon is None else horizon(plan)
    if len(plan.t_s) >= 2:
        dt0 = np.diff(plan.t_s)
        k = planned_stretch(plan.t_s, plan.p_enu_m, guard.speed_limits, until)
        for _ in range(MAX_TRIES):
            # no interval slower than MAX_TOTAL_STRETCH times its plan: a sample that stays too
            # fast at that pace is too near to be paced (the check refuses it)
            k = np.minimum(k, MAX_TOTAL_STRETCH * dt0 / np.diff(plan.t_s))
            if not np.any(k > 1.0 + 1e-9):
                break
            plan = _resolve(plan, x0, k)
            until = None if horizon is None else horizon(plan)
            k = sampled_stretch(plan, guard.speed_limits, until_s=until)
    plan = replace(plan, new_until_s=until)
    verdict = guard.check_trajectory(plan.trajectory, float(plan.t_s[0]), until)
    if verdict.ok and until is not None:
        # the rest flies the installed plan: not re-paced, but never into an obstacle seen since
        verdict = guard.check_obstacle_clear(plan.trajectory, until)
    if verdict.ok and plan.trajectory is not original.trajectory:
        verdict = kept_path(original.trajectory, plan.trajectory, float(plan.t_s[0]), until, guard) or verdict
    if verdict.ok and ceiling_agl_m is not None:
        verdict = guard.check_ceiling(plan.trajectory, float(plan.t_s[0]), until, ceiling_agl_m, CEILING_TOL_M)
    return plan, verdict


def path_offsets_m(points_enu_m: np.ndarray, path_enu_m: np.ndarray) -> np.ndarray:
    """(M,) distance (m) of each point to the polyline ``path_enu_m`` ((N, 3), N >= 1)."""
    q = np.asarray(points_enu_m, float).reshape(-1, 3)
    a = np.asarray(path_enu_m, float).reshape(-1, 3)
    if len(a) == 1:
        return np.linalg.norm(q - a[0], axis=1)
    out = np.full(len(q), np.inf)
    for k0 in range(0, len(q), 256):                 # bounded memory
        out[k0:k0 + 256] = segment_distances(q[k0:k0 + 256], a[:-1], a[1:]).min(axis=1)
    return out


def off_path(points_enu_m: np.ndarray, path_enu_m: np.ndarray, tol_m: float) -> np.ndarray:
    """(M,) bool: ``path_offsets_m(points, path) > tol_m``, exactly, without measuring every
    point against every segment: a point within ``tol_m`` of a segment that ends at its
    nearest vertex is within ``tol_m`` of the path (its offset is the least over all
    segments, each computed by the same formula, pair by pair); only the others are measured
    against the whole path."""
    q = np.asarray(points_enu_m, float).reshape(-1, 3)
    a = np.asarray(path_enu_m, float).reshape(-1, 3)
    if len(a) < 3 or len(q) == 0:
        return path_offsets_m(q, a) > tol_m
    from scipy.spatial import cKDTree

    j = cKDTree(a).query(q)[1]
    near = np.zeros(len(q), bool)
    for seg in (np.clip(j - 1, 0, len(a) - 2), np.minimum(j, len(a) - 2)):
        near |= pair_segment_distances(q, a[seg], a[seg + 1]) <= tol_m
    out = np.zeros(len(q), bool)
    rest = np.flatnonzero(~near)
    if len(rest):
        out[rest] = path_offsets_m(q[rest], a) > tol_m
    return out


def kept_path(before, after, t_from_s: float, t_to_s: float | None, guard):
    """Pacing kept the candidate's path: every sample (every ``SAMPLE_DT_S``) of the paced
    trajectory ``after`` from ``t_from_s`` to ``t_to_s`` (None: its end) lies within
    ``PATH_TOL_M`` of the path of ``before`` (its samples joined): None; else a ``path``
    refusal (the guard's ``Verdict``) at the first sample that left it (module doc)."""
    tb = np.append(np.arange(float(before.t0), float(before.tf), SAMPLE_DT_S / 2.0), float(before.tf))
    ref = np.asarray(before.sample(tb).p, float).reshape(-1, 3)
    t0 = float(max(t_from_s, after.t0))
    tf = float(after.tf if t_to_s is None else min(t_to_s, after.tf))
    ta = np.append(np.arange(t0, tf, SAMPLE_DT_S), tf)
    p = np.asarray(after.sample(ta).p, float).reshape(-1, 3)
    bad = off_path(p, ref, PATH_TOL_M)
    if not bad.any():
        return None
    k = int(np.argmax(bad))
    off_k = float(path_offsets_m(p[k:k + 1], ref)[0])
    return guard.refusal("path", None, f"path: paced {off_k:.2f} m off the candidate's path at t={ta[k]:.2f} s",
                         float(ta[k]), p[k])
