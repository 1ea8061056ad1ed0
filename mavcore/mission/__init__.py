"""Mission file: schema and loader."""

from .loader import load_mission
from .schema import CoverageConfig, FlightConfig, HomeConfig, Mission, PointingConfig
from .replan import ReplanConfig, SensorMount
from .sim import NoiseConfig, ObstacleConfig, SimConfig

__all__ = [
    "load_mission", "Mission", "HomeConfig", "FlightConfig", "CoverageConfig",
    "PointingConfig", "ReplanConfig", "SensorMount", "SimConfig", "NoiseConfig", "ObstacleConfig",
]
