"""A flight put together from a mission and its ``FlightPlan``: the take-off
floor, the replanner, the guard, the true-clearance function and the
``FlightCore`` (the same construction for ``companion fly`` and
``companion replay``).
"""

from __future__ import annotations

from .flight_plan import FlightPlan


#: Clearance (m) of the take-off transfer above the highest canopy of the field.
TRANSIT_CLEARANCE_M = 1.0


def transit_floor_z_m(mission, dem) -> float:
    """Lowest height (ENU z, m) at which a level flight across the field cannot touch a
    vine row: the DEM's (``load_mission_dem``) highest point, plus the canopy
    (``replan.canopy_height_m``), plus ``TRANSIT_CLEARANCE_M``."""
    import numpy as np

    h = np.asarray(dem.heights_m, dtype=float)
    return float(np.nanmax(h)) + mission.replan.canopy_height_m + TRANSIT_CLEARANCE_M


def build_flight_core(mission, flight_plan: FlightPlan, cfg, setup: dict | None, maps=None):
    """The ``FlightCore`` that flies ``flight_plan`` (already cut) with ``cfg``: the
    same construction for ``companion fly`` and ``companion replay``. ``maps``: the
    mission's (grid, dem) when already read (``load_mission_maps``)."""
    from .control import GeometricController
    from .runner import FlightCore, FlightInputs

    from mavcore.maps.field import load_mission_maps

    ctrl = None
    if cfg.control in ("companion", "rates"):
        ctrl = GeometricController(mission.vehicle, mission.control, flight_plan.target_enu_m)
    # the maps are read once: the take-off floor, the replanner and the report's clearance share them
    grid, dem = load_mission_maps(mission) if maps is None else maps
    replanner = build_replanner(mission, flight_plan, grid, dem) if mission.replan.enabled else None
    inputs = FlightInputs(flight_plan.trajectory, flight_plan.waypoints_p_enu_m,
                          (mission.home.lat, mission.home.lon, mission.home.alt_m),
                          tuple(float(x) for x in flight_plan.target_enu_m),
                          tuple(float(x) for x in mission.control.mag_field_enu_gauss), mission.name,
                          flight_plan.coverage_fraction, flight_plan.path_xy_m, setup,
                          transit_floor_z_m(mission, dem), replanner, obstacle_clearance_fn(mission, dem),
                          build_guard(mission, replanner, grid, dem))
    return FlightCore(inputs, cfg, mission.vehicle, ctrl)


def build_guard(mission, replanner, grid, dem):
    """The guard every reference passes (``companion.safety``, docs/replan.md "The guard"):
    the replanner's known map (rows, terrain) and what it knows of the obstacles
    (its memory and the cells a re-route added); without a replanner, the mission's
    maps and no obstacles."""
    from .safety import Guard, GuardConfig, SafetyScene, known_obstacle_distance
    from .safety.gate import GuardGate

    cfg = GuardConfig.from_mission(mission)
    if replanner is not None:
        scene = SafetyScene.from_known_map(replanner.known)
        od = known_obstacle_distance(replanner.memory, lambda: replanner.known)
    else:
        scene, od = SafetyScene.from_maps(grid, dem, mission.replan.canopy_height_m), None
    rp = mission.replan
    gate = GuardGate(Guard(cfg, scene, od), rp.jerk_m_s3, rp.emergency_limits())
    if replanner is not None:
        replanner.guard = gate.guard      # re-routes and rejoins are paced to it
    return gate


def build_replanner(mission, flight_plan: FlightPlan, grid, dem):
    """The replanner (``companion.replan``) of ``flight_plan``: the mission's maps
    (``load_mission_maps``) as the known map, the plan's way-points, turning points and
    coverage segments. Way-points without a turning-point flag (a plan.json sortie) take
    their stops (v = 0) as turns."""
    import numpy as np

    from .replan import GlobalPlan, KnownMap, Replanner
    from .replan.replanner import mission_replan_config

    fp = flight_plan
    if fp.waypoints_t_s is None:
        return None
    known = KnownMap.from_mission(mission, grid, dem)
    corner = fp.waypoints_corner
    if corner is None:
        corner = np.linalg.norm(fp.waypoints_v_enu_m_s, axis=1) < 1e-9
        corner[[0, -1]] = True
    plan = GlobalPlan.from_waypoints(fp.trajectory, fp.waypoints_t_s, fp.waypoints_p_enu_m, fp.waypoints_v_enu_m_s,
                                     fp.waypoints_a_enu_m_s2, corner, fp.main_segments_xy, fp.target_enu_m,
                                     mission.flight, mission.trajectory, mission.coverage.min_segment_m,
                                     None if fp.path_xy_m is None or fp.main_segments_xy is None
                                     else tuple(fp.path_xy_m[-1]))
    return Replanner(mission_replan_config(mission), known, plan)


def obstacle_clearance_fn(mission, dem):
    """``f(pos_enu_m, t_us=None) -> (clearance_m, index)``: the vehicle sphere's distance to the
    nearest of the mission's simulated obstacles (``sim.obstacles``, standing on ``dem``) and movers
    (``sim.movers`` at vehicle time ``t_us``, us since boot; index ``len(sim.obstacles) + k`` for
    mover k); None without any. Applied to the SITL's true position only (report
    ``replanning.min_clearance_m``)."""
    obstacles = mission.sim.obstacles if mission.sim is not None else ()
    movers = mission.sim.movers if mission.sim is not None else ()
    if not obstacles and not movers:
        return None
    from mavcore.geometry import scene_from_maps
    from mavcore.mission.sim import vehicle_radius_m
    from mavcore.movers import movers_nearest

    scene = scene_from_maps(None, dem, tuple(obstacles), mission.sim.canopy_height_m)
    radius = vehicle_radius_m(mission.sim, mission.vehicle.arm_m)
    n_static = len(obstacles)

    def clearance(pos, t_us=None):
        x, y, z = float(pos[0]), float(pos[1]), float(pos[2])
        d, k = scene.nearest_obstacle(x, y, z)
        if movers and t_us is not None:
            dm, km = movers_nearest(movers, t_us * 1e-6, scene.height, x, y, z)
            if dm < d:
                d, k = dm, n_static + km
        return d - radius, k
    return clearance
