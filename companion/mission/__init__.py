"""Mission file: schema and loader."""

from .loader import load_mission
from .schema import CoverageConfig, FlightConfig, HomeConfig, Mission, PointingConfig
from .sim import NoiseConfig, ObstacleConfig, SimConfig

__all__ = [
    "load_mission", "Mission", "HomeConfig", "FlightConfig", "CoverageConfig",
    "PointingConfig", "SimConfig", "NoiseConfig", "ObstacleConfig",
]
