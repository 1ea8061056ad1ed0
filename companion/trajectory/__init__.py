"""LQR trajectory generation (Section 2.3.2) and the pointing direction (eq. 21)."""

from .config import TrajectoryConfig
from .lqr import generate_trajectory
from .pointing import PointingDerivatives, pointing_derivatives, pointing_directions
from .sampling import Trajectory, TrajectorySample

__all__ = [
    "TrajectoryConfig",
    "generate_trajectory",
    "PointingDerivatives",
    "pointing_derivatives",
    "pointing_directions",
    "Trajectory",
    "TrajectorySample",
]
