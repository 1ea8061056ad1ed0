"""Clearances a plan keeps, and the tolerances its exports give the flight stack (pure).

One page of rules (docs/mission.md "Margins"), used by the planner, the
launch point, the exports and the replanner's known map:

Airframe radius ``R``
    The sphere holding the vehicle (arms and propellers): ``replan.body_radius_m``
    when the mission sets it, else ``vehicle.arm_m + PROP_RADIUS_M`` (a
    10-inch propeller; 0.315 + 0.127 = 0.442 m for the default vehicle). The
    replanner and the SITL's crash sphere use the same default.
Planning clearance
    ``coverage.safety_margin_m`` is measured from the airframe's **surface**:
    the planner erodes the free space by ``R + safety_margin_m`` from the
    vehicle's centre, so the path, the transits and the launch point keep
    ``safety_margin_m`` between the airframe and every non-free cell. A
    margin below ``R`` is accepted with a warning naming both values (it
    used to be measured from the centre: a mission written then keeps
    ``R`` more clearance now, which it may not have room for).
Acceptance radius (NAV_WAYPOINT param2)
    The corridor is the free width between two rows, ``w = row spacing - row
    width``. A flight stack switches to the next way-point once it is inside
    the acceptance radius, so it turns early by up to that much; the radius is
    ``min(w / 3, w / 2 - R)``: at most a third of the corridor, and never more
    than the room between the airframe and a row when the vehicle is centred
    in it. Not below ``MIN_ACCEPTANCE_RADIUS_M``. The row width is
    ``field.row_width_m`` for a vector field; on a map ``w`` is measured
    (:func:`measured_corridor_width_m`). Without rows (an open field) ``w``
    is the line spacing. PX4 reads param2; ArduCopter uses WPNAV_RADIUS.
Fence margin
    The inclusion fence must not trip on the navigation error nor on the
    tracking error the plan allows: ``fence margin = navigation accuracy
    (95 % horizontal, m) + replan.lateral_limit_m``. The fence is the field
    grown until every point of the path is at least that far inside it
    (``plan_io.field_fence``).
    ``navigation.accuracy``: ``rtk`` = 0.1 m, ``gnss`` = 3.0 m, or a number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Propeller radius (m) of the default airframe sphere: a 10-inch propeller.
PROP_RADIUS_M = 0.127
#: 95 % horizontal accuracy (m) of each named navigation class: RTK fixed
#: (u-blox ZED-F9P class: 0.01 m + 1 ppm CEP, 0.1 m allows for float fixes
#: and the antenna offset), single-frequency standalone GNSS (1.5-2.5 m CEP).
NAVIGATION_ACCURACY_M = {"rtk": 0.1, "gnss": 3.0}
#: Smallest acceptance radius written (m): a stack may never reach a smaller sphere.
MIN_ACCEPTANCE_RADIUS_M = 0.1
#: Half-size of the window searched for the rows beside a corridor point (m).
MEASURE_WINDOW_M = 5.0


def airframe_radius_m(arm_m: float, body_radius_m: float | None = None) -> float:
    """Radius (m) of the sphere holding the vehicle: ``body_radius_m`` when given,
    else the arm length plus a 10-inch propeller."""
    return float(body_radius_m) if body_radius_m is not None else float(arm_m) + PROP_RADIUS_M


def mission_airframe_radius_m(mission) -> float:
    """:func:`airframe_radius_m` of a mission (``replan.body_radius_m``, ``vehicle.arm_m``)."""
    return airframe_radius_m(mission.vehicle.arm_m, mission.replan.body_radius_m)


def planning_clearance_m(mission) -> float:
    """Distance (m) the planner keeps between the vehicle's centre and every non-free
    cell: airframe radius + ``coverage.safety_margin_m``."""
    return mission_airframe_radius_m(mission) + float(mission.coverage.safety_margin_m)


def margin_warning(mission) -> str | None:
    """One line when ``coverage.safety_margin_m`` is below the airframe radius, else None."""
    r = mission_airframe_radius_m(mission)
    m = float(mission.coverage.safety_margin_m)
    if m >= r:
        return None
    return (f"{mission.source}: key 'coverage.safety_margin_m': {m:g} m is below the airframe radius "
            f"{r:.3f} m; margins are measured from the airframe's surface, so the plan keeps "
            f"{r + m:.3f} m between the vehicle's centre and the rows and obstacles")


def navigation_accuracy_m(accuracy: str | float) -> float:
    """95 % horizontal accuracy (m) of ``navigation.accuracy`` (a class name or metres)."""
    if isinstance(accuracy, str):
        return NAVIGATION_ACCURACY_M[accuracy]
    return float(accuracy)


def fence_margin_m(accuracy: str | float, lateral_limit_m: float) -> float:
    """Least distance (m) from the path to the inclusion fence (module doc)."""
    return navigation_accuracy_m(accuracy) + float(lateral_limit_m)


def corridor_width_m(row_spacing_m: float, row_width_m: float) -> float:
    """Free width (m) between two rows: spacing minus the row's width."""
    return float(row_spacing_m) - float(row_width_m)


