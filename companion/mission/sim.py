"""The ``sim:`` section of a mission: known to the SITL only, never to the planner.

Owned by the simulator (issue 3); the companion only parses it so that a
mission file is validated in one place.
"""

from __future__ import annotations

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

    def __post_init__(self) -> None:
        for name in ("vector_variance", "gyro_variance", "position_std_m", "velocity_std_m_s"):
            if getattr(self, name) < 0:
                raise ValueError(f"noise.{name} must be >= 0")


@dataclass(frozen=True)
class SimConfig:
    """Simulation-only settings of a mission."""

    obstacles: tuple[ObstacleConfig, ...] = ()
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    seed: int = 0
