"""Way-points with velocity and acceleration constraints (paper Sections 2.2, 2.3.1, 3.3).

Placement
    Every turning point (corner) of the coverage path is a way-point with
    velocity 0. Along each straight run between two corners, intermediate
    way-points are spaced ``d = speed * interval`` apart in 3D arc length
    along the terrain-following run (1 m/s x 4 s = 4 m as the paper); they
    are centred on the run, leaving equal end gaps ``g`` in
    ``[g_min, g_min + d/2)``, ``g_min = max(d/2, speed * t_acc / 2)``, so
    the vehicle has room to reach cruise speed. Their velocity is the
    cruise speed along the run's 3D tangent; every acceleration is 0.
    Altitude: ``z = DEM(x, y) + flight.height_agl_m``.
Times (first way-point at t = 0)
    ``t_acc = 1.875 speed / a_ref`` is the time a smooth (quintic) speed
    ramp from rest to cruise takes with peak acceleration ``a_ref``
    (default 0.5 m/s^2); the ramp covers ``speed t_acc / 2``.

    * between two intermediate way-points: ``d / speed`` (= the interval);
    * first and last piece of a run (rest <-> cruise, length ``g``):
      ``g / speed + t_acc / 2`` (cruise time plus the time lost ramping);
    * a run too short for intermediate points (rest to rest, length ``L``):
      ``max(1.875 L / speed, sqrt(5.774 L / a_ref))``, the duration at which
      the quintic rest-to-rest profile peaks at the cruise speed, or at
      ``a_ref`` (peak speed and acceleration of that profile are
      ``1.875 L / T`` and ``5.774 L / T^2``).

    These are the durations of smooth profiles that satisfy the way-point
    constraints exactly, so the minimum-snap LQR trajectory has little to
    trade off and passes the way-points closely.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mavcore.errors import PlanError
from mavcore.maps.grid import ElevationModel
from mavcore.mission.schema import FlightConfig

if TYPE_CHECKING:       # the planner's modules stay out of the flight's imports
    from .plan import CoveragePlan

#: reference peak acceleration of the speed ramps (m/s^2)
A_REF_M_S2 = 0.5
_QUINTIC_PEAK_V = 1.875       # max of d/dtau (10 tau^3 - 15 tau^4 + 6 tau^5)
_QUINTIC_PEAK_A = 5.7735      # max of d2/dtau2 of the same (10 / sqrt(3))
_DENSE_STEP_M = 0.25


@dataclass(frozen=True, eq=False)
class Waypoints:
    """Time-stamped 3D way-points (ENU, SI) for the LQR trajectory (eq. 3).

    Attributes
    ----------
    t_s : (N,) float
        Times (s), ``t_s[0] = 0``, strictly increasing.
    p_enu_m : (N, 3) float
        Positions b_i (ENU, m).
    v_enu_m_s : (N, 3) float
        Velocity constraints v_i (ENU, m/s): 0 at corners, cruise along the run elsewhere.
    a_enu_m_s2 : (N, 3) float
        Acceleration constraints a_i (ENU, m/s^2): all 0 (Section 2.3.1).
    corner : (N,) bool
        True for turning points of the coverage path.
    """

    t_s: np.ndarray
    p_enu_m: np.ndarray
    v_enu_m_s: np.ndarray
    a_enu_m_s2: np.ndarray
    corner: np.ndarray


def _dense_runs(path: np.ndarray, dem: ElevationModel, agl: float):
    """Dense terrain-following samples of every straight run of ``path`` (K, 2), ENU m.

    Run ``i`` is sampled at ``k_i = max(2, ceil(L_i / _DENSE_STEP_M) + 1)``
    evenly spaced points, both corners included (``np.linspace`` arithmetic),
    all runs in one DEM lookup. Returns the (sum k, 3) points and the index
    where each run starts (length K, the last entry the total).
    """
    a, b = path[:-1], path[1:]
    L = np.hypot(*(b - a).T)
    k = np.maximum(2, np.ceil(L / _DENSE_STEP_M).astype(np.int64) + 1)
    first = np.concatenate([[0], np.cumsum(k)])
    run = np.repeat(np.arange(len(k)), k)
    s = ((np.arange(first[-1]) - first[run]) * (1.0 / (k - 1))[run])[:, None]
    s[first[1:] - 1] = 1.0                      # np.linspace sets the end point exactly
    xy = (1 - s) * a[run] + s * b[run]
    z = dem.height_at(xy[:, 0], xy[:, 1]) + agl
    return np.column_stack([xy, z]), first


def run_duration_s(length_m, flight: FlightConfig, a_ref_m_s2: float = A_REF_M_S2, speed_m_s: float | None = None):
    """Duration (s) of a rest-to-rest straight run of ``length_m`` (scalar or array) as
    :func:`extract_waypoints` times it (module doc): ``L / V + t_acc`` when the run holds
    intermediate way-points, the quintic rest-to-rest time otherwise. ``speed_m_s``:
    the run's cruise speed (default the flight speed)."""
    L = np.asarray(length_m, dtype=float)
    V = flight.speed_m_s if speed_m_s is None else speed_m_s
    dt = flight.waypoint_interval_s
    t_acc = _QUINTIC_PEAK_V * V / a_ref_m_s2
    g_min = max(V * dt / 2, V * t_acc / 2)
    short = np.maximum(_QUINTIC_PEAK_V * L / V, np.sqrt(_QUINTIC_PEAK_A * L / a_ref_m_s2))
    return np.where(L >= 2 * g_min, L / V + t_acc, short)


