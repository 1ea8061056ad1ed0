"""Mission file schema (DESIGN.md "Mission YAML"): frozen dataclasses.

Only the keys below are accepted; an unknown key or a wrong type is a
``MissionError`` naming the file and the dotted key.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from ..control.config import ControlConfig
from ..vehicle import VehicleConfig
from ..trajectory.config import TrajectoryConfig
from .replan import ReplanConfig
from .sim import SimConfig

#: Upper bounds of the lengths a vineyard mission can sensibly hold (m): flight
#: height, line spacing and safety margin; beyond them the grid arithmetic of the
#: planner overflows instead of failing with a message.
MAX_LENGTH_M = 1000.0
#: Home altitude bound (m AMSL, +-).
MAX_ALTITUDE_M = 1.0e5


@dataclass(frozen=True)
class HomeConfig:
    """Geodetic pose of the map origin (WGS-84 degrees, metres AMSL)."""

    lat: float
    lon: float
    alt_m: float

    def __post_init__(self) -> None:
        if not -90.0 <= self.lat <= 90.0:
            raise ValueError(f"home.lat {self.lat} is outside [-90, 90]")
        if not -180.0 <= self.lon <= 180.0:
            raise ValueError(f"home.lon {self.lon} is outside [-180, 180]")
        if not -MAX_ALTITUDE_M <= self.alt_m <= MAX_ALTITUDE_M:
            raise ValueError(f"home.alt_m {self.alt_m} is outside [-{MAX_ALTITUDE_M:g}, {MAX_ALTITUDE_M:g}] m")


@dataclass(frozen=True)
class FlightConfig:
    """Flight height above the terrain, cruise speed and way-point spacing in time."""

    height_agl_m: float = 1.5
    speed_m_s: float = 1.0
    waypoint_interval_s: float = 4.0

    def __post_init__(self) -> None:
        if not 0 < self.height_agl_m <= MAX_LENGTH_M:
            raise ValueError(f"flight.height_agl_m must be in (0, {MAX_LENGTH_M:g}] m")
        if self.speed_m_s <= 0:
            raise ValueError("flight.speed_m_s must be > 0")
        if self.waypoint_interval_s <= 0:
            raise ValueError("flight.waypoint_interval_s must be > 0")


@dataclass(frozen=True)
class CoverageConfig:
    """ISOA settings. ``line_spacing_m`` None: detect the row spacing from the map."""

    line_spacing_m: float | None = None
    safety_margin_m: float = 0.5
    orientation_step_deg: float = 1.0
    orientation_deg: float | None = None   # force the beam orientation (deg, ENU, from east)
    min_segment_m: float = 1.0             # main segments shorter than this are not flown (m)

    def __post_init__(self) -> None:
        if self.line_spacing_m is not None and not 0 < self.line_spacing_m <= MAX_LENGTH_M:
            raise ValueError(f"coverage.line_spacing_m must be in (0, {MAX_LENGTH_M:g}] m")
        if not 0 <= self.safety_margin_m <= MAX_LENGTH_M:
            raise ValueError(f"coverage.safety_margin_m must be in [0, {MAX_LENGTH_M:g}] m")
        if not 0 < self.orientation_step_deg <= 1.0:
            raise ValueError("coverage.orientation_step_deg must be in (0, 1]")
        if self.min_segment_m <= 0:
            raise ValueError("coverage.min_segment_m must be > 0")


@dataclass(frozen=True)
class PointingConfig:
    """Pointing target S_p of eq. (21): the field's centroid or an ENU point (m)."""

    target: Literal["centroid"] | tuple[float, float, float] = "centroid"


@dataclass(frozen=True)
class Mission:
    """A whole mission, paths resolved relative to the mission file."""

    name: str
    map: str
    dem: str
    home: HomeConfig
    flight: FlightConfig = field(default_factory=FlightConfig)
    coverage: CoverageConfig = field(default_factory=CoverageConfig)
    pointing: PointingConfig = field(default_factory=PointingConfig)
    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)
    control: ControlConfig = field(default_factory=ControlConfig)
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    replan: ReplanConfig = field(default_factory=ReplanConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    description: str = ""
    base_dir: str = "."   # set by the loader: directory of the mission file
    source: str = "<mission>"   # set by the loader: the mission file (for error messages)

    @property
    def map_path(self) -> Path:
        return Path(self.base_dir) / self.map

    @property
    def dem_path(self) -> Path:
        return Path(self.base_dir) / self.dem
