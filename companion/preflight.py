"""Sanity of every way-point list that can be flown, before the flight.

``load_plan`` checks that a plan.json is well formed (keys, shapes, finite
numbers, increasing times). A well-formed plan can still be unflyable or
dangerous: a way-point at 1e300 m (it cannot even be encoded in a
MISSION_ITEM_INT), 5 km off the map, 50 m underground, a plan made for
another field, or so long that the flight cannot be held in memory.

Every list that ``companion fly`` can fly is checked by the same rules: the
whole plan, each of its sorties (``sorties[j].waypoints``, flown by
``--sortie``), a plan made on the spot, what ``--cut`` re-solves (its
way-points and the re-solved trajectory), and the trajectory actually flown,
sampled at ``SAMPLE_HZ``. Rules (ENU metres of the map frame):

- ``origin`` is the mission's ``home`` (1e-7 degree, 1 cm): a plan is made for one field;
- every number is finite; way-point times are >= 0 and strictly increasing,
  and span at most ``MAX_DURATION_S`` (one day);
- every way-point lies on the occupancy grid and inside the DEM;
- every way-point's height above the terrain is in
  ``[0.5 * flight.height_agl_m, flight.height_agl_m + max(2 m, flight.height_agl_m)]``
  (the planner puts them at exactly ``height_agl_m``): above the terrain by
  the clearance, under the ceiling;
- speeds at most ``MAX_SPEED_M_S``; accelerations at most ``MAX_ACCEL_M_S2``
  and within the vehicle's thrust: ``|a + g e_z| <= 4 max_thrust_per_rotor_n / mass_kg``
  (four rotors at full thrust; ``a_z >= -g`` needs no thrust at all);
- pointing directions are not zero (eq. 21 normalises them).

A failure is a ``PlanError``: one line naming the file (or option), the key
with the sortie and way-point index, and the problem (exit code 2 before
anything is sent to the vehicle).
"""

from __future__ import annotations

import math

import numpy as np

from mavcore.errors import PlanError
from mavcore.vehicle import GRAVITY_M_S2

MAX_DURATION_S = 86_400.0
MAX_SPEED_M_S = 30.0
MAX_ACCEL_M_S2 = 30.0
#: Rate (Hz) at which a trajectory to be flown is sampled for the same rules.
SAMPLE_HZ = 5.0
#: Samples of a trajectory check at most (a day at ``SAMPLE_HZ`` is 432 000).
MAX_SAMPLES = 500_000


def agl_band_m(mission) -> tuple[float, float]:
    """(lowest, highest) height above the terrain (m) a way-point may have."""
    agl = float(mission.flight.height_agl_m)
    return 0.5 * agl, agl + max(2.0, agl)


def max_thrust_accel_m_s2(vehicle) -> float:
    """``4 max_thrust_per_rotor_n / mass_kg`` (m/s^2): the largest ``|a + g e_z|`` the rotors give."""
    return 4.0 * float(vehicle.max_thrust_per_rotor_n) / float(vehicle.mass_kg)


def _first(bad: np.ndarray) -> int:
    return int(np.argmax(bad))


def check_waypoints(where: str, key: str, t_s, p_enu_m, v_enu_m_s, a_enu_m_s2, mission, grid, dem,
                    points: bool = True) -> None:
    """Raise ``PlanError`` unless one way-point list may be flown (module rules).

    Parameters
    ----------
    where : str
        The file or option the list comes from (``plan.json``, ``--cut 45``).
    key : str
        The list's key, e.g. ``waypoints`` or ``sorties[1].waypoints``; messages
        name ``key[i].t|p|v|a``.
    t_s : (N,) ; p_enu_m, v_enu_m_s, a_enu_m_s2 : (N, 3)
        Way-point times (s), positions (m), velocities (m/s), accelerations (m/s^2), ENU.
    mission, grid, dem
        The mission, its occupancy grid and elevation model (``load_mission_maps``).
    points : bool
        False: the per-point rules (map, terrain band, speed, acceleration) are known
        to pass already (``check_plan`` checks all the sorties' points at once).
    """
    t = np.asarray(t_s, dtype=float).reshape(-1)
    cols = {"p": p_enu_m, "v": v_enu_m_s, "a": a_enu_m_s2}
    arr = {k: np.asarray(x, dtype=float).reshape(-1, 3) for k, x in cols.items()}
    if t.size < 2 or any(x.shape[0] != t.size for x in arr.values()):
        raise PlanError(f"{where}: key '{key}'", "expected at least 2 way-points with t, p, v and a each")
    for k, x in (("t", t), *arr.items()):
        bad = ~np.isfinite(x) if x.ndim == 1 else ~np.all(np.isfinite(x), axis=1)
        if bad.any():
            raise PlanError(f"{where}: key '{key}[{_first(bad)}].{k}'", "non-finite value")
    if t[0] < 0.0:
        raise PlanError(f"{where}: key '{key}[0].t'", f"{t[0]:.6g} s: times must be >= 0")
    dt = np.diff(t)
    if np.any(dt <= 0.0):
        i = _first(dt <= 0.0) + 1
        raise PlanError(f"{where}: key '{key}[{i}].t'", f"{t[i]:.6g} s is not after {t[i - 1]:.6g} s: "
                                                       f"times must be strictly increasing")
    if t[-1] - t[0] > MAX_DURATION_S:
        raise PlanError(f"{where}: key '{key}[].t'", f"the way-points span {t[-1] - t[0]:.3g} s, "
                                                     f"more than {MAX_DURATION_S:g} s")
    if points:
        _check_points(where, lambda i: f"{key}[{i}]", arr["p"], arr["v"], arr["a"], mission, grid, dem)


