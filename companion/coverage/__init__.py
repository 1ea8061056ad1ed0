"""ISOA coverage planning and way-point extraction (paper Section 2.2, 2.3.1)."""

from .plan import CoveragePlan, plan_coverage
from .rows import RowSpacing, detect_row_spacing
from .waypoints import Waypoints, extract_waypoints, waypoints_along

__all__ = ["CoveragePlan", "plan_coverage", "RowSpacing", "detect_row_spacing",
           "Waypoints", "extract_waypoints", "waypoints_along"]
