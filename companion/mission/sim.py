"""The ``sim:`` section of a mission: known to the SITL only, never to the planner.

Owned by the simulator (issue 3); the companion only parses it so that a
mission file is validated in one place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal


@dataclass(frozen=True)
class ObstacleConfig:
    """An unknown obstacle, ENU metres on the map frame, standing on the terrain.

    ``cylinder`` uses ``radius``; ``box`` uses ``size_x``/``size_y`` (m) and
    ``yaw_deg`` (rotation about z, ENU, CCW from east).
    """

    type: Literal["cylinder", "box"]
    x: float
    y: float
    height: float
    radius: float = 0.0
    size_x: float = 0.0
    size_y: float = 0.0
    yaw_deg: float = 0.0

    def __post_init__(self) -> None:
        if self.height <= 0:
            raise ValueError("obstacle height must be > 0")
        if self.type == "cylinder" and self.radius <= 0:
            raise ValueError("cylinder radius must be > 0")
        if self.type == "box" and (self.size_x <= 0 or self.size_y <= 0):
            raise ValueError("box size_x and size_y must be > 0")


@dataclass(frozen=True)
class NoiseConfig:
    """White measurement noise (variances per component, as the paper) and biases."""

    vector_variance: float = 5.0e-4       # on the unit vector measurements (accel dir, mag dir)
    gyro_variance: float = 5.0e-4         # (rad/s)^2 on Omega
    position_std_m: float = 0.0           # mocap-like by default, as the paper
    velocity_std_m_s: float = 0.0
    gyro_bias_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    accel_bias_m_s2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    range_std_m: float = 0.01             # rangefinder white noise (m)

    def __post_init__(self) -> None:
        for name in ("vector_variance", "gyro_variance", "position_std_m", "velocity_std_m_s", "range_std_m"):
            if getattr(self, name) < 0:
                raise ValueError(f"noise.{name} must be >= 0")


# MAV_SENSOR_ORIENTATION values a body-fixed rangefinder may use (pymavlink
# common dialect): NONE (forward) 0, YAW_45..YAW_315 1..7, PITCH_90 (up) 24,
# PITCH_270 (down) 25.
RANGEFINDER_ORIENTATIONS = (0, 1, 2, 3, 4, 5, 6, 7, 24, 25)


@dataclass(frozen=True)
class RangefinderConfig:
    """A body-fixed rangefinder (one DISTANCE_SENSOR id).

    ``orientation`` is a MAV_SENSOR_ORIENTATION: 0 forward, 2 right (yaw 90,
    FRD convention), 4 back, 6 left, 25 down (pitch 270), 24 up (pitch 90),
    odd values the diagonals. Fields of view are full angles (deg).
    """

    id: int
    orientation: int = 0
    min_m: float = 0.1
    max_m: float = 10.0
    hfov_deg: float = 5.0
    vfov_deg: float = 5.0
    rate_hz: float = 25.0

    def __post_init__(self) -> None:
        if not 0 <= self.id <= 255:
            raise ValueError("rangefinder id must be in [0, 255]")
        if self.orientation not in RANGEFINDER_ORIENTATIONS:
            raise ValueError(f"rangefinder orientation must be one of {RANGEFINDER_ORIENTATIONS}")
        if not 0 <= self.min_m < self.max_m:
            raise ValueError("rangefinder needs 0 <= min_m < max_m")
        if not (0 <= self.hfov_deg < 180 and 0 <= self.vfov_deg < 180):
            raise ValueError("rangefinder fields of view must be in [0, 180) deg")
        if self.rate_hz <= 0:
            raise ValueError("rangefinder rate_hz must be > 0")


def default_rangefinders() -> tuple[RangefinderConfig, ...]:
    """Forward, left, right and down, as used when the mission lists none."""
    return (
        RangefinderConfig(id=0, orientation=0),
        RangefinderConfig(id=1, orientation=6),
        RangefinderConfig(id=2, orientation=2),
        RangefinderConfig(id=3, orientation=25, max_m=20.0),
    )


@dataclass(frozen=True)
class WindConfig:
    """Wind (ENU, m/s) acting through a linear drag ``F = -drag (v - w)``.

    Gusts are a first-order Gauss-Markov process per axis (stationary std
    ``gust_std_m_s``, correlation time ``gust_time_constant_s``), the
    simplest Dryden-like model. ``drag_n_s_m`` = 0 keeps the paper's
    eq. (20) (no aerodynamic force), so wind then has no effect.
    """

    mean_enu_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gust_std_m_s: float = 0.0
    gust_time_constant_s: float = 2.0
    drag_n_s_m: float = 0.0

    def __post_init__(self) -> None:
        if self.gust_std_m_s < 0 or self.drag_n_s_m < 0:
            raise ValueError("wind.gust_std_m_s and wind.drag_n_s_m must be >= 0")
        if self.gust_time_constant_s <= 0:
            raise ValueError("wind.gust_time_constant_s must be > 0")


@dataclass(frozen=True)
class SimConfig:
    """Simulation-only settings of a mission.

    ``rangefinders`` None: the default set (forward, left, right, down);
    an empty list: none. ``canopy_height_m``: the OGM's occupied cells are
    extruded from the DEM to this height for the rangefinders.
    ``magnetic_field_enu_gauss``: Earth field (default about Bordeaux's).
    ``start_enu_m``: where the vehicle starts, landed, (x, y) on the map
    frame (m); z is the terrain there. None: the SITL picks the free OGM
    cell nearest to the centroid of the free space (it never plans).
    """

    obstacles: tuple[ObstacleConfig, ...] = ()
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    seed: int = 0
    rangefinders: tuple[RangefinderConfig, ...] | None = None
    canopy_height_m: float = 2.0
    wind: WindConfig = field(default_factory=WindConfig)
    magnetic_field_enu_gauss: tuple[float, float, float] = (0.0, 0.21, -0.42)
    start_enu_m: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        from .sim_ranges import check_sim_ranges   # physical ranges of every numeric key

        if self.canopy_height_m <= 0:
            raise ValueError("sim.canopy_height_m must be > 0")
        if self.start_enu_m is not None and not all(math.isfinite(x) for x in self.start_enu_m):
            raise ValueError("sim.start_enu_m must be finite")
        if self.rangefinders is not None:
            ids = [r.id for r in self.rangefinders]
            if len(set(ids)) != len(ids):
                raise ValueError("sim.rangefinders ids must be unique")
        check_sim_ranges(self)

    @property
    def rangefinders_or_default(self) -> tuple[RangefinderConfig, ...]:
        return default_rangefinders() if self.rangefinders is None else self.rangefinders
