"""Mission file schema (docs/mission.md): frozen dataclasses.

The field comes from ``map`` (a Nav2 map YAML) or ``field`` (GeoJSON/KML);
``dem`` is a local ASCII grid or a georeferenced raster (``dem_crs`` when the
file has no CRS); see ``mavcore.maps.field``.

Only the keys below are accepted; an unknown key or a wrong type is a
``MissionError`` naming the file and the dotted key.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from dataclasses import field as _field   # the Mission class has a key named "field"
from pathlib import Path
from typing import Literal

from mavcore.mission.control import ControlConfig
from ..energy import EnergyConfig
from ..vehicle import VehicleConfig
from mavcore.mission.trajectory import TrajectoryConfig
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
    """Geodetic pose of the map origin (WGS-84 degrees, metres AMSL).

    ``heading_deg``: compass bearing (deg, clockwise from north) of the local
    map files' x axis; 90 (default) is east. The loaders rotate local maps
    into ENU (``mavcore.maps.field``); everything else in the mission is ENU.
    """

    lat: float
    lon: float
    alt_m: float
    heading_deg: float = 90.0

    def __post_init__(self) -> None:
        if not -90.0 <= self.lat <= 90.0:
            raise ValueError(f"home.lat {self.lat} is outside [-90, 90]")
        if not -180.0 <= self.lon <= 180.0:
            raise ValueError(f"home.lon {self.lon} is outside [-180, 180]")
        if not -MAX_ALTITUDE_M <= self.alt_m <= MAX_ALTITUDE_M:
            raise ValueError(f"home.alt_m {self.alt_m} is outside [-{MAX_ALTITUDE_M:g}, {MAX_ALTITUDE_M:g}] m")
        if not -360.0 <= self.heading_deg <= 360.0:
            raise ValueError(f"home.heading_deg {self.heading_deg} is outside [-360, 360]")


@dataclass(frozen=True)
class FlightConfig:
    """Flight height above the terrain, cruise speed and way-point spacing in time.

    ``transit_speed_m_s``: speed of the transits between the launch point and
    the corridors of a sortie (nothing is covered there), default 3 m/s.
    """

    height_agl_m: float = 1.5
    speed_m_s: float = 1.0
    waypoint_interval_s: float = 4.0
    transit_speed_m_s: float = 3.0

    def __post_init__(self) -> None:
        if not 0 < self.height_agl_m <= MAX_LENGTH_M:
            raise ValueError(f"flight.height_agl_m must be in (0, {MAX_LENGTH_M:g}] m")
        if self.speed_m_s <= 0:
            raise ValueError("flight.speed_m_s must be > 0")
        if self.waypoint_interval_s <= 0:
            raise ValueError("flight.waypoint_interval_s must be > 0")
        if not 0 < self.transit_speed_m_s <= 30.0:
            raise ValueError("flight.transit_speed_m_s must be in (0, 30] m/s")


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
class FieldConfig:
    """A field given as vectors (GeoJSON or KML, WGS-84): rasterised at ``resolution_m``;
    line strings are vine rows ``row_width_m`` wide (``mavcore.maps.field``)."""

    file: str
    resolution_m: float = 0.1
    row_width_m: float = 0.4
    border_m: float = 2.0

    def __post_init__(self) -> None:
        if not 0.01 <= self.resolution_m <= 10.0:
            raise ValueError("field.resolution_m must be in [0.01, 10] m")
        if not 0 < self.row_width_m <= 10.0:
            raise ValueError("field.row_width_m must be in (0, 10] m")
        if not 0 <= self.border_m <= 100.0:
            raise ValueError("field.border_m must be in [0, 100] m")


@dataclass(frozen=True)
class NavigationConfig:
    """The flight stack's navigation: ``accuracy`` is its 95 % horizontal position
    error, ``rtk`` (0.1 m), ``gnss`` (3.0 m) or metres (``companion.margins``);
    it sizes the inclusion fence's margin."""

    accuracy: Literal["rtk", "gnss"] | float = "rtk"

    def __post_init__(self) -> None:
        if not isinstance(self.accuracy, str) and not 0 < self.accuracy <= 100.0:
            raise ValueError("navigation.accuracy must be rtk, gnss or a number in (0, 100] m")