def acceptance_radius_m(corridor_width: float, airframe_radius: float) -> float:
    """NAV_WAYPOINT acceptance radius (m): ``min(w / 3, w / 2 - R)``, at least
    ``MIN_ACCEPTANCE_RADIUS_M`` (module doc)."""
    w = float(corridor_width)
    r = min(w / 3.0, w / 2.0 - float(airframe_radius))
    return max(r, MIN_ACCEPTANCE_RADIUS_M) if math.isfinite(r) else MIN_ACCEPTANCE_RADIUS_M


def measured_corridor_width_m(grid, corridors_xy_m: np.ndarray, max_points: int = 400) -> float | None:
    """Free width (m) between the rows of a map: twice the median distance from points
    of the corridor centre lines (ENU, (k, 2, 2)) to the nearest occupied cell's edge
    (the cell centre's distance minus half a cell), searched in a window of
    ``MEASURE_WINDOW_M`` about each point. None without corridors or rows in reach."""
    lines = np.asarray(corridors_xy_m, float).reshape(-1, 2, 2)
    if len(lines) == 0:
        return None
    h = float(grid.resolution_m)
    per = max(2, max_points // len(lines))
    t = (np.arange(per) + 0.5) / per
    pts = (lines[:, None, 0] + t[None, :, None] * (lines[:, None, 1] - lines[:, None, 0])).reshape(-1, 2)
    r, c = grid.world_to_cell(pts[:, 0], pts[:, 1])
    k = int(math.ceil(MEASURE_WINDOW_M / h))
    occ = np.asarray(grid.occupied, dtype=bool)
    rows, cols = occ.shape
    d = []
    for ri, ci in zip(np.asarray(r, int), np.asarray(c, int)):
        r0, r1, c0, c1 = max(0, ri - k), min(rows, ri + k + 1), max(0, ci - k), min(cols, ci + k + 1)
        if r0 >= r1 or c0 >= c1:
            continue
        orr, occ_c = np.nonzero(occ[r0:r1, c0:c1])
        if len(orr):
            d.append(h * float(np.sqrt(np.min((orr + r0 - ri) ** 2 + (occ_c + c0 - ci) ** 2))) - 0.5 * h)
    return 2.0 * float(np.median(d)) if d else None


@dataclass(frozen=True)
class PlanMargins:
    """The clearances of a plan and the tolerances of its exports (plan.json ``margins``).

    Attributes (m)
    --------------
    airframe_radius_m, safety_margin_m, clearance_m
        R, the mission's margin (from the airframe's surface), and R + margin:
        the distance from the vehicle's centre the plan keeps.
    corridor_width_m : float
        Free width between rows (module doc); the line spacing without rows.
    acceptance_radius_m : float
        NAV_WAYPOINT param2 of the exports.
    navigation_accuracy_m : float
        95 % horizontal accuracy (``navigation.accuracy``).
    fence_margin_m : float
        Least distance from the path to the inclusion fence.
    """

    airframe_radius_m: float
    safety_margin_m: float
    clearance_m: float
    corridor_width_m: float
    acceptance_radius_m: float
    navigation_accuracy_m: float
    fence_margin_m: float


def plan_margins(mission, grid, coverage) -> PlanMargins:
    """:class:`PlanMargins` of a planned mission (its grid and ``CoveragePlan``)."""
    R = mission_airframe_radius_m(mission)
    m = float(mission.coverage.safety_margin_m)
    spacing = coverage.row_spacing_m if coverage.row_spacing_m is not None else coverage.line_spacing_m
    w = None
    if len(np.asarray(coverage.corridors_xy_m).reshape(-1, 2, 2)):
        if mission.field is not None:
            w = corridor_width_m(spacing, mission.field.row_width_m)
        else:
            w = measured_corridor_width_m(grid, coverage.corridors_xy_m)
    if w is None:
        w = float(coverage.line_spacing_m)
    acc = navigation_accuracy_m(mission.navigation.accuracy)
    return PlanMargins(airframe_radius_m=R, safety_margin_m=m, clearance_m=R + m, corridor_width_m=float(w),
                       acceptance_radius_m=acceptance_radius_m(w, R), navigation_accuracy_m=acc,
                       fence_margin_m=fence_margin_m(mission.navigation.accuracy, mission.replan.lateral_limit_m))
