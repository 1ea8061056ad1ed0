"""LQR trajectory weights (mission key ``trajectory``).

Placeholder defaults; owned by the trajectory module (issue 2).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TrajectoryConfig:
    """Diagonal weights of the paper's cost (eq. 4), per axis (same on x, y, z).

    S: way-point output weights on position, velocity, acceleration.
    Q: running state weights on p, v, a, jerk. R: running weight on snap.
    """

    s_position: float = 1.0e4
    s_velocity: float = 1.0e2
    s_acceleration: float = 1.0e1
    q_position: float = 0.0
    q_velocity: float = 0.0
    q_acceleration: float = 0.0
    q_jerk: float = 0.0
    r_snap: float = 1.0