@dataclass(frozen=True)
class LaunchConfig:
    """Where every sortie takes off and lands, in one of three forms (exactly one):

    - ``enu_m: [x, y]``: ENU metres on the map frame;
    - ``lat``, ``lon``: WGS-84 degrees;
    - a GeoJSON Point, inline (``type: Point``, ``coordinates: [lon, lat]``)
      or ``file``: a GeoJSON file (relative to the mission file) holding one
      Point, or a Point feature whose ``role`` is ``launch``.

    Resolved to ENU by ``companion.launch``.
    """

    enu_m: tuple[float, float] | None = None
    lat: float | None = None
    lon: float | None = None
    type: Literal["Point"] | None = None
    coordinates: tuple[float, float] | tuple[float, float, float] | None = None
    file: str | None = None

    def __post_init__(self) -> None:
        forms = [self.enu_m is not None, self.lat is not None or self.lon is not None,
                 self.type is not None or self.coordinates is not None, self.file is not None]
        if sum(forms) != 1:
            raise ValueError("launch: give exactly one of enu_m, lat/lon, a GeoJSON Point "
                             "(type, coordinates) or file")
        if (self.lat is None) != (self.lon is None):
            raise ValueError("launch: give both lat and lon")
        if self.lat is not None and not (-90.0 <= self.lat <= 90.0 and -180.0 <= self.lon <= 180.0):
            raise ValueError(f"launch: lat {self.lat}, lon {self.lon} are not WGS-84 degrees")
        if (self.type is None) != (self.coordinates is None):
            raise ValueError("launch: a GeoJSON Point needs both type: Point and coordinates: [lon, lat]")
        if self.coordinates is not None and not (-180.0 <= self.coordinates[0] <= 180.0
                                                 and -90.0 <= self.coordinates[1] <= 90.0):
            raise ValueError(f"launch: coordinates {list(self.coordinates)} are not [lon, lat] in WGS-84 degrees")


@dataclass(frozen=True)
class PointingConfig:
    """Pointing target S_p of eq. (21): the field's centroid or an ENU point (m)."""

    target: Literal["centroid"] | tuple[float, float, float] = "centroid"


@dataclass(frozen=True)
class Mission:
    """A whole mission, paths resolved relative to the mission file."""

    name: str
    home: HomeConfig
    dem: str | None = None
    elevation_m: float | None = None
    map: str | None = None
    field: FieldConfig | None = None
    dem_crs: str | None = None
    launch: LaunchConfig | None = None
    flight: FlightConfig = _field(default_factory=FlightConfig)
    coverage: CoverageConfig = _field(default_factory=CoverageConfig)
    navigation: NavigationConfig = _field(default_factory=NavigationConfig)
    pointing: PointingConfig = _field(default_factory=PointingConfig)
    trajectory: TrajectoryConfig = _field(default_factory=TrajectoryConfig)
    control: ControlConfig = _field(default_factory=ControlConfig)
    vehicle: VehicleConfig = _field(default_factory=VehicleConfig)
    energy: EnergyConfig = _field(default_factory=EnergyConfig)
    replan: ReplanConfig = _field(default_factory=ReplanConfig)
    sim: SimConfig = _field(default_factory=SimConfig)
    description: str = ""
    base_dir: str = "."   # set by the loader: directory of the mission file
    source: str = "<mission>"   # set by the loader: the mission file (for error messages)

    def __post_init__(self) -> None:
        if (self.map is None) == (self.field is None):
            raise ValueError("give exactly one of 'map' (a map YAML) and 'field' (a GeoJSON or KML field)")
        if self.dem is not None and self.elevation_m is not None:
            raise ValueError("give at most one of 'dem' (an elevation model) and 'elevation_m' (a flat field)")
        if self.elevation_m is not None and not -MAX_ALTITUDE_M <= self.elevation_m <= MAX_ALTITUDE_M:
            raise ValueError(f"elevation_m {self.elevation_m} is outside [-{MAX_ALTITUDE_M:g}, {MAX_ALTITUDE_M:g}] m")
        if self.launch is not None and self.energy.launch_xy_m is not None:
            raise ValueError("give at most one of 'launch' and 'energy.launch_xy_m'")

    @property
    def map_path(self) -> Path:
        return Path(self.base_dir) / self.map

    @property
    def field_path(self) -> Path:
        return Path(self.base_dir) / self.field.file

    @property
    def dem_path(self) -> Path | None:
        """The DEM file, None for a flat field (no ``dem``)."""
        return None if self.dem is None else Path(self.base_dir) / self.dem
