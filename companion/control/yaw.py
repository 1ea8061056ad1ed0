r"""The yaw channel's gains, derived from the yaw authority and the gyro noise.

Why. A quadrotor yaws with the rotors' drag torque, ``c_tau`` times the
thrust difference of its two spin pairs: the paper's vehicle (c_tau = 0.8
mm, J_zz = 0.1377 kg m^2) has at hover

    a_yaw = 4 c_tau min(f/4, f_max - f/4) / J_zz = c_tau m g / J_zz = 0.247 rad/s^2

(``Mixer.yaw_torque_limit(m g) / J_zz``; one spin pair at zero thrust, the
other at twice hover). Roll and pitch have ~270 times more. The paper's
single damping alpha = 12 /s on every axis, acting on the raw gyro (the
paper's noise: variance 5e-4 per 250 Hz sample, 0.022 rad/s), asks the yaw
for ``alpha sigma`` = 0.27 rad/s^2 of pure noise, more than a_yaw, and rho2
= 50 /s^2 saturates at 5 mrad of yaw error: the yaw torque demand sat at the
mixer's limit on most frames and the motor pairs swung between 0 and 0.85
from one frame to the next (issue 17).

What. The yaw loop gets its own stiffness and damping (the thrust
direction's rho1 and alpha are untouched) and its damping acts on a
low-passed yaw rate. Linearised, with ``e = Omega_z - Omega_d,z``::

    psi_e_ddot = -rho_y psi_e - alpha_y e_f,     e_f = LPF(e, f_c)

1. The yaw rate through a first-order low-pass of corner ``f_c`` (Hz):
   white gyro noise of density ``n`` (rad/s/sqrt(Hz); per-sample std ``n
   sqrt(f_s)``) leaves ``sigma_f = n sqrt(pi f_c)`` (the filter's noise
   bandwidth is ``pi f_c / 2`` one-sided, ``pi f_c`` against a two-sided
   density).
2. The damping so that the noise's demand is a stated fraction ``k_n`` of
   the authority: ``alpha_y sigma_f = k_n a_yaw``, i.e. ``alpha_y = k_n
   a_yaw / sigma_f``, bounded by the tilt damping alpha (the yaw loop is
   never made faster than the tilt loop).
3. The stiffness from the damping ratio ``zeta``: ``rho_y = (alpha_y / (2
   zeta))^2`` (natural frequency ``omega_y = alpha_y / (2 zeta)``).

Defaults (``ControlConfig.yaw_*``): f_c = 5 Hz, k_n = 0.1, zeta = 0.8 on the
paper's vehicle and noise (n = 1.4e-3): sigma_f = 5.5e-3 rad/s, alpha_y =
4.46 /s, omega_y = 2.79 rad/s, rho_y = 7.77 /s^2. The noise then takes 10 %
of a_yaw at 1 sigma (30 % at 3 sigma), the pointing reference at most
``pointing_yaw_accel_fraction`` = 50 % (``companion.control.pointing``),
and 20 % is left for the errors. With the filter the loop is third order,
``s^3 + w_c s^2 + w_c alpha_y s + w_c rho_y`` (``w_c = 2 pi f_c``), stable
iff ``w_c alpha_y > rho_y`` (Routh): poles -26.5 and -2.47 +- 1.76j
(damping 0.81) with the defaults. PX4 low-passes the yaw torque setpoint
(``MC_YAW_TQ_CUTOFF``, default 2 Hz) and ArduCopter the yaw-rate error
(``ATC_RAT_YAW_FLTE``, 2.5 Hz) for the same reason: yaw is the weak axis
and the gyro's path to the motors.

Pure: no clock, no I/O; the filter takes the vehicle time.
"""

from __future__ import annotations

import math
from typing import NamedTuple


