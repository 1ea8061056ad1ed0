"""The safety guard (issue 15): every reference any mode proposes passes through
one 3-D check before it reaches the link (docs/replan.md "The guard")."""

from .guard import Guard, GuardConfig, Verdict
from .obstacles import known_obstacle_distance, points_distance
from .scene import SafetyScene, RowField, TerrainField
from .stopping import stopping_distance_m, stopping_speed_m_s

__all__ = ["Guard", "GuardConfig", "Verdict", "SafetyScene", "RowField", "TerrainField",
           "known_obstacle_distance", "points_distance", "stopping_distance_m", "stopping_speed_m_s"]
