"""The ``replan:`` section of a mission: the obstacle-avoiding replanner
(``companion.replan``, paper Section 2.3.3 and issue 8).

Defined here, next to the schema, so that loading a mission does not import
the replanner itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class SensorMount:
    """Where a rangefinder (one DISTANCE_SENSOR id) sits on the airframe.

    Attributes
    ----------
    id : int
        DISTANCE_SENSOR id (0..255).
    offset_flu_m : (3,) floats
        Position of the sensor relative to the centre of mass, body FLU (m).
    """

    id: int
    offset_flu_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not 0 <= self.id <= 255:
            raise ValueError("replan.sensors id must be in [0, 255]")
        if not all(math.isfinite(x) and abs(x) <= 10.0 for x in self.offset_flu_m):
            raise ValueError("replan.sensors offset_flu_m must be finite, within 10 m")


@dataclass(frozen=True)
class ReplanConfig:
    """Settings of the replanner (mission key ``replan``).

    Attributes
    ----------
    enabled : bool
        Run the replanner in flight (False: fly the plan blind, as before).
    k_att, k_rep, influence_range_m, n : float
        The improved APF of eqs. (14)-(19): attractive gain (1/s^2),
        repulsive gain (m^(4-n)/s^2), d_o (m, the paper's 2.1 m) and the
        goal-distance exponent (the paper's n = 2). k_rep / k_att = 0.2 puts
        the equilibrium in front of an obstacle on the line to a goal 10 m
        away at about 1 m (``companion.replan.apf``).
    clearance_m : float
        Closest the vehicle's body may come to an unknown obstacle (m): the
        reference's centre keeps ``clearance_m + body_radius_m`` from every
        obstacle point; the vehicle stops that far in front of an obstacle it
        cannot pass.
    body_radius_m : float or None
        Radius of the sphere holding the vehicle (arms and propellers, m);
        None: ``Replanner.from_plan`` takes the vehicle's arm plus a 10-inch
        propeller (0.442 m for the paper's vehicle), the constructor 0.
    lateral_limit_m : float
        Largest horizontal deviation from the planned path while avoiding
        (m): the rows are walls.
    ceiling_agl_m : float
        Highest the vehicle may climb above the terrain to pass over an
        obstacle (m); an obstacle whose top plus ``clearance_m`` is above it
        makes the vehicle stop and re-route.
    floor_agl_m : float
        Lowest the avoidance reference may go above the terrain (m).
    speed_m_s : float or None
        Speed limit of the avoidance reference (m/s); None: the mission's
        ``flight.speed_m_s``.
    vertical_speed_m_s, accel_m_s2, jerk_m_s3 : float
        Vertical speed, acceleration and jerk limits of the avoidance
        reference (and the jerk bound checked on a rejoin).
    emergency_accel_m_s2, emergency_jerk_m_s3 : float
        Limits of the emergency brake (per axis): a surface that the
        brake at ``accel_m_s2`` / ``jerk_m_s3`` can no longer stop for
        (it came into view inside that stopping distance: a walker out
        of a row), and the guard gate's braked hover; never below the
        normal limits (``emergency_limits``).
    canopy_height_m : float
        Height of the vine canopy above the terrain (m): the occupied OGM
        cells extruded to it are known obstacles, not unknown ones.
    known_tolerance_m : float
        A range hit within this distance of an occupied OGM cell (below the
        canopy) or of the terrain is a known feature (m).
    tilt_tolerance_deg, heading_tolerance_deg : float
        Accuracy of the attitude estimate (deg), its tilt (roll and pitch)
        and its heading: a return the known map does not explain with the
        estimated attitude is still the ground or a row when it explains it
        with the beam placed by the estimate turned by up to this much about
        a horizontal axis, or about the vertical (docs/replan.md "The
        attitude allowance"). 0 and 0 turn the allowance off. The heading's
        default is small on purpose: wider, it hid a low post from a wide
        beam whose field also held a row face.
    memory_s : float
        Not used (the obstacle map forgets nothing with time); accepted for older missions (s).
    memory_radius_m : float
        Not used (the obstacle map keeps the whole area flown); accepted for older missions (m).
    voxel_m : float
        Voxel edge of the obstacle map (``companion.replan.voxmap``, m).
    stall_s : float
        No progress along the path for this long while avoiding is a local
        minimum: the vertical escape starts (s).
    escape_timeout_s : float
        The escape must pass the obstacle it met within this time, else stop
        and re-route (s; the clock restarts once nothing is ahead).
    obstacle_depth_m : float
        Assumed depth of an obstacle behind the face the sensors saw (m),
        when it is added to the map for a re-route.
    clearance_governor : bool
        Limit the approach speed to every obstacle point so the reference
        can always brake before ``clearance_m`` (our addition to the paper's
        APF; False only for the ablation).
    vertical_escape : bool
        Climb over an obstacle the corridor does not let the vehicle pass
        (our escape from the APF's local minimum); False only for the
        ablation (the vehicle then stops and re-routes after ``escape_timeout_s``).
    give_way : bool
        Bound the closing speed to obstacles that move toward the vehicle,
        measured from successive returns (``companion.replan.closing``).
        Off by default: on static obstacles seen by wide beams it can read
        an approach that is not there (a false mover), which widens the
        avoidance trigger; turn it on where people or machines move.
    sensors : tuple of SensorMount
        Mounting offsets by DISTANCE_SENSOR id; ids not listed sit at the
        centre of mass.
    """

    enabled: bool = True
    k_att: float = 1.0
    k_rep: float = 0.2
    influence_range_m: float = 2.1
    n: float = 2.0
    clearance_m: float = 0.5
    body_radius_m: float | None = None
    lateral_limit_m: float = 0.5
    ceiling_agl_m: float = 3.0
    floor_agl_m: float = 0.5
    speed_m_s: float | None = None
    vertical_speed_m_s: float = 0.5
    accel_m_s2: float = 1.0
    jerk_m_s3: float = 2.0
    emergency_accel_m_s2: float = 3.0
    emergency_jerk_m_s3: float = 8.0
    canopy_height_m: float = 2.0
    known_tolerance_m: float = 0.2
    tilt_tolerance_deg: float = 1.5
    heading_tolerance_deg: float = 2.0
    memory_s: float = 10.0
    memory_radius_m: float = 15.0
    voxel_m: float = 0.1
    stall_s: float = 2.0
    escape_timeout_s: float = 20.0
    obstacle_depth_m: float = 0.5
    clearance_governor: bool = True
    vertical_escape: bool = True
    give_way: bool = False
    sensors: tuple[SensorMount, ...] = ()

    def __post_init__(self) -> None:
        positive = ("k_att", "influence_range_m", "clearance_m", "lateral_limit_m", "ceiling_agl_m",
                    "vertical_speed_m_s", "accel_m_s2", "jerk_m_s3", "canopy_height_m", "memory_s",
                    "memory_radius_m", "voxel_m", "stall_s", "escape_timeout_s")
        for name in positive:
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"replan.{name} must be a finite number > 0, got {v}")
        for name in ("k_rep", "n", "floor_agl_m", "known_tolerance_m", "obstacle_depth_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"replan.{name} must be a finite number >= 0, got {v}")
        for name in ("tilt_tolerance_deg", "heading_tolerance_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0 <= v <= 10):
                raise ValueError(f"replan.{name} must be in [0, 10] deg, got {v}")
        if self.body_radius_m is not None and not (math.isfinite(self.body_radius_m) and 0 <= self.body_radius_m <= 10):
            raise ValueError(f"replan.body_radius_m must be in [0, 10] m, got {self.body_radius_m}")
        if self.speed_m_s is not None and not (math.isfinite(self.speed_m_s) and self.speed_m_s > 0):
            raise ValueError(f"replan.speed_m_s must be > 0, got {self.speed_m_s}")
        if self.floor_agl_m >= self.ceiling_agl_m:
            raise ValueError("replan.floor_agl_m must be below replan.ceiling_agl_m")
        if self.clearance_m + (self.body_radius_m or 0.0) >= self.influence_range_m:
            raise ValueError("replan.clearance_m + body_radius_m must be below replan.influence_range_m")
        if self.voxel_m > self.clearance_m:
            raise ValueError("replan.voxel_m must not exceed replan.clearance_m")
        for name in ("emergency_accel_m_s2", "emergency_jerk_m_s3"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0 < v <= 20.0):
                raise ValueError(f"replan.{name} must be in (0, 20], got {v}")
        ids = [s.id for s in self.sensors]
        if len(set(ids)) != len(ids):
            raise ValueError("replan.sensors ids must be unique")

    def emergency_limits(self) -> tuple[float, float]:
        """(acceleration m/s^2, jerk m/s^3) of the emergency brake: the emergency limits,
        or the normal ones where those are higher."""
        return max(self.emergency_accel_m_s2, self.accel_m_s2), max(self.emergency_jerk_m_s3, self.jerk_m_s3)

    def offset_of(self, sensor_id: int) -> tuple[float, float, float]:
        """Mounting offset (body FLU, m) of a sensor id; the centre of mass if not listed."""
        for s in self.sensors:
            if s.id == sensor_id:
                return s.offset_flu_m
        return (0.0, 0.0, 0.0)