def _points_pass(p, v, a, mission, grid, dem) -> bool:
    """Whether ``_check_points`` passes on these points (its rules are per point, so
    the points of many lists are checked at once: one pass instead of one per list)."""
    try:
        _check_points("", lambda i: "", p, v, a, mission, grid, dem)
    except PlanError:
        return False
    return True


def _check_points(where, name, p, v, a, mission, grid, dem) -> None:
    """The map, terrain band, speed and acceleration rules on points ``p`` (n, 3)."""
    rows, cols = grid.world_to_cell(p[:, 0], p[:, 1])
    nr, nc = grid.shape
    off = ~((rows >= -0.5) & (rows <= nr - 0.5) & (cols >= -0.5) & (cols <= nc - 0.5))
    off |= ~np.asarray(dem.covers(p[:, 0], p[:, 1]), dtype=bool)
    if off.any():
        i = _first(off)
        raise PlanError(f"{where}: key '{name(i)}.p'", f"({p[i, 0]:.6g}, {p[i, 1]:.6g}) m is off the map "
                                                        f"or outside the elevation model")
    lo, hi = agl_band_m(mission)
    h_agl = p[:, 2] - np.asarray(dem.height_at(p[:, 0], p[:, 1]), dtype=float)
    bad = (h_agl < lo) | (h_agl > hi)
    if bad.any():
        i = _first(bad)
        side = "below the clearance" if h_agl[i] < lo else "above the ceiling"
        raise PlanError(f"{where}: key '{name(i)}.p'",
                        f"{h_agl[i]:.3g} m above the terrain, {side}: outside [{lo:g}, {hi:g}] m "
                        f"(flight.height_agl_m {mission.flight.height_agl_m:g})")
    speed = np.linalg.norm(v, axis=1)
    if np.any(speed > MAX_SPEED_M_S):
        i = _first(speed > MAX_SPEED_M_S)
        raise PlanError(f"{where}: key '{name(i)}.v'", f"|v| = {speed[i]:.3g} m/s, more than {MAX_SPEED_M_S:g} m/s")
    acc = np.linalg.norm(a, axis=1)
    if np.any(acc > MAX_ACCEL_M_S2):
        i = _first(acc > MAX_ACCEL_M_S2)
        raise PlanError(f"{where}: key '{name(i)}.a'",
                        f"|a| = {acc[i]:.3g} m/s^2, more than {MAX_ACCEL_M_S2:g} m/s^2")
    thrust = np.linalg.norm(a + np.array([0.0, 0.0, GRAVITY_M_S2]), axis=1)
    limit = max_thrust_accel_m_s2(mission.vehicle)
    if np.any(thrust > limit):
        i = _first(thrust > limit)
        raise PlanError(f"{where}: key '{name(i)}.a'",
                        f"|a + g e_z| = {thrust[i]:.3g} m/s^2, more than the vehicle's thrust gives "
                        f"({limit:.3g} m/s^2 = 4 x vehicle.max_thrust_per_rotor_n / vehicle.mass_kg)")


def check_trajectory(where: str, traj, mission, grid, dem) -> None:
    """Raise ``PlanError`` unless the trajectory ``traj`` (``companion.trajectory.Trajectory``),
    sampled at ``SAMPLE_HZ`` and at its end, keeps the way-point rules; the key
    named is ``trajectory(t=...)``, the time in seconds from its start."""
    t0, tf = float(traj.t0), float(traj.tf)
    if not (math.isfinite(t0) and math.isfinite(tf) and tf > t0):
        raise PlanError(f"{where}: key 'trajectory'", f"times [{t0:.6g}, {tf:.6g}] s are not a finite interval")
    n = int(min((tf - t0) * SAMPLE_HZ, MAX_SAMPLES))
    t = np.append(t0 + np.arange(n + 1) / SAMPLE_HZ, tf)
    d = traj.derivatives(t)                       # sample(t)'s p, v, a without the pointing
    p, v, a = (np.ascontiguousarray(d[:, k, :]) for k in range(3))
    bad = ~np.all(np.isfinite(np.hstack([p, v, a])), axis=1)
    if bad.any():
        raise PlanError(f"{where}: key 'trajectory(t={t[_first(bad)] - t0:.2f} s)'", "non-finite value")
    _check_points(where, lambda i: f"trajectory(t={t[i] - t0:.2f} s)", p, v, a, mission, grid, dem)


