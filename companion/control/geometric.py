r"""Geometric SE(3) tracking controller on vector measurements (paper Section 2.4.2).

World ENU, body FLU, z up (e3 = [0, 0, 1]); ``R`` maps body to world. Plant,
eq. (20): ``x_dot = v``, ``m v_dot = f R e3 - m g e3``, ``R_dot = R S(Omega)``,
``J Omega_dot = -Omega x J Omega + tau``.

Thrust and desired attitude (eqs. 21-26)
-----------------------------------------
``F_d = -kx e_x - kv e_v + m (g e3 + a_d)``, ``b3d = F_d/|F_d|`` (eq. 23);
pointing ``s = (S_p - x_d)/|S_p - x_d|`` (eq. 21), ``sc = unit(s - (s.b3d)
b3d)`` (eq. 22), ``b2d = sc``, ``b1d = b2d x b3d``, ``R_d = [b1d, b2d,
b3d]``. Thrust ``f = F_d . (R e3)`` with ``R e3`` estimated from the two
vector pairs (TRIAD, primary pair the specific force), never the true attitude.
Safety invariant (not in the paper): before the normalisation F_d is limited
to a tilt cone and a vertical floor (``companion.control.tilt``,
``ControlConfig.tilt_max_deg`` and ``vertical_thrust_min_fraction``); b3d,
f and Omega_d then follow the limited vector, bit for bit unchanged where no
limit is active.

Desired angular velocity (eq. 31), analytic
--------------------------------------------
``Omega_d = vee(R_d^T R_d_dot) = (b3d.b2d_dot, b1d.b3d_dot, b2d.b1d_dot)`` and
its derivative from the first and second derivatives of ``b3d`` and ``sc``,
with, for ``n = u/|u|``: ``n_dot = (I - n n^T) u_dot/|u|`` and ``n_ddot =
(u_ddot - 2 n_dot (n.u_dot) - n (n_dot.u_dot + n.u_ddot))/|u|``. Scheme for
the derivatives of F_d: ``e_x_dot = e_v``; ``e_v_dot = a_hat - a_d`` with
``a_hat`` the measured acceleration (differentiated velocity); ``a_d_dot =
jerk``; for the second derivative, the unmeasurable ``e_v_ddot`` is taken
from the ideal closed loop ``m e_v_dot = -kx e_x - kv e_v - ki e_i + d``
(d a constant disturbance) differentiated, ``e_v_ddot = -(kx e_v + kv
e_v_dot + ki e_i_dot)/m``, and ``a_d_ddot = snap``; the integral adds ``-ki
e_i_dot`` to F_d_dot and ``-ki e_i_ddot`` to F_d_ddot. Of ``s``:
``u = S_p - x_d``, ``u_dot = -v_d``, ``u_ddot = -a_d``.

Torque (eq. 27) with the signs restored
----------------------------------------
Measurements ``b_i = R^T r_i`` (body) of known world directions ``r_i``;
desired ``b_i^d = R_d^T r_i``; ``z_rho = sum rho_i b_i^d x b_i`` (eq. 28),
``e_Omega1 = Omega - Omega_d`` (29), ``e_Omega2 = Omega_d x Omega`` (30).
The law is::

    tau = Omega x J Omega + J Omega_d_dot + J z_rho - alpha J e_Omega1 - J e_Omega2

i.e. ``e_Omega1_dot = z_rho - alpha e_Omega1 - e_Omega2``. Derivation: with
``R_e = R R_d^T``, ``R_e_dot = R S(e_Omega1) R_d^T = R_e S(R_d e_Omega1)``,
so ``omega_bar = R_d e_Omega1`` (a world-frame vector, expressed through
R_d not R) is the body-type rate of R_e and its quaternion obeys eq. (34),
``q_e_dot = 1/2 (q0e I + S(q_e)) omega_bar``. Differentiating,
``omega_bar_dot = R_d (Omega_d x e_Omega1 + e_Omega1_dot) = R_d (e_Omega2 +
e_Omega1_dot)`` because ``Omega_d x (Omega - Omega_d) = Omega_d x Omega``;
the law above gives eq. (37), ``omega_bar_dot = -alpha omega_bar + R_d z_rho``
(the ``-J e_Omega2`` term cancels the frame rotation). Since ``r^T R_e r =
b.b^d = 1 - 2 |q_e x r|^2`` for unit r, ``2 q_e^T W_rho q_e = sum rho_i (1 -
b_i . b_i^d)`` with ``W_rho = -sum rho_i S(r_i)^2``, so the Lyapunov function
(38) is, without quaternions,

    V = sum rho_i (1 - b_i . b_i^d) + 1/2 |e_Omega1|^2       (|omega_bar| = |e_Omega1|)

For constant r_i, ``d/dt (b_i . b_i^d) = e_Omega1 . (b_i^d x b_i)``, so
``V_dot = -e_Omega1 . z_rho + e_Omega1 . (z_rho - alpha e_Omega1 - e_Omega2)
= -alpha |e_Omega1|^2`` (e_Omega2 is orthogonal to e_Omega1): eq. (41). The
sign of the e_Omega2 term does not change V_dot, only the minus sign makes
eq. (37) hold. Time-varying r_1 (the specific force turns with the
acceleration) adds ``sum rho_i r_i_dot . (R_e^T ...)`` terms, small at the
low accelerations of coverage flight.

What the controller uses by default (``ControlConfig.attitude_law``)
-------------------------------------------------------------------
The law above acts on ``R_e = R R_d^T`` through ``R_d``. With the specific
force as vector 1, ``r_1 = R e3`` turns with the body, and ``z_1 = rho_1
(R_d^T R e3) x e3`` is the tilt error in desired-frame axes: a yaw error psi
rotates the roll/pitch correction by psi. This vehicle's yaw saturates at
0.25 rad/s^2, so when the pointing of eq. (21) swings fast (passing 1.25 m
from S_p at 1 m/s) the yaw lags by ~40 deg, the tilt loop loses its damping
(stiffness ``rho1 e^{i psi}`` against alpha) and the position took 100 mm
spikes. By default the torque is therefore :func:`attitude_torque_decoupled`:
the same gains, every term in the body frame, the thrust direction
controlled independently of the yaw error (decoupled-yaw geometric control,
Gamagedara et al. 2019), ``Omega_d`` moved into the body frame with ``R^T
R_d`` obtained from the vector pairs. ``attitude_law = "paper"`` keeps the
law above. Separately, the pointing reference is made flyable
(``companion.control.pointing``: eq. 21 exactly where the vehicle can
follow it, yaw-rate/acceleration limited elsewhere).

The yaw channel of the decoupled law has its own gains (``companion.control.yaw``,
issue 17): the paper's single alpha = 12 on the raw gyro asked the yaw for more
noise (0.27 rad/s^2) than the rotors can make (0.247), so the yaw damping
``alpha_y`` acts on a low-passed yaw rate and is sized so that the gyro noise
takes a stated fraction of the authority, and the yaw stiffness ``rho_y``
follows from a damping ratio; roll and pitch keep rho1 and alpha
(``docs/control.md``, "The yaw channel").

Where the vector pairs come from (``ControlConfig.vectors``, ``velocity_aided``, ``observer``)
--------------------------------------------------------------------------------------------
By default (``observer``) from the attitude observer of
``companion.control.observer``: a velocity-aided complementary filter on
SO(3) with gyro-bias estimation and a translational filter. The law then
acts on the virtual pairs ``b_1 = R_hat^T e3``, ``b_2 = R_hat^T h`` (``h``
the horizontal Earth field) against ``r_1 = e3``, ``r_2 = h``, on the
bias-corrected gyro, and on the filtered position and velocity at the
frame's time (e_x, e_v, and a_hat for F_dot: the filter's velocity
differentiated as below). The observer's inputs are the same raw
measurements; it never sees the true attitude. Without the observer the
pairs are the measured vectors (``vectors.controller_vectors``):

- ``vectors = "paper"`` (the paper's sensor model, ``sim.vector_sensors:
  paper``): the accelerometer fields carry ``g R^T e3``, so ``r_1 = e3``;
  with ``velocity_aided`` the tilt comes instead from the velocity (``b_1 =
  e3``, the thrust axis of eq. 20's plant, against ``unit(a_hat + g e3)``);
- ``vectors = "physical"`` (a real IMU): as described next.

The two measured vectors and how their world directions are known
-----------------------------------------------------------------
(details in ``companion.control.vectors``) b_1: the accelerometer's specific
force, against ``r_1 = unit(a_hat + g e3)`` with ``a_hat`` the vehicle's
acceleration from the measured velocity differentiated on the vehicle clock
(its half-frame lag advanced by the reference jerk); b_2: the magnetometer,
against the configured Earth field ``ControlConfig.mag_field_enu_gauss``, by
default both taken normal to the specific force (decouples yaw from tilt).
Optional filters: a slow body-frame low-pass on b_1 (constant for a
drag-free multirotor) and a gyro-propagated complementary filter on b_2.
With the filters off and the raw field, this is the paper's law on raw
vectors.

With noisy velocity fixes (1 cm/s and more) the differentiated velocity
leaves its noise in ``r_1`` and in ``Omega_d``: the previous default
diverged at 1 cm/s; the observer keeps millimetres (``tests/test_observer.py``).

Everything here is pure: the controller object holds only filter state and
takes the vehicle's time as an argument. One path: ``GeometricController.command``
(the 250 Hz path, motor commands) composes the pieces below on float
tuples (:func:`desired_frame`, :func:`decoupled_law`, the TRIAD helpers of
``mavcore.so3``); ``update`` adds the named ``ControlOutput``.
:func:`desired_attitude` and :func:`attitude_torque_decoupled` are the same
pieces with named results. ``tests/test_control_fast.py`` checks the path
against a plain composition of eqs. (21)-(31) written in the test
(``python benchmarks/bench_control.py --timing`` times it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig
from mavcore.mission.control import ControlConfig
from .mixer import Mixer
from .pointing import PointingGovernor
from .rates import rate_command
from .tilt import limit_thrust
from .observer import AttitudeEstimate, VelocityAidedObserver, horizontal_field, virtual_pairs
from mavcore.so3 import (Vec3, body_coordinates, cross, dot, thrust_axis_estimate, triad_body_z, triad_frames,
                         triad_rotation, triad_to_body3, unit3, unit_d2)
from .vectors import AccelerationEstimator, BodyVectorFilter, controller_vectors
from .yaw import YawGains, YawRateFilter, yaw_gains

# --- small float-tuple vector algebra (the hot path avoids numpy) ---------


_ZERO = (0.0, 0.0, 0.0)
_E3 = (0.0, 0.0, 1.0)


# --- named inputs and outputs ----------------------------------------------


class Measurements(NamedTuple):
    """What the vehicle sends (HIGHRES_IMU, LOCAL_POSITION_NED), converted to ENU/FLU.

    A named tuple (built every frame: cheaper than a dataclass).

    Attributes
    ----------
    gyro_flu_rad_s : sequence (3,)
        Angular velocity Omega, body FLU, rad/s.
    accel_flu_m_s2 : sequence (3,)
        Accelerometer specific force, body FLU, m/s^2.
    mag_flu_gauss : sequence (3,)
        Magnetometer, body FLU, gauss.
    pos_enu_m : sequence (3,)
        Position, world ENU, m.
    vel_enu_m_s : sequence (3,)
        Velocity, world ENU, m/s.
    nav_time_s : float or None
        Vehicle time stamp (s) of the position/velocity sample (its
        LOCAL_POSITION_NED ``time_boot_ms``), when it differs from the IMU's;
        None: the same as the ``t_s`` given to ``update``.
    """

    gyro_flu_rad_s: tuple
    accel_flu_m_s2: tuple
    mag_flu_gauss: tuple
    pos_enu_m: tuple
    vel_enu_m_s: tuple
    nav_time_s: float | None = None


class Reference(NamedTuple):
    """One sample of the reference trajectory, world ENU (a named tuple, as ``Measurements``).

    Attributes
    ----------
    pos_enu_m, vel_enu_m_s, acc_enu_m_s2, jerk_enu_m_s3, snap_enu_m_s4 : sequence (3,)
        x_d and its first four derivatives (m, m/s, ..., m/s^4).
    target_enu_m : sequence (3,) or None
        Pointing target S_p (eq. 21); None: the controller's.
    """

    pos_enu_m: tuple
    vel_enu_m_s: tuple = (0.0, 0.0, 0.0)
    acc_enu_m_s2: tuple = (0.0, 0.0, 0.0)
    jerk_enu_m_s3: tuple = (0.0, 0.0, 0.0)
    snap_enu_m_s4: tuple = (0.0, 0.0, 0.0)
    target_enu_m: tuple | None = None


@dataclass(frozen=True, slots=True)
class DesiredAttitude:
    """R_d = [b1d, b2d, b3d] (columns, body -> world) with Omega_d and its derivative.

    Attributes
    ----------
    R_d : tuple of 3 rows (3x3)
        Desired attitude, ``R_d[i][j]`` = component i of column b_{j+1}d.
    b1d, b2d, b3d : tuple (3,)
        Columns of R_d, world ENU.
    Omega_d, Omega_d_dot : tuple (3,)
        vee(R_d^T R_d_dot) (rad/s) and its time derivative (rad/s^2), desired body frame.
    """

    R_d: tuple
    b1d: Vec3
    b2d: Vec3
    b3d: Vec3
    Omega_d: Vec3
    Omega_d_dot: Vec3


@dataclass(frozen=True, slots=True)
class ControlOutput:
    """One controller step.

    Attributes
    ----------
    f_n : float
        Collective thrust demand f (N), before the mixer.
    tau_flu_nm : tuple (3,)
        Torque demand (N m, body FLU), before the mixer.
    motor_cmd : tuple (4,)
        Normalised motor commands in [0, 1], PX4 quad-X order (after the mixer).
    saturated : bool
        The mixer had to modify the demand.
    b3d, b2d : tuple (3,)
        Desired thrust and pointing directions (world ENU).
    R_d : tuple of 3 rows (3x3)
        Desired attitude.
    Omega_d : tuple (3,)
        Desired angular velocity (rad/s, desired body frame).
    e_x, e_v : tuple (3,)
        Position (m) and velocity (m/s) errors, world ENU.
    z_rho : tuple (3,)
        Attitude error of eq. (28) (1/s^2, body).
    V : float
        Lyapunov function (38) from the measurements, ``sum rho_i (1 - b_i .
        b_i^d) + |e_Omega1|^2 / 2``.
    rate_cmd_flu_rad_s : tuple (3,)
        Body-rate command of ``--control rates`` (rad/s, FLU):
        ``Omega_d^b + z / alpha`` (``companion.control.rates``).
    """

    f_n: float
    tau_flu_nm: Vec3
    motor_cmd: tuple
    saturated: bool
    b3d: Vec3
    b2d: Vec3
    R_d: tuple
    Omega_d: Vec3
    e_x: Vec3
    e_v: Vec3
    z_rho: Vec3
    V: float
    rate_cmd_flu_rad_s: Vec3 = _ZERO


# --- pure pieces --------------------------------------------------------------


def desired_attitude(F, F_dot, F_ddot, u_s, u_s_dot, u_s_ddot, b2_fallback=(0.0, 1.0, 0.0)) -> DesiredAttitude:
    """R_d, Omega_d and Omega_d_dot from the thrust vector and the pointing vector.

    Parameters
    ----------
    F, F_dot, F_ddot : sequence (3,)
        Desired thrust vector F_d of eq. (23) (N, world ENU) and its first two
        time derivatives.
    u_s, u_s_dot, u_s_ddot : sequence (3,)
        Unnormalised pointing vector ``S_p - x_d`` (eq. 21, m) and its first
        two derivatives (``-v_d``, ``-a_d``).
    b2_fallback : sequence (3,)
        Pointing direction used, with zero derivatives, where eq. (21) or (22)
        is undefined (at the target, or pointing along the thrust); the
        controller passes its previous b2d.

    Returns
    -------
    DesiredAttitude
        eqs. (21)-(26) and (31); Omega_d_dot analytic (module docstring).
    """
    b1, b2, b3, Od, Odd = desired_frame(F, F_dot, F_ddot, u_s, u_s_dot, u_s_ddot, b2_fallback)
    R_d = ((b1[0], b2[0], b3[0]), (b1[1], b2[1], b3[1]), (b1[2], b2[2], b3[2]))
    return DesiredAttitude(R_d, b1, b2, b3, Od, Odd)


def desired_frame(F, F_dot, F_ddot, u_s, u_s_dot, u_s_ddot, b2_fallback) -> tuple:
    """:func:`desired_attitude` as plain tuples: ``(b1d, b2d, b3d, Omega_d, Omega_d_dot)``.

    The arithmetic of eqs. (21)-(26), (31) on float locals (``unit_d2``
    written out for b3d, s and b2d, then ``b1d = b2d x b3d``): the
    controller's per-frame path. Where eq. (21) or (22) is undefined it
    continues with the fallbacks of :func:`desired_attitude`.
    """
    sqrt = math.sqrt
    F0, F1, F2 = F
    Fd0, Fd1, Fd2 = F_dot
    Fdd0, Fdd1, Fdd2 = F_ddot
    if F0 * F0 + F1 * F1 + F2 * F2 < 1e-12:   # free fall demanded: no thrust direction, keep level
        F0, F1, F2, Fd0, Fd1, Fd2, Fdd0, Fdd1, Fdd2 = 0.0, 0.0, 1e-6, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    # b3 = unit_d2(F, F_dot, F_ddot)
    r = sqrt(F0 * F0 + F1 * F1 + F2 * F2)
    b3x, b3y, b3z = F0 / r, F1 / r, F2 / r
    rd = b3x * Fd0 + b3y * Fd1 + b3z * Fd2
    b3dx, b3dy, b3dz = (Fd0 - b3x * rd) / r, (Fd1 - b3y * rd) / r, (Fd2 - b3z * rd) / r
    rdd = b3dx * Fd0 + b3dy * Fd1 + b3dz * Fd2 + b3x * Fdd0 + b3y * Fdd1 + b3z * Fdd2
    b3ddx = (Fdd0 - 2.0 * b3dx * rd - b3x * rdd) / r
    b3ddy = (Fdd1 - 2.0 * b3dy * rd - b3y * rdd) / r
    b3ddz = (Fdd2 - 2.0 * b3dz * rd - b3z * rdd) / r
    u0, u1, u2 = u_s
    uu = u0 * u0 + u1 * u1 + u2 * u2
    if uu > 1e-12:
        # s = unit_d2(u_s, u_s_dot, u_s_ddot)
        ud0, ud1, ud2 = u_s_dot
        udd0, udd1, udd2 = u_s_ddot
        r = sqrt(uu)
        s0, s1, s2 = u0 / r, u1 / r, u2 / r
        rd = s0 * ud0 + s1 * ud1 + s2 * ud2
        sd0, sd1, sd2 = (ud0 - s0 * rd) / r, (ud1 - s1 * rd) / r, (ud2 - s2 * rd) / r
        rdd = sd0 * ud0 + sd1 * ud1 + sd2 * ud2 + s0 * udd0 + s1 * udd1 + s2 * udd2
        sdd0 = (udd0 - 2.0 * sd0 * rd - s0 * rdd) / r
        sdd1 = (udd1 - 2.0 * sd1 * rd - s1 * rdd) / r
        sdd2 = (udd2 - 2.0 * sd2 * rd - s2 * rdd) / r
    else:
        s0, s1, s2 = b2_fallback
        sd0 = sd1 = sd2 = sdd0 = sdd1 = sdd2 = 0.0
    # w = s - (s.b3) b3 (eq. 22) and its derivatives
    c = s0 * b3x + s1 * b3y + s2 * b3z
    cd = (sd0 * b3x + sd1 * b3y + sd2 * b3z) + (s0 * b3dx + s1 * b3dy + s2 * b3dz)
    cdd = ((sdd0 * b3x + sdd1 * b3y + sdd2 * b3z) + 2.0 * (sd0 * b3dx + sd1 * b3dy + sd2 * b3dz)
           + (s0 * b3ddx + s1 * b3ddy + s2 * b3ddz))
    w0, w1, w2 = s0 - c * b3x, s1 - c * b3y, s2 - c * b3z
    if w0 * w0 + w1 * w1 + w2 * w2 < 1e-12:   # s along b3d: keep the previous pointing, frozen
        f0, f1, f2 = b2_fallback
        c = f0 * b3x + f1 * b3y + f2 * b3z
        w0, w1, w2 = f0 - c * b3x, f1 - c * b3y, f2 - c * b3z
        wd0 = wd1 = wd2 = wdd0 = wdd1 = wdd2 = 0.0
        if w0 * w0 + w1 * w1 + w2 * w2 < 1e-12:
            w0, w1, w2 = cross((b3x, b3y, b3z), (1.0, 0.0, 0.0) if abs(b3x) < 0.9 else (0.0, 1.0, 0.0))
    else:
        wd0, wd1, wd2 = sd0 - cd * b3x - c * b3dx, sd1 - cd * b3y - c * b3dy, sd2 - cd * b3z - c * b3dz
        wdd0 = sdd0 - cdd * b3x - 2.0 * cd * b3dx - c * b3ddx
        wdd1 = sdd1 - cdd * b3y - 2.0 * cd * b3dy - c * b3ddy
        wdd2 = sdd2 - cdd * b3z - 2.0 * cd * b3dz - c * b3ddz
    # b2 = unit_d2(w, w_dot, w_ddot)
    r = sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    b2x, b2y, b2z = w0 / r, w1 / r, w2 / r
    rd = b2x * wd0 + b2y * wd1 + b2z * wd2
    b2dx, b2dy, b2dz = (wd0 - b2x * rd) / r, (wd1 - b2y * rd) / r, (wd2 - b2z * rd) / r
    rdd = b2dx * wd0 + b2dy * wd1 + b2dz * wd2 + b2x * wdd0 + b2y * wdd1 + b2z * wdd2
    b2ddx = (wdd0 - 2.0 * b2dx * rd - b2x * rdd) / r
    b2ddy = (wdd1 - 2.0 * b2dy * rd - b2y * rdd) / r
    b2ddz = (wdd2 - 2.0 * b2dz * rd - b2z * rdd) / r
    # b1 = b2 x b3 and its derivatives
    b1x, b1y, b1z = b2y * b3z - b2z * b3y, b2z * b3x - b2x * b3z, b2x * b3y - b2y * b3x
    b1dx = (b2dy * b3z - b2dz * b3y) + (b2y * b3dz - b2z * b3dy)
    b1dy = (b2dz * b3x - b2dx * b3z) + (b2z * b3dx - b2x * b3dz)
    b1dz = (b2dx * b3y - b2dy * b3x) + (b2x * b3dy - b2y * b3dx)
    b1ddx = (b2ddy * b3z - b2ddz * b3y) + 2.0 * (b2dy * b3dz - b2dz * b3dy) + (b2y * b3ddz - b2z * b3ddy)
    b1ddy = (b2ddz * b3x - b2ddx * b3z) + 2.0 * (b2dz * b3dx - b2dx * b3dz) + (b2z * b3ddx - b2x * b3ddz)
    b1ddz = (b2ddx * b3y - b2ddy * b3x) + 2.0 * (b2dx * b3dy - b2dy * b3dx) + (b2x * b3ddy - b2y * b3ddx)
    # Omega_d = vee(R_d^T R_d_dot) and its derivative (eq. 31)
    Od = (b3x * b2dx + b3y * b2dy + b3z * b2dz, b1x * b3dx + b1y * b3dy + b1z * b3dz,
          b2x * b1dx + b2y * b1dy + b2z * b1dz)
    Odd = ((b3dx * b2dx + b3dy * b2dy + b3dz * b2dz) + (b3x * b2ddx + b3y * b2ddy + b3z * b2ddz),
           (b1dx * b3dx + b1dy * b3dy + b1dz * b3dz) + (b1x * b3ddx + b1y * b3ddy + b1z * b3ddz),
           (b2dx * b1dx + b2dy * b1dy + b2dz * b1dz) + (b2x * b1ddx + b2y * b1ddy + b2z * b1ddz))
    return (b1x, b1y, b1z), (b2x, b2y, b2z), (b3x, b3y, b3z), Od, Odd


def attitude_torque(inertia_kg_m2, Omega, Omega_d, Omega_d_dot, b_meas, r_world,
                    b1d, b2d, b3d, rho, alpha: float):
    """The attitude law (27)-(30) with the signs derived in the module docstring.

    Parameters
    ----------
    inertia_kg_m2 : sequence (3,)
        Diagonal of J (kg m^2, body).
    Omega, Omega_d, Omega_d_dot : sequence (3,)
        Measured and desired angular velocity (rad/s), desired angular acceleration (rad/s^2).
    b_meas : sequence of (3,)
        Measured body unit vectors b_i.
    r_world : sequence of (3,)
        Their world directions r_i.
    b1d, b2d, b3d : sequence (3,)
        Columns of R_d (world); ``b_i^d = R_d^T r_i``.
    rho : sequence of float
        Weights rho_i (1/s^2).
    alpha : float
        Damping (1/s).

    Returns
    -------
    tau : tuple (3,)
        Torque (N m, body).
    z_rho : tuple (3,)
        eq. (28).
    V : float
        Lyapunov function (38) in the measured form of the module docstring.
    """
    zx = zy = zz = 0.0
    V = 0.0
    for b, r, k in zip(b_meas, r_world, rho):
        bd = (dot(b1d, r), dot(b2d, r), dot(b3d, r))   # R_d^T r_i
        zx += k * (bd[1] * b[2] - bd[2] * b[1])
        zy += k * (bd[2] * b[0] - bd[0] * b[2])
        zz += k * (bd[0] * b[1] - bd[1] * b[0])
        V += k * (1.0 - dot(b, bd))
    Jx, Jy, Jz = inertia_kg_m2
    wx, wy, wz = Omega
    dx, dy, dz = Omega_d
    e1 = (wx - dx, wy - dy, wz - dz)
    e2 = (dy * wz - dz * wy, dz * wx - dx * wz, dx * wy - dy * wx)   # Omega_d x Omega
    Jw = (Jx * wx, Jy * wy, Jz * wz)
    gyro = (wy * Jw[2] - wz * Jw[1], wz * Jw[0] - wx * Jw[2], wx * Jw[1] - wy * Jw[0])
    z = (zx, zy, zz)
    tau = tuple(gyro[i] + inertia_kg_m2[i] * (Omega_d_dot[i] + z[i] - alpha * e1[i] - e2[i])
                for i in range(3))
    V += 0.5 * dot(e1, e1)
    return tau, z, V


@dataclass(frozen=True, slots=True)
class DecoupledTorque:
    """Output of :func:`attitude_torque_decoupled`.

    Attributes
    ----------
    tau : tuple (3,)
        Torque (N m, body FLU).
    z : tuple (3,)
        Attitude error term (1/s^2, body): ``rho1 (e3 x d) + rho2 sin(psi_e) e3``.
    e_Omega : tuple (3,)
        ``Omega - Q Omega_d`` (rad/s, body).
    tilt_rad : float
        Angle between the body thrust axis and b3d.
    yaw_err_rad : float
        psi_e, the rotation about the body z axis left after the tilt.
    V : float
        ``rho1 (1 - d_z) + rho2 (1 - cos psi_e) + |e_Omega|^2 / 2``.
    """

    tau: Vec3
    z: Vec3
    e_Omega: Vec3
    tilt_rad: float
    yaw_err_rad: float
    V: float


def attitude_torque_decoupled(inertia_kg_m2, Omega, Omega_d, Omega_d_dot, q1, q2, q3, rho,
                              alpha: float, alpha_yaw: float | None = None,
                              yaw_rate_filtered: float | None = None) -> DecoupledTorque:
    r"""Attitude law with the thrust direction decoupled from the yaw (tilt first).

    The paper's law (27) acts on the full error ``R_e = R R_d^T`` expressed
    through ``R_d``: its restoring torque ``J z_rho`` and ``Omega - Omega_d``
    are desired-frame vectors applied in the body frame. That is exact while
    the yaw follows, but a yaw error psi rotates the roll/pitch correction by
    psi (stiffness ``W e^{i psi}`` against damping alpha: with rho1 = 200,
    alpha = 12 the tilt loop loses its damping near psi = 45 deg). On a vehicle
    whose yaw saturates, a lagging yaw then drags the thrust direction and the
    position. Here every term is in the body frame and the attitude error is
    split, as in the "decoupled yaw" geometric controller of Gamagedara,
    Bisheban, Kaufman and Lee (ACC 2019) and the tilt-prioritised law of
    Brescianini and D'Andrea, so the thrust direction is controlled the same
    whatever the yaw error.

    With ``Q = R^T R_d = [q1 q2 q3]`` (the desired axes in body coordinates,
    from the vector measurements by :func:`body_coordinates`, never the
    attitude), ``d = q3 = R^T b3d``:

    - tilt: ``z_t = rho1 e3 x d`` (magnitude rho1 sin of the tilt error);
    - yaw: ``Q = Q_xy Rz(psi_e)`` with ``Q_xy`` the smallest rotation taking
      e3 to d (axis in the body xy plane), ``z_y = rho2 sin(psi_e) e3``;
    - ``Omega_d^b = Q Omega_d`` (eq. 31's Omega_d moved to the body frame),
      ``e_Omega = Omega - Omega_d^b``, and since ``d/dt (Q Omega_d) = Q
      Omega_d_dot - Omega x Q Omega_d``::

          tau = Omega x J Omega + J (Q Omega_d_dot - Omega x Omega_d^b + z - alpha e_Omega)

      i.e. ``e_Omega_dot = z - alpha e_Omega`` (the analogue of eq. 35).

    Lyapunov: ``d_dot = d x e_Omega`` (b3d turns with the desired rate), so
    ``d/dt rho1 (1 - d_z) = -e_Omega . z_t``, and for the yaw ``d/dt rho2 (1
    - cos psi_e) = -e_Omega . z_y`` (exact for d = e3), hence ``V_dot = -alpha
    |e_Omega|^2`` as eq. (41). With the yaw's own damping (``alpha_yaw``,
    ``companion.control.yaw``) the damping is ``A = diag(alpha, alpha,
    alpha_y)`` and ``V_dot = -e_Omega^T A e_Omega <= 0`` all the same; with
    the yaw rate low-passed (``yaw_rate_filtered``) the yaw damping acts on
    ``e_f`` and ``V_dot <= -e^T A' e + alpha_y |e_z - e_f|^2 / 2`` (A' with
    alpha_y / 2 in yaw), the filter's lag ``|e_z - e_f|`` bounded by the
    yaw acceleration over the filter's rate (``docs/control.md``). The tilt subsystem's torque involves the yaw
    error only through the damping of ``Q Omega_d`` (which is the correct
    body-frame desired rate); a yaw torque that the mixer cuts (yaw-first
    desaturation) leaves it untouched.

    Parameters
    ----------
    inertia_kg_m2 : sequence (3,)
        Diagonal of J.
    Omega, Omega_d, Omega_d_dot : sequence (3,)
        Measured rate (body), desired rate and its derivative (desired frame, eq. 31).
    q1, q2, q3 : sequence (3,)
        b1d, b2d, b3d in body coordinates.
    rho : (rho1, rho2)
        Tilt and yaw stiffness (1/s^2).
    alpha : float
        Damping (1/s); of roll and pitch only where ``alpha_yaw`` is given.
    alpha_yaw : float or None
        Yaw damping alpha_y (1/s; ``companion.control.yaw``); None: alpha.
    yaw_rate_filtered : float or None
        The low-passed yaw rate (rad/s, body z) that the yaw damping acts on,
        ``e_f = yaw_rate_filtered - (Q Omega_d)_z``; None: ``Omega_z``.
    """
    tau, z, e, _, psi = decoupled_law(inertia_kg_m2, Omega, Omega_d, Omega_d_dot, q1, q2, q3, rho, alpha,
                                      alpha_yaw, yaw_rate_filtered)
    kx, ky, dz = -q3[1], q3[0], q3[2]
    tilt = math.atan2(math.sqrt(kx * kx + ky * ky), dz)
    r1, r2 = rho
    V = r1 * (1.0 - dz) + r2 * (1.0 - math.cos(psi)) + 0.5 * dot(e, e)
    return DecoupledTorque(tau, z, e, tilt, psi, V)


def decoupled_law(inertia_kg_m2, Omega, Omega_d, Omega_d_dot, q1, q2, q3, rho, alpha: float,
                  alpha_yaw: float | None = None, yaw_rate_filtered: float | None = None) -> tuple:
    """:func:`attitude_torque_decoupled` as plain tuples: ``(tau, z, e_Omega, Q Omega_d, psi_e)``.

    The controller's per-frame path (no tilt angle, no V); ``Q Omega_d`` is
    the desired rate in body axes, the rate command's feed-forward
    (``companion.control.rates``). ``e_Omega`` is returned unfiltered.
    """
    dx, dy, dz = q3
    q10, q11, q12 = q1
    q20, q21, q22 = q2
    kx, ky = -dy, dx                       # k = e3 x d (k_z = 0)
    # Q_xy^T q1 = q1 - k x q1 + k x (k x q1) / (1 + d_z): q1 with the tilt undone; psi_e its heading
    if dz > -1.0 + 1e-9:
        kv0, kv1, kv2 = ky * q12, -kx * q12, kx * q11 - ky * q10                # k x q1
        kkv0, kkv1 = ky * kv2, -kx * kv2                                         # k x (k x q1), x and y
        w = 1.0 / (1.0 + dz)
        psi = math.atan2(q11 - kv1 + w * kkv1, q10 - kv0 + w * kkv0)
    else:                                  # upside down: tilt first, no yaw error
        psi = 0.0
    r1, r2 = rho
    z0, z1, z2 = r1 * kx, r1 * ky, r2 * math.sin(psi)
    O0, O1, O2 = Omega_d
    o0 = O0 * q10 + O1 * q20 + O2 * dx
    o1 = O0 * q11 + O1 * q21 + O2 * dy
    o2 = O0 * q12 + O1 * q22 + O2 * dz
    P0, P1, P2 = Omega_d_dot
    oo0 = P0 * q10 + P1 * q20 + P2 * dx
    oo1 = P0 * q11 + P1 * q21 + P2 * dy
    oo2 = P0 * q12 + P1 * q22 + P2 * dz
    wx, wy, wz = Omega
    e0, e1, e2 = wx - o0, wy - o1, wz - o2
    J0, J1, J2 = inertia_kg_m2
    Jw0, Jw1, Jw2 = J0 * wx, J1 * wy, J2 * wz
    tx = (wy * Jw2 - wz * Jw1) + J0 * (oo0 - (wy * o2 - wz * o1) + z0 - alpha * e0)
    ty = (wz * Jw0 - wx * Jw2) + J1 * (oo1 - (wz * o0 - wx * o2) + z1 - alpha * e1)
    if alpha_yaw is None:
        tz = (wx * Jw1 - wy * Jw0) + J2 * (oo2 - (wx * o1 - wy * o0) + z2 - alpha * e2)
    else:                                  # the yaw channel's own damping on the filtered rate (yaw.py)
        ez = e2 if yaw_rate_filtered is None else yaw_rate_filtered - o2
        tz = (wx * Jw1 - wy * Jw0) + J2 * (oo2 - (wx * o1 - wy * o0) + z2 - alpha_yaw * ez)
    return (tx, ty, tz), (z0, z1, z2), (e0, e1, e2), (o0, o1, o2), psi


_INTEGRAL_DT_MAX_S = 0.1   # a gap in the frames longer than this integrates as 0.1 s


def integral_step(e_i, e_x, dt: float, ki: float, limit_n: float, zone_m: float):
    """One step of the position-error integral of the integral term (module docstring).

    Parameters
    ----------
    e_i : sequence (3,)
        Integral so far (m s, world ENU).
    e_x : sequence (3,)
        Position error (m, world ENU) of this frame.
    dt : float
        Vehicle time since the previous frame (s); <= 0: no step.
    ki : float
        Integral gain (N/(m s)), > 0.
    limit_n : float
        Bound on ``|ki e_i|`` (N).
    zone_m : float
        Integrate only while ``|e_x| < zone_m`` (m).

    Returns
    -------
    e_i : tuple (3,)
        The new integral (m s), ``e_i + dt e_x`` projected onto ``|ki e_i| <= limit_n``.
    active : bool
        The integral moved freely (``e_i_dot = e_x``); False: frozen or on
        the bound (its derivative is then taken as 0).
    """
    ex0, ex1, ex2 = e_x
    if not dt > 0.0 or not ex0 * ex0 + ex1 * ex1 + ex2 * ex2 < zone_m * zone_m:
        return (e_i[0], e_i[1], e_i[2]), False
    if dt > _INTEGRAL_DT_MAX_S:
        dt = _INTEGRAL_DT_MAX_S
    i0, i1, i2 = e_i[0] + dt * ex0, e_i[1] + dt * ex1, e_i[2] + dt * ex2
    n = ki * math.sqrt(i0 * i0 + i1 * i1 + i2 * i2)
    if n > limit_n:
        c = limit_n / n
        return (i0 * c, i1 * c, i2 * c), False
    return (i0, i1, i2), True


# --- the controller -----------------------------------------------------------


class GeometricController:
    """The paper's controller (Section 2.4.2) on vector measurements.

    Parameters
    ----------
    vehicle : VehicleConfig
        Mass, inertia and rotor layout (mixer).
    cfg : ControlConfig
        Gains and sensor settings.
    target_enu_m : sequence (3,)
        Pointing target S_p (eq. 21), world ENU, m.

    Notes
    -----
    Holds the state of the small measurement filters (acceleration estimate,
    body-vector filters) and nothing else; no clock, no I/O. Never reads
    the attitude: see ``companion.control.vectors``.
    """

    def __init__(self, vehicle: VehicleConfig, cfg: ControlConfig, target_enu_m) -> None:
        self.vehicle = vehicle
        self.cfg = cfg
        self.target_enu_m = (float(target_enu_m[0]), float(target_enu_m[1]), float(target_enu_m[2]))
        self._m = float(vehicle.mass_kg)
        self._J = tuple(float(j) for j in vehicle.inertia_kg_m2)
        self._g = GRAVITY_M_S2
        self._r2 = unit3(cfg.mag_field_enu_gauss)
        self.mixer = Mixer(vehicle)
        #: The yaw loop of the decoupled law (``companion.control.yaw``); None with the paper's law.
        self.yaw: YawGains | None = None
        self._yaw_filter = None
        if cfg.attitude_law == "decoupled":
            a_yaw = self.mixer.yaw_torque_limit(self._m * self._g) / self._J[2]
            self.yaw = yaw_gains(a_yaw, cfg.gyro_noise_rad_s_sqrt_hz, cfg.yaw_rate_cutoff_hz,
                                 cfg.yaw_damping_ratio, cfg.yaw_noise_fraction, cfg.alpha)
            self._yaw_filter = YawRateFilter(cfg.yaw_rate_cutoff_hz)
            self._rho = (float(cfg.rho1), self.yaw.stiffness_1_s2)
            self._alpha_y = self.yaw.damping_1_s
        else:
            self._rho = (float(cfg.rho1), float(cfg.rho2))
            self._alpha_y = float(cfg.alpha)
        self._ialpha_y = 1.0 / self._alpha_y
        self.accel = AccelerationEstimator(cfg.accel_filter_tau_s)
        self._tau_a = float(cfg.accel_filter_tau_s)
        # the paper's accelerometer vector is R^T e3, a world-fixed direction: propagate it with the gyro
        self._f_acc = BodyVectorFilter(cfg.accel_vector_gain_rad_s, propagate=cfg.vectors == "paper")
        self._f_mag = BodyVectorFilter(cfg.mag_vector_gain_rad_s, propagate=True)
        self._b2_prev: Vec3 = (0.0, 1.0, 0.0)
        self._decoupled = cfg.attitude_law == "decoupled"
        self.pointing = None
        if cfg.pointing_limit:
            a_max = cfg.pointing_yaw_accel_fraction * self.mixer.yaw_torque_limit(self._m * self._g) / self._J[2]
            self.pointing = PointingGovernor(cfg.pointing_yaw_rate_max_rad_s, a_max)
        # Floats for the per-frame path (an int gain multiplies exactly as its float).
        self._kx, self._kv, self._alpha = float(cfg.kx), float(cfg.kv), float(cfg.alpha)
        self._ialpha = 1.0 / self._alpha
        #: Body-rate command of the last update (rad/s, FLU; ``ControlOutput.rate_cmd_flu_rad_s``).
        self.last_rate_cmd: Vec3 = _ZERO
        self._perp = bool(cfg.mag_perpendicular)
        self._ki = float(cfg.ki)
        if not self._ki * self._m < cfg.kv * cfg.kx:
            # Routh on m s^3 + kv s^2 + kx s + ki: the translational loop would be unstable.
            raise ValueError(f"control.ki must be < kv kx / m = {cfg.kv * cfg.kx / self._m:.4g} N/(m s)")
        self._i_limit = float(cfg.integral_limit_fraction) * self._m * self._g
        self._i_zone = float(cfg.integral_zone_m)
        # safety limit of F_d (companion.control.tilt): vertical floor (N) and tan of the largest tilt
        self._fz_min = float(cfg.vertical_thrust_min_fraction) * self._m * self._g
        self._tan_max = math.tan(math.radians(float(cfg.tilt_max_deg)))
        self._tan2_max = self._tan_max * self._tan_max
        #: True where the last command's F_d was limited (tilt or vertical floor).
        self.last_limited = False
        self._e_i: Vec3 = _ZERO
        self._t_i: float | None = None
        self.last_desired = None
        self._last_detail = None
        self._vectors = cfg.vectors
        self._aided = bool(cfg.velocity_aided)
        self._fmax = float(vehicle.max_thrust_per_rotor_n)
        self._thrust_prev: float | None = None
        self._pairs = None
        self._pv = None
        self._t_last: float | None = None
        self.observer = None
        if cfg.observer:
            self._h = horizontal_field(cfg.mag_field_enu_gauss)
            self.observer = VelocityAidedObserver(
                cfg.mag_field_enu_gauss, self._g, paper_vectors=cfg.vectors == "paper",
                velocity_aided=cfg.velocity_aided, tilt_gain_max_rad_s=cfg.observer_tilt_gain_max_rad_s,
                gravity_gain_rad_s=cfg.observer_gravity_gain_rad_s, mag_gain_rad_s=cfg.observer_mag_gain_rad_s,
                bias_gain_1_s=cfg.observer_bias_gain_1_s, bias_max_rad_s=cfg.observer_bias_max_rad_s,
                window_s=cfg.observer_window_s, history_s=cfg.observer_history_s,
                pos_std_m=cfg.nav_position_std_m, vel_std_m_s=cfg.nav_velocity_std_m_s,
                accel_noise=cfg.nav_accel_noise_m_s2_sqrt_hz, accel_bias_walk=cfg.nav_accel_bias_walk_m_s3_sqrt_hz,
                gyro_noise=cfg.gyro_noise_rad_s_sqrt_hz, mass_kg=self._m,
                motor_time_constant_s=vehicle.motor_time_constant_s,
                accel_direction_gain_rad_s=cfg.accel_vector_gain_rad_s, adaptive=cfg.nav_adaptive_noise)

    def observe(self, t_s: float, gyro, accel, mag, pos, vel, nav_t) -> None:
        """Feed the observer one frame without computing a command (``Measurements``' fields, positional).

        For the frames before the controller takes over (on the ground
        before arming, or while the vehicle's own controller flies): the
        gyro bias and the fix noise are then estimated at rest, and the
        first :meth:`command` starts from a converged estimate. A frame
        fed here and again to :meth:`command` (same ``t_s``) is used
        once. No-op without the observer.
        """
        if self.observer is not None:
            self.observer.update(t_s, gyro, accel, mag, pos, vel, nav_t, self._thrust_prev)

    def attitude_estimate(self) -> AttitudeEstimate | None:
        """The attitude the controller acts on, with the position and velocity it used (last frame).

        With the observer: its estimate (``R_hat``, gyro bias, filtered
        position/velocity at the frame's time). Without: the rotation the
        two vector pairs define (TRIAD, pair 1 exact; :func:`body_coordinates`
        uses the same), zero bias, the measured position/velocity. None
        before the first update. For the pose of rangefinder readings.
        """
        if self.observer is not None and self.observer.initialised:
            return self.observer.estimate()
        if self._pairs is None:
            return None
        b1, b2, r1, r2 = self._pairs
        p, v = self._pv
        return AttitudeEstimate(self._t_last, triad_rotation(b1, b2, r1, r2), (0.0, 0.0, 0.0), p, v)

    @property
    def integral_m_s(self) -> Vec3:
        """The position-error integral e_i (m s, world ENU); ``ki e_i`` is its force (N)."""
        return self._e_i

    def reset(self) -> None:
        """Clear the integral of the position error (e.g. at a hand-over).

        The measurement filters keep their state (they follow the sensors,
        not the reference).
        """
        self._e_i = _ZERO
        self._t_i = None

    def _integrate(self, t_s: float, e_x) -> tuple:
        """Advance e_i to the frame at ``t_s`` (vehicle clock); returns (e_i, active)."""
        t_prev = self._t_i
        if t_prev is None:
            self._t_i = t_s
            return self._e_i, False
        dt = t_s - t_prev
        if dt > 0.0:
            self._t_i = t_s
        e_i, active = integral_step(self._e_i, e_x, dt, self._ki, self._i_limit, self._i_zone)
        self._e_i = e_i
        return e_i, active

    def update(self, t_s: float, meas: Measurements, ref: Reference) -> ControlOutput:
        """One control step on one sensor frame, with everything it computed.

        Parameters
        ----------
        t_s : float
            Vehicle time of the sensor frame (s).
        meas : Measurements
        ref : Reference
            Reference sample at ``t_s``.

        Returns
        -------
        ControlOutput
            :meth:`command`'s motor commands with the named intermediate results.
        """
        cmd = self.command(t_s, meas, ref)
        b1x, b1y, b1z, b2x, b2y, b2z, b3x, b3y, b3z, f = self.last_desired
        tau, saturated, Omega_d, e_x, e_v, z, V = self._last_detail
        if V is None:   # decoupled law: V from (d_z, psi_e, e_Omega), as attitude_torque_decoupled
            dz, psi, e = z[3], z[4], z[5]
            r1, r2 = self._rho
            V = r1 * (1.0 - dz) + r2 * (1.0 - math.cos(psi)) + 0.5 * dot(e, e)
            z = z[:3]
        R_d = ((b1x, b2x, b3x), (b1y, b2y, b3y), (b1z, b2z, b3z))
        cmd = (float(cmd[0]), float(cmd[1]), float(cmd[2]), float(cmd[3]))   # as Mixer.mix (numpy inputs)
        return ControlOutput(f, tau, cmd, saturated, (b3x, b3y, b3z), (b2x, b2y, b2z), R_d, Omega_d,
                             e_x, e_v, z, V, self.last_rate_cmd)

    def command(self, t_s: float, meas: Measurements, ref: Reference) -> tuple:
        """One control step: the normalised motor commands (``ControlOutput.motor_cmd``), the 250 Hz path.

        The composition of this module's pieces: the observer (or the
        measured vector pairs), the acceleration estimate, the thrust
        vector of eq. (23) with the integral term, limited to the tilt cone
        and the vertical floor (``companion.control.tilt``; ``last_limited``),
        the governed pointing, :func:`desired_frame` (eqs. 21-26, 31), the torque law
        (:func:`decoupled_law` or :func:`attitude_torque`), the collective
        thrust ``f = F_d . R e3`` and the mixer.

        Side outputs: ``last_desired`` = (b1d, b2d, b3d, f) flattened (10
        floats: R_d's columns, world ENU, and the collective thrust, N), for
        logging; ``last_rate_cmd`` = the body-rate command of ``--control
        rates`` (rad/s, FLU). Raises ValueError where a measured or derived
        direction is zero or not finite.
        """
        gyro, accel, mag, pos, vel, nav_t = meas
        xd, vd, ad, jd, sd, target = ref
        obs = self.observer
        if obs is not None:
            # the observer (companion.control.observer): bias-corrected rate, filtered p, v at t_s
            obs.update(t_s, gyro, accel, mag, pos, vel, nav_t, self._thrust_prev)
            if obs.t is None:        # no vertical yet (free fall at start-up): no estimate to act on
                raise ValueError("the observer has no attitude estimate yet")
            bx, by, bz = obs.b
            gyro = (gyro[0] - bx, gyro[1] - by, gyro[2] - bz)
            pos, vel, nav_t = obs.p, obs.v, t_s
            # a_hat from the filter's velocity, low-passed over one fix interval: a 10 Hz fix's
            # correction step in v_hat must not reach F_dot as a one-frame spike
            fi = obs.fix_interval_s
            self.accel.tau_s = fi if fi > self._tau_a else self._tau_a
        a_hat = self.accel.update(t_s if nav_t is None else nav_t, vel, jd)
        b1, b2, r1, r2 = self._vector_pairs(t_s, gyro, accel, mag, a_hat)
        self._pairs = (b1, b2, r1, r2)
        self._pv = (tuple(pos), tuple(vel))
        self._t_last = t_s
        e_x = (pos[0] - xd[0], pos[1] - xd[1], pos[2] - xd[2])
        e_v = (vel[0] - vd[0], vel[1] - vd[1], vel[2] - vd[2])
        F, F_dot, F_ddot = self._thrust_vector(t_s, e_x, e_v, (a_hat[0] - ad[0], a_hat[1] - ad[1], a_hat[2] - ad[2]),
                                               ad, jd, sd)
        u, u_dot, u_ddot = self._pointing(t_s, self.target_enu_m if target is None else target, xd, vd, ad)
        F2 = F[2]
        # safety invariant: b3d within the tilt cone, F_d's vertical part above the floor (tilt.py)
        self.last_limited = F2 < self._fz_min or F[0] * F[0] + F[1] * F[1] > F2 * F2 * self._tan2_max
        if self.last_limited:     # b3d along the limited F, Omega_d from that direction's derivatives
            F, G, G_dot, G_ddot = limit_thrust(F, F_dot, F_ddot, self._fz_min, self._tan_max)
            b1d, b2d, b3d, Od, Odd = desired_frame(G, G_dot, G_ddot, u, u_dot, u_ddot, self._b2_prev)
        else:
            b1d, b2d, b3d, Od, Odd = desired_frame(F, F_dot, F_ddot, u, u_dot, u_ddot, self._b2_prev)
        self._b2_prev = b2d
        frames = triad_frames(b1, b2, r1, r2)
        if self._decoupled:
            q1, q2, q3 = triad_to_body3(b1d, b2d, b3d, b1, r1, frames)    # R^T b_jd
            wz_f = self._yaw_filter.step(t_s, gyro[2])
            tau, z, e, Od_b, psi = decoupled_law(self._J, gyro, Od, Odd, q1, q2, q3, self._rho, self._alpha,
                                                 self._alpha_y, wz_f)
            ia = self._ialpha
            self.last_rate_cmd = (Od_b[0] + ia * z[0], Od_b[1] + ia * z[1], Od_b[2] + self._ialpha_y * z[2])
            zV, V = (z[0], z[1], z[2], q3[2], psi, e), None
        else:
            tau, zV, V = attitude_torque(self._J, gyro, Od, Odd, (b1, b2), (r1, r2), b1d, b2d, b3d, self._rho,
                                         self._alpha)
            self.last_rate_cmd = rate_command(Od, zV, self._alpha)
        ez = triad_body_z(b1, r1, frames)
        f = F[0] * ez[0] + F[1] * ez[1] + F[2] * ez[2]
        cmd, saturated = self.mixer.mix_fast(f, tau[0], tau[1], tau[2])
        self._thrust_prev = (cmd[0] + cmd[1] + cmd[2] + cmd[3]) * self._fmax
        self.last_desired = (*b1d, *b2d, *b3d, f)
        self._last_detail = (tau, saturated, Od, e_x, e_v, zV, V)
        return cmd

    def _vector_pairs(self, t_s, gyro, accel, mag, a_hat) -> tuple:
        """``(b1, b2, r1, r2)``: the observer's virtual pairs, else the measured vectors
        (filtered, :func:`companion.control.vectors.controller_vectors`)."""
        if self.observer is not None:
            # virtual_pairs(R_hat, h): b_i = R_hat^T r_i, r_1 = e3, r_2 = h (horizontal field)
            R = self.observer.R
            hx, hy, hz = self._h
            return ((R[6], R[7], R[8]), (R[0] * hx + R[3] * hy + R[6] * hz, R[1] * hx + R[4] * hy + R[7] * hz,
                                         R[2] * hx + R[5] * hy + R[8] * hz), _E3, self._h)
        wx, wy, wz = gyro
        x, y, z = unit3(accel)
        fa = self._f_acc.step(t_s, x, y, z, wx, wy, wz)
        x, y, z = unit3(mag)
        fm = self._f_mag.step(t_s, x, y, z, wx, wy, wz)
        pr = controller_vectors(fa, fm, a_hat, self._r2, self._g, self._perp, self._vectors, self._aided)
        return pr.b1, pr.b2, pr.r1, pr.r2

    def _thrust_vector(self, t_s, e_x, e_v, ev_dot, ad, jd, sd) -> tuple:
        """F_d of eq. (23) with the integral term, and its first two derivatives (module docstring)."""
        m, g, kx, kv, ki = self._m, self._g, self._kx, self._kv, self._ki
        ex0, ex1, ex2 = e_x
        ev0, ev1, ev2 = e_v
        ea0, ea1, ea2 = ev_dot
        if ki > 0.0:
            (i0, i1, i2), active = self._integrate(t_s, e_x)
            if active:                                             # e_i_dot = e_x, e_i_ddot = e_v
                id0, id1, id2, idd0, idd1, idd2 = ex0, ex1, ex2, ev0, ev1, ev2
            else:
                id0 = id1 = id2 = idd0 = idd1 = idd2 = 0.0
            ej0 = -(kx * ev0 + kv * ea0 + ki * id0) / m            # e_v_ddot of the ideal closed loop
            ej1 = -(kx * ev1 + kv * ea1 + ki * id1) / m
            ej2 = -(kx * ev2 + kv * ea2 + ki * id2) / m
            return ((-kx * ex0 - kv * ev0 - ki * i0 + m * ad[0], -kx * ex1 - kv * ev1 - ki * i1 + m * ad[1],
                     -kx * ex2 - kv * ev2 - ki * i2 + m * (g + ad[2])),
                    (-kx * ev0 - kv * ea0 - ki * id0 + m * jd[0], -kx * ev1 - kv * ea1 - ki * id1 + m * jd[1],
                     -kx * ev2 - kv * ea2 - ki * id2 + m * jd[2]),
                    (-kx * ea0 - kv * ej0 - ki * idd0 + m * sd[0], -kx * ea1 - kv * ej1 - ki * idd1 + m * sd[1],
                     -kx * ea2 - kv * ej2 - ki * idd2 + m * sd[2]))
        ej0 = -(kx * ev0 + kv * ea0) / m
        ej1 = -(kx * ev1 + kv * ea1) / m
        ej2 = -(kx * ev2 + kv * ea2) / m
        return ((-kx * ex0 - kv * ev0 + m * ad[0], -kx * ex1 - kv * ev1 + m * ad[1], -kx * ex2 - kv * ev2 + m * (g + ad[2])),
                (-kx * ev0 - kv * ea0 + m * jd[0], -kx * ev1 - kv * ea1 + m * jd[1], -kx * ev2 - kv * ea2 + m * jd[2]),
                (-kx * ea0 - kv * ej0 + m * sd[0], -kx * ea1 - kv * ej1 + m * sd[1], -kx * ea2 - kv * ej2 + m * sd[2]))

    def _pointing(self, t_s, Sp, xd, vd, ad) -> tuple:
        """The pointing vector ``u_s = S_p - x_d`` (eq. 21) and its derivatives, governed
        (``companion.control.pointing``: a unit vector with consistent derivatives passes
        :func:`desired_frame`'s normalisation unchanged)."""
        u = (Sp[0] - xd[0], Sp[1] - xd[1], Sp[2] - xd[2])
        ud, udd = (-vd[0], -vd[1], -vd[2]), (-ad[0], -ad[1], -ad[2])
        if self.pointing is not None and u[0] * u[0] + u[1] * u[1] + u[2] * u[2] > 1e-12:
            return self.pointing.update(t_s, *unit_d2(u, ud, udd))
        return u, ud, udd
