"""The offline planning pipeline (paper Sections 2.1-2.3.2): maps -> ISOA
coverage -> 3D way-points -> LQR trajectory.

``plan_mission`` is the one entry point used by ``companion plan``, the
mission runner and the benchmarks. It reads the two map files named by the
mission (the only I/O here) and chains the pure cores.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from .coverage import extract_waypoints, plan_coverage
from mavcore.errors import PlanError
from mavcore.maps import ElevationModel, OccupancyGrid
from .launch import launch_enu_xy, launch_key
from .polyline import densify
from mavcore.maps.field import flat_field_warning, load_mission_maps
from mavcore.maps.grid import mask_centroid_rc
from .margins import PlanMargins, margin_warning, mission_airframe_radius_m, plan_margins, planning_clearance_m
from mavcore.mission import Mission
from .sorties import plan_sorties
from .trajectory import Trajectory, generate_trajectory

#: Samples per knot interval for the speed/acceleration statistics (the pieces are
#: smooth degree-7 polynomials over ~4 s: 16 samples find their maxima to well under 1 %).
STATS_SAMPLES_PER_INTERVAL = 16
#: Most way-points a plan may have (path length / (speed x interval)); beyond it the
#: mission's speed or way-point interval is a typo, not a plan (memory would run out).
MAX_WAYPOINTS = 1_000_000


@dataclass(frozen=True)
class PlanStats:
    """Summary figures of a plan (the plan.json ``stats``).

    Attributes
    ----------
    coverage_fraction : float
        Fraction of the corridors covered by the path (from the coverage planner).
    path_length_m : float
        Length of the 2D coverage path (m).
    duration_s : float
        Trajectory duration tf - t0 (s).
    n_waypoints : int
    orientation_deg : float
        ISOA beam orientation (deg, ENU, counter-clockwise from east).
    max_speed_m_s, max_accel_m_s2 : float
        Maxima of |v| and |a| of the trajectory sampled ``STATS_SAMPLES_PER_INTERVAL``
        times per knot interval.
    waypoint_residual_m : float
        Largest distance between the trajectory and a way-point position at its time (m).
    """

    coverage_fraction: float
    path_length_m: float
    duration_s: float
    n_waypoints: int
    orientation_deg: float
    max_speed_m_s: float
    max_accel_m_s2: float
    waypoint_residual_m: float


@dataclass(frozen=True)
class PlanTimings:
    """Wall-clock time (s, ``time.perf_counter``) of each phase of ``plan_mission``.

    ``coverage`` includes the way-point extraction; ``trajectory`` includes
    the statistics sampling and the sortie split.
    """

    load: float
    coverage: float
    trajectory: float
    total: float


@dataclass(frozen=True, eq=False)
class Plan:
    """Everything ``plan_mission`` produced.

    Attributes
    ----------
    grid : OccupancyGrid
    dem : ElevationModel
    coverage : CoveragePlan
        ISOA result (``path_xy_m`` (N, 2) ENU m, ``orientation_deg``, ...).
    waypoints : Waypoints
        3D way-points (``t_s``, ``p_enu_m``, ``v_enu_m_s``, ``a_enu_m_s2``, ``corner``).
    trajectory : Trajectory
        LQR reference; its samples carry the pointing direction toward ``target_enu_m``.
    target_enu_m : (3,) array
        Pointing target S_p of eq. (21) (ENU, m).
    stats : PlanStats
    timings_s : PlanTimings
    warnings : tuple of str
        Things the user should know that did not stop the plan (main segments
        that cannot be reached and are not flown, ...), one line each.
    sorties : SortiePlan or None
        The plan split into battery-sized sorties (``companion.sorties``).
    margins : PlanMargins or None
        Clearances kept and the exports' tolerances (``companion.margins``).
    """

    grid: OccupancyGrid
    dem: ElevationModel
    coverage: object
    waypoints: object
    trajectory: Trajectory
    target_enu_m: np.ndarray
    stats: PlanStats
    timings_s: PlanTimings
    warnings: tuple[str, ...] = ()
    sorties: object = None
    margins: PlanMargins | None = None


def free_centroid_xy(grid: OccupancyGrid) -> np.ndarray:
    """Centroid (ENU m, (2,)) of the grid's free cells.

    This is the "polygon centroid" of the paper (Section 3, S_p) for a field
    given as a map: the mean of the free cell centres, i.e. the area centroid
    of the flyable ground (the field minus the vine rows; unknown cells
    outside the field do not count).
    """
    if not grid.free.any():
        raise PlanError(grid.source, "the map has no free cells")
    row_mean, col_mean = mask_centroid_rc(grid.free)
    x, y = grid.cell_to_world(row_mean, col_mean)
    return np.array([float(x), float(y)])


def pointing_target(mission: Mission, grid: OccupancyGrid, waypoints_p_enu_m: np.ndarray) -> np.ndarray:
    """S_p (ENU m, (3,)): the mission's ENU point, or for ``centroid`` the centroid
    of the free cells at the mean way-point altitude."""
    target = mission.pointing.target
    if target == "centroid":
        cx, cy = free_centroid_xy(grid)
        return np.array([cx, cy, float(np.mean(waypoints_p_enu_m[:, 2]))])
    return np.asarray(target, dtype=float)


def check_dem_covers(dem: ElevationModel, path_xy_m: np.ndarray) -> None:
    """PlanError naming the DEM file unless the DEM covers the whole path.

    The path is checked every half DEM cell along its segments, so a NODATA
    hole between two vertices is found too.
    """
    pts = densify(path_xy_m, 0.5 * dem.cellsize_m)
    ok = dem.covers(pts[:, 0], pts[:, 1])
    if not np.all(ok):
        i = int(np.flatnonzero(~ok)[0])
        x_min, x_max, y_min, y_max = dem.extent_m
        raise PlanError(dem.source, f"the DEM does not cover the coverage path (first uncovered point "
                        f"x={pts[i, 0]:.2f}, y={pts[i, 1]:.2f} m; DEM extent x {x_min:.2f}..{x_max:.2f}, "
                        f"y {y_min:.2f}..{y_max:.2f} m, NODATA cells excluded)")


def check_dem_overlaps(dem: ElevationModel, grid: OccupancyGrid) -> None:
    """PlanError naming the DEM when it does not overlap the map at all: a
    georeferenced DEM (UTM, Lambert-93, ...) read as local coordinates, said
    before planning instead of as "does not cover the path" afterwards."""
    rows, cols = grid.shape
    cx, cy = grid.cell_to_world(np.array([0, 0, rows - 1, rows - 1]), np.array([0, cols - 1, 0, cols - 1]))
    x_min, x_max, y_min, y_max = dem.extent_m
    if cx.max() < x_min or cx.min() > x_max or cy.max() < y_min or cy.min() > y_max:
        raise PlanError(dem.source, f"the DEM (x {x_min:.0f}..{x_max:.0f}, y {y_min:.0f}..{y_max:.0f} m) does not "
                        f"overlap the map (x {cx.min():.0f}..{cx.max():.0f}, y {cy.min():.0f}..{cy.max():.0f} m); "
                        "if it is georeferenced (UTM, ...), give the mission key dem_crs or a .prj file")


def check_sizes(mission: Mission, grid: OccupancyGrid) -> None:
    """PlanError unless the coverage settings fit the map's cell size.

    The erosion disk and the beam of lines are sized in cells: a safety margin
    wider than the whole grid leaves no free space (said here, before the disk
    is built), and lines closer than one cell cannot be told apart on the grid.
    """
    cov = mission.coverage
    clearance = planning_clearance_m(mission)
    if clearance / grid.resolution_m > max(grid.shape):
        raise PlanError(grid.source, f"no free space left after eroding by the airframe radius + the safety "
                        f"margin {clearance:g} m (wider than the map)")
    if cov.line_spacing_m is not None and cov.line_spacing_m < grid.resolution_m:
        raise PlanError(f"{mission.source}: key 'coverage.line_spacing_m'",
                        f"{cov.line_spacing_m:g} m is below the map resolution {grid.resolution_m:g} m")
    extent_m = max(grid.shape) * grid.resolution_m
    if cov.line_spacing_m is not None and cov.line_spacing_m >= extent_m:
        raise PlanError(f"{mission.source}: key 'coverage.line_spacing_m'",
                        f"{cov.line_spacing_m:g} m is not below the map's size {extent_m:g} m: "
                        f"no two coverage lines fit")


def trajectory_stats(trajectory: Trajectory, per_interval: int = STATS_SAMPLES_PER_INTERVAL,
                     chunk_intervals: int = 2048) -> tuple[float, float, float]:
    """(max |v| m/s, max |a| m/s^2, max way-point residual m) of a trajectory.

    Sampled ``chunk_intervals`` knot intervals at a time, so that the memory
    does not grow with the field (a 10 ha field has ~1.6e4 intervals).
    """
    knots = trajectory.knot_times_s
    tau = np.arange(per_interval) / per_interval
    # Without the pointing target: s(t) and its derivatives are not needed here.
    traj = dataclasses.replace(trajectory, target_enu_m=None)
    max_v = max_a = 0.0
    M = knots.shape[0] - 1
    for m0 in range(0, M, chunk_intervals):
        k = knots[m0:min(M, m0 + chunk_intervals) + 1]
        t = (k[:-1, None] + np.diff(k)[:, None] * tau).ravel()
        if m0 + chunk_intervals >= M:
            t = np.append(t, knots[-1])
        s = traj.sample(t)
        max_v = max(max_v, float(np.linalg.norm(s.v, axis=1).max()))
        max_a = max(max_a, float(np.linalg.norm(s.a, axis=1).max()))
    return max_v, max_a, float(np.max(trajectory.waypoint_residual_m))


def plan_mission(mission: Mission) -> Plan:
    """Plan a mission end to end.

    Parameters
    ----------
    mission : Mission
        A loaded mission (paths resolved against its file).

    Returns
    -------
    Plan

    Raises
    ------
    MapError
        A map file is missing or malformed.
    PlanError
        No coverage path, the DEM does not cover it (names the DEM file), or the
        coverage/flight settings do not fit the map (``check_sizes``, ``MAX_WAYPOINTS``).
    """
    t_start = time.perf_counter()
    launch = launch_enu_xy(mission)          # a bad launch file fails before any work
    grid, dem = load_mission_maps(mission)
    t_loaded = time.perf_counter()

    check_sizes(mission, grid)
    check_dem_overlaps(dem, grid)
    coverage = plan_coverage(grid, mission.coverage, mission_airframe_radius_m(mission))
    path = np.asarray(coverage.path_xy_m, dtype=float)
    if path.ndim != 2 or path.shape[0] < 2:
        raise PlanError(grid.source, "the coverage planner found no path in the free space")
    check_dem_covers(dem, path)
    spacing_m = mission.flight.speed_m_s * mission.flight.waypoint_interval_s
    if float(coverage.path_length_m) / spacing_m > MAX_WAYPOINTS:
        raise PlanError(f"{mission.source}: keys 'flight.speed_m_s', 'flight.waypoint_interval_s'",
                        f"way-points every {spacing_m:g} m along a {float(coverage.path_length_m):.1f} m path "
                        f"would be more than {MAX_WAYPOINTS}")
    waypoints = extract_waypoints(coverage, dem, mission.flight)
    t_covered = time.perf_counter()

    # the sorties first (they do not depend on the trajectory): the transit search's
    # peak and the LQR solve's then do not stack, nor the solve on the transit caches
    energy = mission.energy if launch is None else dataclasses.replace(
        mission.energy, launch_xy_m=(float(launch[0]), float(launch[1])))
    sorties = plan_sorties(coverage, waypoints, dem, mission.flight, mission.vehicle, energy, grid, mission.source,
                           launch_key=launch_key(mission))
    if hasattr(coverage, "free_space") and coverage.free_space is not None:
        coverage.free_space.drop_caches()
    target = pointing_target(mission, grid, np.asarray(waypoints.p_enu_m))
    trajectory = generate_trajectory(waypoints.t_s, waypoints.p_enu_m, waypoints.v_enu_m_s,
                                     waypoints.a_enu_m_s2, mission.trajectory, target_enu_m=target)
    max_v, max_a, residual = trajectory_stats(trajectory)
    t_done = time.perf_counter()

    stats = PlanStats(
        coverage_fraction=float(coverage.coverage_fraction),
        path_length_m=float(coverage.path_length_m),
        duration_s=float(trajectory.duration_s),
        n_waypoints=int(len(waypoints.t_s)),
        orientation_deg=float(coverage.orientation_deg),
        max_speed_m_s=max_v,
        max_accel_m_s2=max_a,
        waypoint_residual_m=residual,
    )
    timings = PlanTimings(load=t_loaded - t_start, coverage=t_covered - t_loaded,
                          trajectory=t_done - t_covered, total=t_done - t_start)
    return Plan(grid=grid, dem=dem, coverage=coverage, waypoints=waypoints, trajectory=trajectory,
                target_enu_m=target, stats=stats, timings_s=timings,
                warnings=tuple(w for w in (flat_field_warning(mission), margin_warning(mission)) if w)
                + tuple(grid.warnings)
                + tuple(coverage.warnings), sorties=sorties, margins=plan_margins(mission, grid, coverage))