def check_plan(pf, mission, grid, dem) -> None:
    """Raise ``PlanError`` (one line naming the plan file and key) unless the plan fits:
    its origin, its whole way-point list and every sortie's.

    Parameters
    ----------
    pf : companion.plan_io.PlanFile
    mission : Mission
    grid : OccupancyGrid
        The mission's map.
    dem : ElevationModel
        The mission's terrain.
    """
    src = pf.source
    h = mission.home
    lat, lon, alt = pf.origin
    if abs(lat - h.lat) > 1e-7 or abs(lon - h.lon) > 1e-7 or abs(alt - h.alt_m) > 0.01:
        raise PlanError(f"{src}: key 'origin'", f"({lat:g}, {lon:g}, {alt:g}) is not the mission's home "
                                                f"({h.lat:g}, {h.lon:g}, {h.alt_m:g}): a plan for another field")
    check_waypoints(src, "waypoints", pf.waypoint_t_s, pf.waypoint_p_enu_m, pf.waypoint_v_enu_m_s,
                    pf.waypoint_a_enu_m_s2, mission, grid, dem)
    # the sorties' points all at once (a 10 ha plan has ~100 sorties); only when one fails
    # are they checked list by list, for the message naming the first bad way-point
    ok = bool(pf.sorties) and _points_pass(*(np.concatenate([np.asarray(so[k], dtype=float).reshape(-1, 3)
                                                             for so in pf.sorties])
                                             for k in ("waypoint_p_enu_m", "waypoint_v_enu_m_s",
                                                       "waypoint_a_enu_m_s2")), mission, grid, dem)
    for j, so in enumerate(pf.sorties):
        check_waypoints(src, f"sorties[{j}].waypoints", so["waypoint_t_s"], so["waypoint_p_enu_m"],
                        so["waypoint_v_enu_m_s"], so["waypoint_a_enu_m_s2"], mission, grid, dem, points=not ok)
    if pf.pointing_enu is not None:
        s = np.linalg.norm(np.asarray(pf.pointing_enu, dtype=float), axis=1)
        if np.any(~(s > 1e-9)):
            i = _first(~(s > 1e-9))
            key = "trajectory.pointing" if pf.format_major == 1 else "samples.pointing"
            raise PlanError(f"{src}: key '{key}'", f"sample {i} is a zero vector")
    if pf.target_enu_m is not None and not all(math.isfinite(float(x)) for x in pf.target_enu_m):
        raise PlanError(f"{src}: key 'target_enu_m'", "non-finite value")


def check_flight_plan(where: str, fp, mission, grid, dem) -> None:
    """Raise ``PlanError`` unless what is about to be flown (``companion.flight_plan.FlightPlan``:
    a whole plan, a sortie, a cut) keeps the rules: its way-points (when it has
    their times) and its trajectory, sampled."""
    if fp.waypoints_t_s is not None:
        check_waypoints(where, "waypoints", fp.waypoints_t_s, fp.waypoints_p_enu_m, fp.waypoints_v_enu_m_s,
                        fp.waypoints_a_enu_m_s2, mission, grid, dem)
    check_trajectory(where, fp.trajectory, mission, grid, dem)


def check_plan_file(pf, mission) -> None:
    """``check_plan`` with the mission's map and DEM read from disk (MapError if unreadable)."""
    from mavcore.maps.field import load_mission_maps

    grid, dem = load_mission_maps(mission)
    check_plan(pf, mission, grid, dem)


def resume_index(waypoints_p_enu_m, pos_enu_m) -> int | None:
    """The way-point (index) nearest to the vehicle at ``pos_enu_m`` (ENU m), where
    ``--attach resume`` takes the trajectory up; None when the position is not
    finite (a NaN distance would silently pick way-point 0) or there are no way-points."""
    wp = np.asarray(waypoints_p_enu_m, dtype=float).reshape(-1, 3)
    pos = np.asarray(pos_enu_m, dtype=float).reshape(-1)
    if wp.shape[0] == 0 or pos.shape != (3,) or not np.all(np.isfinite(pos)):
        return None
    d = np.linalg.norm(wp - pos, axis=1)
    if not np.all(np.isfinite(d)):
        return None
    return int(np.argmin(d))
