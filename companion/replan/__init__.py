"""Online re-planning around unknown obstacles (paper Section 2.3.3, issue 8):
perception from DISTANCE_SENSOR, the improved APF, rejoin and re-route."""

from mavcore.mission.replan import ReplanConfig, SensorMount
from .apf import ApfForce, ApfParams, apf_force, attractive_potential, repulsive_potential, total_potential
from .globalplan import GlobalPlan, Segment
from .knownmap import KnownMap
from .memory import ObstacleMemory
from .perception import BeamEvidence, Pose, PoseHistory, beam_evidence
from .rejoin import RejoinResult, rejoin
from .replanner import MODES, ReplanEvent, Replanner, ReplanStats, ReplanStep, mission_replan_config
from .reroute import RerouteResult, reroute
from .route3d import Route3D, RouteScene, find_route
from .routecheck import route_exists
from .voxmap import ObstacleMap
from .shaper import ReferenceShaper, ShapedState

__all__ = [
    "ReplanConfig", "SensorMount", "ApfForce", "ApfParams", "apf_force", "attractive_potential",
    "repulsive_potential", "total_potential", "GlobalPlan", "Segment", "KnownMap", "ObstacleMemory",
    "BeamEvidence", "Pose", "PoseHistory", "beam_evidence", "RejoinResult", "rejoin", "MODES",
    "ReplanEvent", "Replanner", "ReplanStats", "ReplanStep", "mission_replan_config", "RerouteResult", "reroute",
    "ReferenceShaper", "ShapedState", "ObstacleMap", "Route3D", "RouteScene", "find_route", "route_exists",
]
