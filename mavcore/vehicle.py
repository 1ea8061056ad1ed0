"""Physical vehicle description shared by the companion (control, mixer) and
the SITL (plant): mission key ``vehicle``.

Defaults are the paper's quadrotor (Section 3; Lee, Leok & McClamroch 2010):
m = 4.34 kg, J = diag(0.0820, 0.0845, 0.1377) kg m^2, arm 0.315 m, yaw torque
coefficient c_tau = 8.004e-4 m (yaw reaction torque = c_tau * thrust).

Rotor layout: quad-X in PX4's motor order (the order of
HIL_ACTUATOR_CONTROLS.controls[0..3]), positions in body FLU:

====  ============  ======================  ============
idx   where         (x, y) FLU              spin (above)
====  ============  ======================  ============
0     front-right   ( +a/sqrt2, -a/sqrt2)   CCW
1     rear-left     ( -a/sqrt2, +a/sqrt2)   CCW
2     front-left    ( +a/sqrt2, +a/sqrt2)   CW
3     rear-right    ( -a/sqrt2, -a/sqrt2)   CW
====  ============  ======================  ============

A rotor spinning CCW seen from above pushes the body clockwise, i.e. a yaw
torque of ``-c_tau * f_i`` about FLU +z; a CW rotor ``+c_tau * f_i``.
The normalised motor command is linear in thrust: ``f_i = cmd_i * max_thrust_per_rotor_n``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

GRAVITY_M_S2 = 9.81


@dataclass(frozen=True)
class VehicleConfig:
    mass_kg: float = 4.34
    inertia_kg_m2: tuple[float, float, float] = (0.0820, 0.0845, 0.1377)
    arm_m: float = 0.315
    torque_coeff_m: float = 8.004e-4
    max_thrust_per_rotor_n: float = 25.0
    motor_time_constant_s: float = 0.005

    def __post_init__(self) -> None:
        if self.mass_kg <= 0:
            raise ValueError("vehicle.mass_kg must be > 0")
        jx, jy, jz = self.inertia_kg_m2
        if min(jx, jy, jz) <= 0:
            raise ValueError("vehicle.inertia_kg_m2 must be positive")
        if jx > jy + jz or jy > jx + jz or jz > jx + jy:
            raise ValueError("vehicle.inertia_kg_m2 breaks the triangle inequality (not a rigid body)")
        if self.arm_m <= 0 or self.torque_coeff_m <= 0:
            raise ValueError("vehicle.arm_m and vehicle.torque_coeff_m must be > 0")
        if self.max_thrust_per_rotor_n * 4 <= self.mass_kg * GRAVITY_M_S2:
            raise ValueError("vehicle.max_thrust_per_rotor_n: four rotors cannot lift the vehicle")
        if self.motor_time_constant_s < 0:
            raise ValueError("vehicle.motor_time_constant_s must be >= 0")

    @property
    def J(self) -> np.ndarray:
        """Inertia matrix (3x3, kg m^2, body FLU)."""
        return np.diag(self.inertia_kg_m2)


ROTOR_SPIN = np.array([+1.0, +1.0, -1.0, -1.0])  # +1 CCW seen from above


def rotor_positions_flu(vehicle: VehicleConfig) -> np.ndarray:
    """Rotor centres (4, 3) in body FLU (m), PX4 quad-X order."""
    d = vehicle.arm_m / math.sqrt(2.0)
    return np.array([[d, -d, 0.0], [-d, d, 0.0], [d, d, 0.0], [-d, -d, 0.0]])


def allocation_matrix(vehicle: VehicleConfig) -> np.ndarray:
    """Map rotor thrusts (4,) N -> [f, tau_x, tau_y, tau_z] (N, N m, body FLU).

    Each rotor thrusts along body +z at r_i: tau = r_i x (0, 0, f_i) plus the
    yaw reaction ``-spin_i * c_tau * f_i``.
    """
    r = rotor_positions_flu(vehicle)
    A = np.empty((4, 4))
    A[0] = 1.0
    A[1] = r[:, 1]           # (r x f e3)_x = y f
    A[2] = -r[:, 0]          # (r x f e3)_y = -x f
    A[3] = -ROTOR_SPIN * vehicle.torque_coeff_m
    return A
