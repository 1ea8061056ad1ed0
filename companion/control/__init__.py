"""Geometric SE(3) controller on vector measurements (paper Section 2.4.2) and mixer."""

from .config import ControlConfig
from .geometric import (
    ControlOutput,
    DecoupledTorque,
    DesiredAttitude,
    GeometricController,
    Measurements,
    Reference,
    attitude_torque,
    attitude_torque_decoupled,
    body_coordinates,
    desired_attitude,
    thrust_axis_estimate,
)
from .mixer import Mixer, MotorCommand
from .pointing import PointingGovernor, heading_derivatives
from .vectors import AccelerationEstimator, BodyVectorFilter, VectorPairs, measurement_vectors

__all__ = [
    "AccelerationEstimator",
    "BodyVectorFilter",
    "ControlConfig",
    "ControlOutput",
    "DecoupledTorque",
    "DesiredAttitude",
    "GeometricController",
    "Measurements",
    "Mixer",
    "MotorCommand",
    "PointingGovernor",
    "Reference",
    "VectorPairs",
    "attitude_torque",
    "attitude_torque_decoupled",
    "body_coordinates",
    "desired_attitude",
    "heading_derivatives",
    "measurement_vectors",
    "thrust_axis_estimate",
]
