"""Sanity of a plan.json against the mission it is flown with, before the flight.

``load_plan`` checks that a plan.json is well formed (keys, shapes, finite
numbers, increasing times). A well-formed plan can still be unflyable or
dangerous: a way-point at 1e300 m (it cannot even be encoded in a
MISSION_ITEM_INT), 5 km off the map, 50 m underground, a plan made for
another field, or so long that the flight cannot be held in memory. Rules
(ENU metres of the map frame):

- ``origin`` is the mission's ``home`` (1e-7 degree, 1 cm): a plan is made for one field;
- every way-point lies on the occupancy grid and inside the DEM;
- every way-point's height above the terrain is in
  ``[0.5 * flight.height_agl_m, flight.height_agl_m + max(2 m, flight.height_agl_m)]``
  (the planner puts them at exactly ``height_agl_m``);
- way-point speeds at most ``MAX_SPEED_M_S``, accelerations at most ``MAX_ACCEL_M_S2``;
- the way-points span at most ``MAX_DURATION_S`` (one day);
- pointing directions are not zero (eq. 21 normalises them).
"""

from __future__ import annotations

import math

import numpy as np

from .errors import PlanError

MAX_DURATION_S = 86_400.0
MAX_SPEED_M_S = 30.0
MAX_ACCEL_M_S2 = 30.0


def check_plan(pf, mission, grid, dem) -> None:
    """Raise ``PlanError`` (one line naming the plan file and key) unless the plan fits.

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
    t = np.asarray(pf.waypoint_t_s, dtype=float)
    if t[-1] - t[0] > MAX_DURATION_S:
        raise PlanError(f"{src}: key 'waypoints[].t'", f"the way-points span {t[-1] - t[0]:.3g} s, "
                                                       f"more than {MAX_DURATION_S:g} s")
    p = np.asarray(pf.waypoint_p_enu_m, dtype=float)
    rows, cols = grid.world_to_cell(p[:, 0], p[:, 1])
    nr, nc = grid.shape
    off = ~((rows >= -0.5) & (rows <= nr - 0.5) & (cols >= -0.5) & (cols <= nc - 0.5))
    off |= ~np.asarray(dem.covers(p[:, 0], p[:, 1]), dtype=bool)
    if off.any():
        i = int(np.argmax(off))
        raise PlanError(f"{src}: key 'waypoints[{i}].p'", f"({p[i, 0]:.6g}, {p[i, 1]:.6g}) m is off the map "
                                                          f"or outside the elevation model")
    agl = float(mission.flight.height_agl_m)
    lo, hi = 0.5 * agl, agl + max(2.0, agl)
    h_agl = p[:, 2] - np.asarray(dem.height_at(p[:, 0], p[:, 1]), dtype=float)
    bad = (h_agl < lo) | (h_agl > hi)
    if bad.any():
        i = int(np.argmax(bad))
        raise PlanError(f"{src}: key 'waypoints[{i}].p'", f"{h_agl[i]:.3g} m above the terrain, outside "
                                                          f"[{lo:g}, {hi:g}] m (flight.height_agl_m {agl:g})")
    for key, arr, limit, unit in (("v", pf.waypoint_v_enu_m_s, MAX_SPEED_M_S, "m/s"),
                                  ("a", pf.waypoint_a_enu_m_s2, MAX_ACCEL_M_S2, "m/s^2")):
        n = np.linalg.norm(np.asarray(arr, dtype=float), axis=1)
        if np.any(n > limit):
            i = int(np.argmax(n > limit))
            raise PlanError(f"{src}: key 'waypoints[{i}].{key}'", f"|{key}| = {n[i]:.3g} {unit}, "
                                                                  f"more than {limit:g} {unit}")
    s = np.linalg.norm(np.asarray(pf.pointing_enu, dtype=float), axis=1)
    if np.any(~(s > 1e-9)):
        i = int(np.argmax(~(s > 1e-9)))
        raise PlanError(f"{src}: key 'trajectory.pointing'", f"sample {i} is a zero vector")
    if pf.target_enu_m is not None and not all(math.isfinite(float(x)) for x in pf.target_enu_m):
        raise PlanError(f"{src}: key 'target_enu_m'", "non-finite value")


def check_plan_file(pf, mission) -> None:
    """``check_plan`` with the mission's map and DEM read from disk (MapError if unreadable)."""
    from .maps.field import load_mission_maps

    check_plan(pf, mission, *load_mission_maps(mission))