def run_waypoints(length_m, flight: FlightConfig, a_ref_m_s2: float = A_REF_M_S2, speed_m_s: float | None = None):
    """Way-points a straight run of ``length_m`` (scalar or array) adds: its
    intermediate ones plus the corner at its end (module doc)."""
    L = np.asarray(length_m, dtype=float)
    V = flight.speed_m_s if speed_m_s is None else speed_m_s
    dt = flight.waypoint_interval_s
    d = V * dt
    t_acc = _QUINTIC_PEAK_V * V / a_ref_m_s2
    g_min = max(d / 2, V * t_acc / 2)
    n_mid = np.where(L >= 2 * g_min, np.floor((L - 2 * g_min) / d) + 1, 0)
    return (n_mid + 1).astype(np.int64)


def extract_waypoints(plan: CoveragePlan, dem: ElevationModel, flight: FlightConfig,
                      a_ref_m_s2: float = A_REF_M_S2) -> Waypoints:
    """Way-points of a coverage plan (placement and time allocation: module doc).

    Parameters
    ----------
    plan : CoveragePlan
        ``plan.path_xy_m`` (ENU, m) gives the corners.
    dem : ElevationModel
        Terrain heights; must cover the whole path.
    flight : FlightConfig
        Height above ground (m), cruise speed (m/s), way-point interval (s).
    a_ref_m_s2 : float
        Reference peak acceleration of the speed ramps (m/s^2).

    Raises
    ------
    MapError
        From ``dem.height_at`` (naming the DEM file) if the DEM does not cover the path.
    PlanError
        If the path has fewer than two distinct points.
    """
    return waypoints_along(np.asarray(plan.path_xy_m, dtype=float), dem, flight, a_ref_m_s2)


def waypoints_along(path_xy_m: np.ndarray, dem: ElevationModel, flight: FlightConfig,
                    a_ref_m_s2: float = A_REF_M_S2, speeds_m_s: np.ndarray | None = None) -> Waypoints:
    """Way-points along a polyline (ENU, m; consecutive vertices distinct): :func:`extract_waypoints`
    for any path (a sortie with its transits).

    ``speeds_m_s`` (K - 1,): cruise speed of each straight run (default: the
    flight speed everywhere); the way-point spacing of a run is its speed
    times the way-point interval.
    """
    dt, agl = flight.waypoint_interval_s, flight.height_agl_m
    path = np.asarray(path_xy_m, dtype=float)
    if len(path) < 2:
        raise PlanError("<plan>", "the coverage path has fewer than two points")
    if speeds_m_s is None:
        speeds_m_s = np.full(len(path) - 1, flight.speed_m_s)
    dense_all, first = _dense_runs(path, dem, agl)
    p0 = dense_all[0]                 # path[0] exactly: the first run's first sample
    step_all = np.linalg.norm(np.diff(dense_all, axis=0), axis=1)
    # per run: the corner (always) after its intermediate way-points (if any)
    ts, xs, ys, tangents, speeds, corners = [np.zeros(1)], [], [], [], [], [p0[None]]
    n_mids = []
    t = 0.0
    for i, V in enumerate(speeds_m_s):
        d = V * dt
        t_acc = _QUINTIC_PEAK_V * V / a_ref_m_s2
        g_min = max(d / 2, V * t_acc / 2)
        i0, i1 = first[i], first[i + 1]
        dense = dense_all[i0:i1]
        arc = np.concatenate([[0.0], np.cumsum(step_all[i0:i1 - 1])])
        S = float(arc[-1])
        n_mid = int(np.floor((S - 2 * g_min) / d)) + 1 if S >= 2 * g_min else 0
        if n_mid > 0:
            g = 0.5 * (S - (n_mid - 1) * d)
            s_mid = g + d * np.arange(n_mid)
            xs.append(np.interp(s_mid, arc, dense[:, 0]))
            ys.append(np.interp(s_mid, arc, dense[:, 1]))
            grad = np.gradient(dense, arc, axis=0)
            tangents.append(np.column_stack([np.interp(s_mid, arc, grad[:, j]) for j in range(3)]))
            speeds.append(np.full(n_mid, V))
            times = t + g / V + t_acc / 2 + dt * np.arange(n_mid)
            ts.append(times)
            t = times[-1] + g / V + t_acc / 2
        else:
            t += max(_QUINTIC_PEAK_V * S / V, np.sqrt(_QUINTIC_PEAK_A * S / a_ref_m_s2))
        ts.append(np.array([t]))
        n_mids.append(n_mid)
    corners.append(dense_all[first[1:] - 1])
    n_mid = np.array(n_mids, dtype=np.int64)
    n = 1 + len(n_mid) + int(n_mid.sum())
    # row of each way-point: p0, then per run its n_mid intermediate ones and its corner
    is_corner = np.zeros(n, dtype=bool)
    is_corner[0] = True
    is_corner[np.cumsum(n_mid + 1)] = True
    ps = np.empty((n, 3))
    vs = np.zeros((n, 3))
    ps[is_corner] = np.vstack(corners)
    if n_mid.sum():
        x, y = np.concatenate(xs), np.concatenate(ys)
        tangent = np.vstack(tangents)
        tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
        ps[~is_corner] = np.column_stack([x, y, dem.height_at(x, y) + agl])
        vs[~is_corner] = np.concatenate(speeds)[:, None] * tangent
    return Waypoints(t_s=np.concatenate(ts), p_enu_m=ps, v_enu_m_s=vs,
                     a_enu_m_s2=np.zeros((n, 3)), corner=is_corner)
