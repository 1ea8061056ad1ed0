"""A re-route that leaves in 3-D (issue 15, "Routes in 3-D"; pure).

The re-route (``companion.replan.reroute``) plans the coverage left in 2-D,
in the corridors and headlands, lifted over the low obstacles it passes.
Stopped where no 2-D start reaches the coverage left (a corridor blocked
behind the vehicle too, a tall obstacle on every way out at the route's
height), it declared "no route" although the independent 3-D check of the
same map found one: over a row's canopy into the next corridor, or over a
low obstacle at the ceiling. Holds the independent check disagreed with
were 6 of 13 in an obstacles-wide campaign.

``reroute_3d`` takes that 3-D route: ``route3d.find_route`` from the vehicle
to the nearest reachable end of the coverage left (the lattice keeps the
airframe radius and clearance from rows up to the canopy, from every
obstacle column of the map and from the terrain, under the ceiling), then
the 2-D re-route from that end, as if the vehicle had stopped there at rest.
The leg in 3-D is flown rest to rest between its turning points: way-points
every ``STEP_M`` at most, sampled from the quintic rest-to-rest profile of
each leg (``prefix_waypoints``), timed like a rejoin's first leg
(``rejoin.first_time_s``). The whole is one LQR from the current state,
paced and checked by the guard like any re-route.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from mavcore.errors import InputError, PlanError
from ..trajectory import generate_trajectory
from .globalplan import GlobalPlan
from .rejoin import first_time_s
from .reroute import RerouteResult, reroute
from .route3d import RouteScene, find_route
from .shaper import ShapedState

#: Longest stretch (m) between way-points of the leg in 3-D.
STEP_M = 1.0


def quintic(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rest-to-rest quintic s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 on [0, 1] and its
    first two derivatives."""
    t = np.asarray(tau, float)
    return (10 * t ** 3 - 15 * t ** 4 + 6 * t ** 5, 30 * t ** 2 - 60 * t ** 3 + 30 * t ** 4,
            60 * t - 180 * t ** 2 + 120 * t ** 3)


def prefix_waypoints(path_enu_m: np.ndarray, speed_m_s: float, vertical_speed_m_s: float,
                     step_m: float = STEP_M) -> tuple:
    """(t (n,) from 0, p, v, a (n, 3), corner (n,)) way-points along the turning points of
    ``path_enu_m`` ((m, 3)), flown rest to rest on each leg (module doc); corner marks the
    turning points."""
    path = np.asarray(path_enu_m, float).reshape(-1, 3)
    t, P, V, A, corner = [0.0], [path[0]], [np.zeros(3)], [np.zeros(3)], [True]
    for q0, q1 in zip(path[:-1], path[1:]):
        d = q1 - q0
        L = float(np.linalg.norm(d))
        if L < 1e-9:
            continue
        T = first_time_s(q0, q1, speed_m_s, vertical_speed_m_s)
        n = max(1, int(math.ceil(L / step_m)))
        tau = np.arange(1, n + 1) / n
        s, ds, dds = quintic(tau)
        for k in range(n):
            t.append(t[-1] + T / n)
            P.append(q0 + s[k] * d)
            V.append(ds[k] / T * d)
            A.append(dds[k] / (T * T) * d)
            corner.append(k == n - 1)
    return np.array(t), np.array(P), np.array(V), np.array(A), np.array(corner)


def reroute_3d(plan: GlobalPlan, scene: RouteScene, goals_enu_m: np.ndarray, state, t_now_s: float,
               wp_index: int, blocking_enu_m: np.ndarray, travel_xy, depth_m: float,
               vertical_speed_m_s: float, keep_m: float, others_enu_m=None, over=None,
               route=None, voxel_m: float | None = None) -> RerouteResult | None:
    """The re-route through the nearest coverage end (``goals_enu_m`` (k, 3)) a 3-D route
    reaches (module doc); None when no 3-D route reaches one, else the 2-D re-route's
    result from there with the leg in 3-D put in front of its plan (its ``plan`` None and
    its reason when that re-route fails). ``route``: ``find_route(scene, state.p,
    goals_enu_m)`` when the caller already has it (it depends only on those three).
    The blocking obstacle's assumed depth extends away from the vehicle, where it was
    seen from, not from the route's far end (``reroute.with_blocking``)."""
    P0 = np.asarray(state.p, float)
    if route is None:
        route = find_route(scene, P0, goals_enu_m)
    if route is None:
        return None
    speed = float(plan.flight.speed_m_s)
    t_pre, P_pre, V_pre, A_pre, c_pre = prefix_waypoints(route.path_enu_m, speed, vertical_speed_m_s)
    goal = P_pre[-1]
    z3 = (0.0, 0.0, 0.0)
    rest = ShapedState(tuple(float(x) for x in goal), z3, z3, z3, z3)
    res = reroute(plan, scene.known, rest, t_now_s + float(t_pre[-1]), wp_index, blocking_enu_m, travel_xy,
                  depth_m, vertical_speed_m_s, keep_m, others_enu_m, over, seen_from_xy=P0[:2], voxel_m=voxel_m)
    if res.plan is None:
        return res
    R = res.plan
    t = np.concatenate([t_now_s + t_pre, R.t_s[1:]])
    P = np.vstack([P_pre, R.p_enu_m[1:]])
    P[0] = P0
    V = np.vstack([V_pre, R.v_enu_m_s[1:]])
    A = np.vstack([A_pre, R.a_enu_m_s2[1:]])
    corner = np.concatenate([c_pre, R.corner[1:]])
    x0 = np.array([state.p, state.v, state.a, state.jerk], dtype=float)
    try:
        traj = generate_trajectory(t, P, V, A, plan.trajectory_config, initial_state=x0,
                                   target_enu_m=plan.target_enu_m)
    except (InputError, PlanError) as exc:
        return replace(res, plan=None, reason=f"re-planning failed: {exc}")
    segs = np.array([[s.start_xy, s.end_xy] for s in R.segments], dtype=float).reshape(-1, 2, 2)
    new = GlobalPlan.from_waypoints(traj, t, P, V, A, corner, segs, plan.target_enu_m, plan.flight,
                                    plan.trajectory_config, plan.min_segment_m, R.final_xy)
    path = np.vstack([route.path_enu_m[:, :2], res.path_xy_m[1:]]) if len(res.path_xy_m) else route.path_enu_m[:, :2]
    return replace(res, plan=new, path_xy_m=path)
