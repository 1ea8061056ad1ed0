"""Geometric SE(3) controller on vector measurements (paper Section 2.4.2) and mixer."""

from .config import ControlConfig
from .geometric import (
    ControlOutput,
    DesiredAttitude,
    GeometricController,
    Measurements,
    Reference,
    attitude_torque,
    desired_attitude,
    thrust_axis_estimate,
)
from .mixer import Mixer, MotorCommand
from .vectors import AccelerationEstimator, BodyVectorFilter, VectorPairs, measurement_vectors

__all__ = [
    "AccelerationEstimator",
    "BodyVectorFilter",
    "ControlConfig",
    "ControlOutput",
    "DesiredAttitude",
    "GeometricController",
    "Measurements",
    "Mixer",
    "MotorCommand",
    "Reference",
    "VectorPairs",
    "attitude_torque",
    "desired_attitude",
    "measurement_vectors",
    "thrust_axis_estimate",
]
