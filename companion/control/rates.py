r"""The geometric controller's outer part as attitude-rate setpoints (``--control rates``).

A flight stack that takes body rates and a collective thrust (PX4 OFFBOARD
with SET_ATTITUDE_TARGET rates, ArduPilot GUIDED / GUIDED_NOGPS) closes the
rate loop itself; the companion keeps the paper's position and attitude
laws and hands over at the angular velocity. Body FLU, SI units; the MAVLink
edge (``mavcore.codec.encode_set_attitude_rates``) turns FLU into FRD.

Rate command from the torque law (derivation in ``docs/control.md``)
--------------------------------------------------------------------
The torque laws of ``companion.control.geometric`` make the rate error obey
``e_Omega_dot = z - alpha e_Omega`` (eq. 35 and its decoupled analogue), with
``e_Omega = Omega - Omega_d^b`` (``Omega_d^b = Q Omega_d``, eq. 31's desired
rate in body axes; the paper's law uses ``Omega_d`` itself) and ``z`` the
attitude error of eq. (28) (``rho1 e3 x d + rho2 sin(psi_e) e3`` for the
decoupled law). Its slow manifold, ``e_Omega_dot = 0``, is the rate command::

    Omega_c = Omega_d^b + z / alpha

An inner loop that holds ``Omega = Omega_c`` gives the attitude Lyapunov
function ``V_att = rho1 (1 - d_z) + rho2 (1 - cos psi_e)`` the derivative
``V_att_dot = -e_Omega . z = -|z|^2 / alpha <= 0`` (the same identity as
eq. 41's proof). For a small tilt error theta the attitude is then first
order with rate ``rho1 / alpha`` (16.7 /s with the defaults) and the yaw
``rho_y / alpha_y`` (1.74 /s, the decoupled law's yaw gains,
``companion.control.yaw``; its yaw-rate command has no gyro term): the
flight stack's rate loop must be several times faster (the SITL's 50 /s on
roll and pitch, 8 /s on yaw, ``sitl.rate_control``).

Thrust
------
The collective force ``f = F_d . R e3`` (eq. 23 projected on the body axis,
N) becomes the normalised thrust of the stacks::

    T = T_hover f / (m g)        clipped to [0, 1]

``T_hover`` is the stack's hover thrust (PX4 ``MPC_THR_HOVER``, ArduPilot
``MOT_THST_HOVER``): both stacks treat T as linear in force once their motor
curve (``THR_MDL_FAC``, ``MOT_THST_EXPO``) linearises the motors, so hover
thrust is the only scale needed. The companion reads ``MPC_THR_HOVER`` from
the vehicle; without it, ``m g / (4 f_max)`` of the vehicle model.
"""

from __future__ import annotations

from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig


def rate_command(omega_d_body_rad_s, z_rad_s2, alpha_1_s: float) -> tuple:
    """``Omega_c = Omega_d^b + z / alpha`` (module docstring).

    Parameters
    ----------
    omega_d_body_rad_s : sequence (3,)
        Desired angular velocity in body axes (rad/s, FLU).
    z_rad_s2 : sequence (3,)
        Attitude error term of the torque law (1/s^2, body).
    alpha_1_s : float
        Rate damping alpha of the torque law (1/s), > 0.

    Returns
    -------
    tuple (3,)
        Body-rate command (rad/s, FLU).
    """
    k = 1.0 / alpha_1_s
    return (omega_d_body_rad_s[0] + k * z_rad_s2[0], omega_d_body_rad_s[1] + k * z_rad_s2[1],
            omega_d_body_rad_s[2] + k * z_rad_s2[2])


def vehicle_hover_thrust(vehicle: VehicleConfig) -> float:
    """Hover thrust of the vehicle model, normalised: ``m g / (4 f_max)``."""
    return float(vehicle.mass_kg) * GRAVITY_M_S2 / (4.0 * float(vehicle.max_thrust_per_rotor_n))


def normalised_thrust(f_n: float, mass_kg: float, hover_thrust: float) -> float:
    """``T = T_hover f / (m g)`` clipped to [0, 1] (module docstring).

    Parameters
    ----------
    f_n : float
        Collective thrust (N).
    mass_kg : float
        Vehicle mass (kg).
    hover_thrust : float
        Normalised thrust of hover, in (0, 1].
    """
    t = hover_thrust * f_n / (mass_kg * GRAVITY_M_S2)
    return 0.0 if not t > 0.0 else (1.0 if t > 1.0 else t)
