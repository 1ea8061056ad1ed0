r"""The onboard stack's inner rate loop and thrust normalisation, for attitude-rate setpoints.

A companion that flies its own controller on PX4 (OFFBOARD with body rates)
or ArduPilot (GUIDED / GUIDED_NOGPS) sends SET_ATTITUDE_TARGET with the
attitude ignored: body rates and a collective thrust normalised to [0, 1].
The flight stack tracks the rates with its rate controller and turns the
thrust and the rate controller's torques into motor commands. This module
is that part of the SITL's stack (``docs/mavlink.md``, "Attitude-rate
setpoints"). Pure: no clock, no I/O; body FLU, SI units.

Rate loop (PX4 ``mc_rate_control``: a PID on the body rates; here the gains
are angular-acceleration gains, i.e. multiplied by the inertia, so they do
not depend on J)::

    e_W  = W_sp - W
    tau  = J (Kp e_W + Ki int(e_W)) + W x J W        (N m, body FLU)

With ``Ki = 0`` and the torque applied at once, each axis obeys ``W_dot =
Kp (W_sp - W)``: a first-order lag with time constant ``1 / Kp``
(``tests/test_rate_control.py`` checks the step response against it).

The yaw torque then goes through a first-order low-pass, PX4's
``MC_YAW_TQ_CUTOFF`` ("Low pass filter cutoff frequency for yaw torque
setpoint", default 2 Hz, ``mc_rate_control``): yaw is the weak axis (0.247
rad/s^2 at hover on the paper's vehicle) and ``Kp_z`` times the gyro noise
(8 x 0.022 rad/s = 0.18 rad/s^2 with the paper's noise) would otherwise
swing the spin pairs between zero and full every frame. With it the noise
asks for ``Kp_z n sqrt(pi f_c)`` = 0.028 rad/s^2 (n = 1.4e-3 rad/s/sqrt(Hz)),
and the yaw rate loop ``s^2 + w_c s + w_c Kp_z`` (w_c = 2 pi f_c) has
natural frequency 10.0 rad/s and damping 0.63.

Thrust (PX4's normalised thrust setpoint, linear in force once the motor
curve is compensated; ArduPilot's "throttle" with the thrust linearisation
of ``MOT_THST_EXPO``)::

    F = T * 4 f_max                                  (collective, N)
    t_i = f_i / f_max                                (relative thrust of rotor i, from the mixer)
    u_i = curve^-1(t_i)                              (motor signal)
    curve(u) = (1 - k) u + k u^2                     (PX4 THR_MDL_FAC = k; ArduPilot MOT_THST_EXPO)

The simulated motors are linear (``f_i = u_i f_max``, ``mavcore/vehicle.py``),
so ``k = 0`` (the default) is the correct setting for them; another value
shows the error a mis-set curve makes. The hover thrust the companion needs
to normalise its force is ``m g / (4 f_max)`` (the SITL's ``MPC_THR_HOVER``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mavcore.vehicle import GRAVITY_M_S2


@dataclass(frozen=True)
class RateLoopGains:
    """Gains of the rate loop, per body axis (x, y, z), as angular-acceleration gains.

    Attributes
    ----------
    kp : tuple (3,)
        Proportional gain (1/s): the time constant of an axis is ``1 / kp``.
        Roll/pitch 50 /s: three times the companion's attitude bandwidth
        (``rho1 / alpha`` = 16.7 /s with the default gains) and a quarter of the
        5 ms motor lag's corner (200 /s).
    ki : tuple (3,)
        Integral gain (1/s^2).
    int_limit_rad_s2 : float
        Bound on each axis of ``Ki int(e_W)`` (rad/s^2).
    yaw_torque_cutoff_hz : float
        Corner of the low-pass on the yaw torque (Hz), PX4's ``MC_YAW_TQ_CUTOFF``
        (module docstring); 0: no filter.
    """

    kp: tuple = (50.0, 50.0, 8.0)
    ki: tuple = (20.0, 20.0, 1.0)
    int_limit_rad_s2: float = 5.0
    yaw_torque_cutoff_hz: float = 2.0


class RateLoop:
    """PID on the body rates producing torques (see the module docstring).

    Parameters
    ----------
    inertia_kg_m2 : sequence (3,)
        Diagonal of J (kg m^2).
    gains : RateLoopGains
    """

    def __init__(self, inertia_kg_m2, gains: RateLoopGains = RateLoopGains()) -> None:
        self.J = tuple(float(j) for j in inertia_kg_m2)
        self.gains = gains
        self.reset()

    def reset(self) -> None:
        """Clear the integrator and the yaw torque filter (when the rate loop takes over)."""
        self._int = [0.0, 0.0, 0.0]
        self._yaw_acc = 0.0

    def update(self, omega_flu_rad_s, omega_sp_flu_rad_s, dt_s: float, landed: bool = False) -> tuple:
        """One step: the torque (N m, body FLU) for the measured and wanted rates.

        Parameters
        ----------
        omega_flu_rad_s, omega_sp_flu_rad_s : sequence (3,)
            Measured and wanted body rates (rad/s, FLU).
        dt_s : float
            Time since the previous step (s): the integrator's step.
        landed : bool
            On the ground: the integrator is held at zero (PX4 resets it).
        """
        g = self.gains
        lim = g.int_limit_rad_s2
        w = omega_flu_rad_s
        J = self.J
        acc = [0.0, 0.0, 0.0]
        for i in range(3):
            e = float(omega_sp_flu_rad_s[i]) - float(w[i])
            if landed:
                self._int[i] = 0.0
            else:
                x = self._int[i] + g.ki[i] * e * dt_s
                self._int[i] = -lim if x < -lim else (lim if x > lim else x)
            acc[i] = g.kp[i] * e + self._int[i]
        fc = g.yaw_torque_cutoff_hz
        if fc > 0.0:        # first-order low-pass, exact for a torque held over dt_s
            self._yaw_acc += (1.0 - math.exp(-2.0 * math.pi * fc * dt_s)) * (acc[2] - self._yaw_acc)
            acc[2] = self._yaw_acc
        wx, wy, wz = float(w[0]), float(w[1]), float(w[2])
        Jx, Jy, Jz = J
        return (Jx * acc[0] + (wy * Jz * wz - wz * Jy * wy),
                Jy * acc[1] + (wz * Jx * wx - wx * Jz * wz),
                Jz * acc[2] + (wx * Jy * wy - wy * Jx * wx))


def thrust_curve(u: float, k: float) -> float:
    """Relative thrust of a motor at signal ``u`` in [0, 1]: ``(1 - k) u + k u^2``.

    PX4's THR_MDL_FAC model ("thrust = (1 - factor) PWM + factor PWM^2",
    normalised); ArduPilot's MOT_THST_EXPO curve has the same form.
    """
    return (1.0 - k) * u + k * u * u


def thrust_curve_inverse(t: float, k: float) -> float:
    """The signal ``u`` in [0, 1] with ``thrust_curve(u, k) = t`` (t clipped to [0, 1]).

    ``u = (-(1 - k) + sqrt((1 - k)^2 + 4 k t)) / (2 k)`` for k > 0 (the root
    in [0, 1]), ``u = t`` for k = 0.
    """
    t = 0.0 if not t > 0.0 else (1.0 if t > 1.0 else t)
    if k <= 0.0 or t == 0.0:
        return t
    a = 1.0 - k
    # the same root written without the cancellation of -a + sqrt(...) at small k t
    return 2.0 * t / (a + math.sqrt(a * a + 4.0 * k * t))


def hover_thrust(vehicle) -> float:
    """The normalised thrust that holds the vehicle in hover: ``m g / (4 f_max)`` (MPC_THR_HOVER)."""
    return float(vehicle.mass_kg) * GRAVITY_M_S2 / (4.0 * float(vehicle.max_thrust_per_rotor_n))
