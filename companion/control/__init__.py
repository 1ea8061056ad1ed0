"""Geometric SE(3) controller on vector measurements (paper Section 2.4.2), its attitude observer and mixer."""

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
from .observer import (
    AttitudeEstimate,
    VelocityAidedObserver,
    VirtualPairs,
    heading_from_accel_mag,
    triad_rotation,
    virtual_pairs,
)
from .pointing import PointingGovernor, heading_derivatives
from .vectors import AccelerationEstimator, BodyVectorFilter, VectorPairs, controller_vectors, measurement_vectors

__all__ = [
    "AccelerationEstimator",
    "AttitudeEstimate",
    "BodyVectorFilter",
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
    "VelocityAidedObserver",
    "VirtualPairs",
    "attitude_torque",
    "attitude_torque_decoupled",
    "body_coordinates",
    "controller_vectors",
    "desired_attitude",
    "heading_derivatives",
    "heading_from_accel_mag",
    "measurement_vectors",
    "thrust_axis_estimate",
    "triad_rotation",
    "virtual_pairs",
]