class YawGains(NamedTuple):
    """The yaw loop of :func:`yaw_gains`.

    Attributes
    ----------
    stiffness_1_s2 : float
        rho_y, the yaw error's weight (1/s^2): ``rho_y sin(psi_e)`` in z.
    damping_1_s : float
        alpha_y, the damping of the filtered yaw-rate error (1/s).
    cutoff_hz : float
        f_c, the yaw-rate low-pass corner (Hz).
    authority_rad_s2 : float
        a_yaw, the yaw acceleration the rotors can make at hover (rad/s^2).
    noise_std_rad_s : float
        sigma_f, the gyro noise left in the filtered yaw rate (rad/s).
    """

    stiffness_1_s2: float
    damping_1_s: float
    cutoff_hz: float
    authority_rad_s2: float
    noise_std_rad_s: float


def yaw_gains(authority_rad_s2: float, gyro_noise_rad_s_sqrt_hz: float, cutoff_hz: float,
              damping_ratio: float, noise_fraction: float, damping_max_1_s: float) -> YawGains:
    """Yaw stiffness and damping from the authority and the gyro noise (module docstring).

    Parameters
    ----------
    authority_rad_s2 : float
        a_yaw = largest yaw torque at hover / J_zz (rad/s^2), > 0.
    gyro_noise_rad_s_sqrt_hz : float
        White gyro noise density n (rad/s/sqrt(Hz)), > 0.
    cutoff_hz : float
        Corner f_c of the yaw-rate low-pass (Hz), > 0.
    damping_ratio : float
        zeta of the linearised yaw loop, > 0.
    noise_fraction : float
        k_n: 1-sigma noise demand ``alpha_y sigma_f`` as a fraction of a_yaw, in (0, 1).
    damping_max_1_s : float
        Upper bound of alpha_y (the tilt damping alpha), > 0.

    Returns
    -------
    YawGains

    Raises
    ------
    ValueError
        When the filtered loop would be unstable (``2 pi f_c alpha_y <= rho_y``, Routh).
    """
    sigma_f = gyro_noise_rad_s_sqrt_hz * math.sqrt(math.pi * cutoff_hz)
    alpha_y = min(noise_fraction * authority_rad_s2 / sigma_f, damping_max_1_s)
    omega_y = alpha_y / (2.0 * damping_ratio)
    rho_y = omega_y * omega_y
    if not 2.0 * math.pi * cutoff_hz * alpha_y > rho_y:
        raise ValueError(f"control.yaw_rate_cutoff_hz = {cutoff_hz:g} Hz is too low for a yaw loop of "
                         f"{omega_y:.3g} rad/s (unstable: needs 2 pi f_c > alpha_y / (4 zeta^2))")
    return YawGains(rho_y, alpha_y, float(cutoff_hz), float(authority_rad_s2), sigma_f)


class YawRateFilter:
    """First-order low-pass of the yaw rate on the vehicle clock (exact discretisation).

    ``y += (1 - exp(-dt / tau)) (x - y)``, ``tau = 1 / (2 pi f_c)``; the first
    sample initialises it; a repeated time stamp (``dt <= 0``) returns the
    previous output.

    Parameters
    ----------
    cutoff_hz : float
        Corner frequency f_c (Hz), > 0.
    """

    __slots__ = ("_w", "_t", "_y", "_dt", "_k")

    def __init__(self, cutoff_hz: float) -> None:
        if not cutoff_hz > 0:
            raise ValueError("YawRateFilter: cutoff_hz must be > 0")
        self._w = 2.0 * math.pi * float(cutoff_hz)
        self._t: float | None = None
        self._y = 0.0
        self._dt = -1.0
        self._k = 0.0

    def reset(self) -> None:
        self._t = None

    def step(self, t_s: float, x: float) -> float:
        """Advance to vehicle time ``t_s`` (s) with input ``x``; returns the filtered value."""
        t_prev = self._t
        if t_prev is None:
            self._t, self._y = t_s, x
            return x
        dt = t_s - t_prev
        if not dt > 0.0:
            return self._y
        if dt != self._dt:                 # the frame period rarely changes: keep its coefficient
            self._dt, self._k = dt, 1.0 - math.exp(-self._w * dt)
        self._t = t_s
        y = self._y + self._k * (x - self._y)
        self._y = y
        return y
