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
takes the vehicle's time as an argument. The pure functions below are the
specification (``GeometricController.update_reference`` composes them); the
250 Hz path ``GeometricController.update_fast`` is the same arithmetic
unrolled into float locals, in the same order, so it gives the same numbers
to the last bit (``tests/test_control_fast.py``) in ~17 us instead of ~45 us
(``python benchmarks/bench_control.py --timing``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..vehicle import GRAVITY_M_S2, VehicleConfig
from .config import ControlConfig
from .mixer import Mixer
from .pointing import PointingGovernor
from .rates import rate_command
from .observer import AttitudeEstimate, VelocityAidedObserver, horizontal_field, virtual_pairs
from .so3 import (Vec3, body_coordinates, cross, dot, thrust_axis_estimate, triad_rotation,  # noqa: F401
                  unit3, unit_d2)
from .vectors import AccelerationEstimator, BodyVectorFilter, controller_vectors

# --- small float-tuple vector algebra (the hot path avoids numpy) ---------


_ZERO = (0.0, 0.0, 0.0)


# --- named inputs and outputs ----------------------------------------------


@dataclass(frozen=True, slots=True)
class Measurements:
    """What the vehicle sends (HIGHRES_IMU, LOCAL_POSITION_NED), converted to ENU/FLU.

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


@dataclass(frozen=True, slots=True)
class Reference:
    """One sample of the reference trajectory, world ENU.

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
    if dot(F, F) < 1e-12:   # free fall demanded: no thrust direction, keep level
        F, F_dot, F_ddot = (0.0, 0.0, 1e-6), _ZERO, _ZERO
    b3, b3d, b3dd = unit_d2(F, F_dot, F_ddot)
    if dot(u_s, u_s) > 1e-12:
        s, sd, sdd = unit_d2(u_s, u_s_dot, u_s_ddot)
    else:
        s, sd, sdd = b2_fallback, _ZERO, _ZERO
    # w = s - (s.b3) b3 (eq. 22) and its derivatives.
    c = dot(s, b3)
    cd = dot(sd, b3) + dot(s, b3d)
    cdd = dot(sdd, b3) + 2.0 * dot(sd, b3d) + dot(s, b3dd)
    w = (s[0] - c * b3[0], s[1] - c * b3[1], s[2] - c * b3[2])
    wd = tuple(sd[i] - cd * b3[i] - c * b3d[i] for i in range(3))
    wdd = tuple(sdd[i] - cdd * b3[i] - 2.0 * cd * b3d[i] - c * b3dd[i] for i in range(3))
    if dot(w, w) < 1e-12:   # s along b3d: keep the previous pointing, frozen
        c = dot(b2_fallback, b3)
        w = tuple(b2_fallback[i] - c * b3[i] for i in range(3))
        wd = wdd = _ZERO
        if dot(w, w) < 1e-12:
            w = cross(b3, (1.0, 0.0, 0.0) if abs(b3[0]) < 0.9 else (0.0, 1.0, 0.0))
    b2, b2d, b2dd = unit_d2(w, wd, wdd)
    b1 = cross(b2, b3)
    x1, x2 = cross(b2d, b3), cross(b2, b3d)
    b1d = (x1[0] + x2[0], x1[1] + x2[1], x1[2] + x2[2])
    y1, y2, y3 = cross(b2dd, b3), cross(b2d, b3d), cross(b2, b3dd)
    b1dd = tuple(y1[i] + 2.0 * y2[i] + y3[i] for i in range(3))
    Omega_d = (dot(b3, b2d), dot(b1, b3d), dot(b2, b1d))
    Omega_d_dot = (dot(b3d, b2d) + dot(b3, b2dd),
                   dot(b1d, b3d) + dot(b1, b3dd),
                   dot(b2d, b1d) + dot(b2, b1dd))
    R_d = ((b1[0], b2[0], b3[0]), (b1[1], b2[1], b3[1]), (b1[2], b2[2], b3[2]))
    return DesiredAttitude(R_d, b1, b2, b3, Omega_d, Omega_d_dot)


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
                              alpha: float) -> DecoupledTorque:
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
    |e_Omega|^2`` as eq. (41). The tilt subsystem's torque involves the yaw
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
        Damping (1/s).
    """
    dx, dy, dz = q3
    kx, ky = -dy, dx                       # k = e3 x d (k_z = 0)
    s_t = math.sqrt(kx * kx + ky * ky)
    tilt = math.atan2(s_t, dz)
    # Q_xy^T q1 = q1 - k x q1 + k x (k x q1) / (1 + d_z): q1 with the tilt undone.
    v = q1
    if dz > -1.0 + 1e-9:
        kv = (ky * v[2], -kx * v[2], kx * v[1] - ky * v[0])                   # k x v
        kkv = (ky * kv[2], -kx * kv[2], kx * kv[1] - ky * kv[0])              # k x (k x v)
        w = 1.0 / (1.0 + dz)
        vx, vy = v[0] - kv[0] + w * kkv[0], v[1] - kv[1] + w * kkv[1]
        psi = math.atan2(vy, vx)
    else:                                  # upside down: tilt first, no yaw error
        psi = 0.0
    r1, r2 = rho
    z = (r1 * kx, r1 * ky, r2 * math.sin(psi))
    Od = tuple(Omega_d[0] * q1[i] + Omega_d[1] * q2[i] + Omega_d[2] * q3[i] for i in range(3))
    Odd = tuple(Omega_d_dot[0] * q1[i] + Omega_d_dot[1] * q2[i] + Omega_d_dot[2] * q3[i] for i in range(3))
    wx, wy, wz = Omega
    e = (wx - Od[0], wy - Od[1], wz - Od[2])
    WxOd = cross(Omega, Od)
    Jx, Jy, Jz = inertia_kg_m2
    Jw = (Jx * wx, Jy * wy, Jz * wz)
    gyro = (wy * Jw[2] - wz * Jw[1], wz * Jw[0] - wx * Jw[2], wx * Jw[1] - wy * Jw[0])
    tau = tuple(gyro[i] + inertia_kg_m2[i] * (Odd[i] - WxOd[i] + z[i] - alpha * e[i]) for i in range(3))
    V = r1 * (1.0 - dz) + r2 * (1.0 - math.cos(psi)) + 0.5 * dot(e, e)
    return DecoupledTorque(tau, z, e, tilt, psi, V)


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
        self.mixer = Mixer(vehicle)
        self._m = float(vehicle.mass_kg)
        self._J = tuple(float(j) for j in vehicle.inertia_kg_m2)
        self._g = GRAVITY_M_S2
        self._r2 = unit3(cfg.mag_field_enu_gauss)
        self._rho = (float(cfg.rho1), float(cfg.rho2))
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
        # Floats for update_fast (an int gain multiplies exactly as its float).
        self._kx, self._kv, self._alpha = float(cfg.kx), float(cfg.kv), float(cfg.alpha)
        self._ialpha = 1.0 / self._alpha
        #: Body-rate command of the last update (rad/s, FLU; ``ControlOutput.rate_cmd_flu_rad_s``).
        self.last_rate_cmd: Vec3 = _ZERO
        self._r2u = unit3(self._r2)      # measurement_vectors normalises r_2 once more
        self._perp = bool(cfg.mag_perpendicular)
        self._ki = float(cfg.ki)
        if not self._ki * self._m < cfg.kv * cfg.kx:
            # Routh on m s^3 + kv s^2 + kx s + ki: the translational loop would be unstable.
            raise ValueError(f"control.ki must be < kv kx / m = {cfg.kv * cfg.kx / self._m:.4g} N/(m s)")
        self._i_limit = float(cfg.integral_limit_fraction) * self._m * self._g
        self._i_zone = float(cfg.integral_zone_m)
        self._e_i: Vec3 = _ZERO
        self._t_i: float | None = None
        self.last_desired = None
        self._last_detail = None
        self._vectors = cfg.vectors
        self._aided = bool(cfg.velocity_aided)
        self._today = cfg.vectors == "physical" and self._aided     # the unrolled pair branch
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
        """Feed the observer one frame without computing a command (arguments as :meth:`update_fast`).

        For the frames before the controller takes over (on the ground
        before arming, or while the vehicle's own controller flies): the
        gyro bias and the fix noise are then estimated at rest, and the
        first :meth:`update_fast` starts from a converged estimate. A frame
        fed here and again to :meth:`update_fast` (same ``t_s``) is used
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
        """One control step on one sensor frame.

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

        Notes
        -----
        A wrapper of :meth:`update_fast` (the same numbers, bit for bit, as
        :meth:`update_reference`, the composition of this module's pure
        functions), plus the named output.
        """
        gy, ac, mg, v = meas.gyro_flu_rad_s, meas.accel_flu_m_s2, meas.mag_flu_gauss, meas.vel_enu_m_s
        cmd = self.update_fast(t_s, (float(gy[0]), float(gy[1]), float(gy[2])),
                               (float(ac[0]), float(ac[1]), float(ac[2])),
                               (float(mg[0]), float(mg[1]), float(mg[2])), meas.pos_enu_m,
                               (float(v[0]), float(v[1]), float(v[2])), meas.nav_time_s,
                               ref.pos_enu_m, ref.vel_enu_m_s, ref.acc_enu_m_s2, ref.jerk_enu_m_s3,
                               ref.snap_enu_m_s4, ref.target_enu_m)
        b1x, b1y, b1z, b2x, b2y, b2z, b3x, b3y, b3z, f = self.last_desired
        tau, saturated, Omega_d, e_x, e_v, z, V = self._last_detail
        if V is None:   # decoupled law: V from (d_z, psi_e, e_Omega), see attitude_torque_decoupled
            dz, psi, e = z[3], z[4], z[5]
            r1, r2 = self._rho
            V = r1 * (1.0 - dz) + r2 * (1.0 - math.cos(psi)) + 0.5 * dot(e, e)
            z = z[:3]
        R_d = ((b1x, b2x, b3x), (b1y, b2y, b3y), (b1z, b2z, b3z))
        cmd = (float(cmd[0]), float(cmd[1]), float(cmd[2]), float(cmd[3]))   # as Mixer.mix (numpy inputs)
        return ControlOutput(f, tau, cmd, saturated, (b3x, b3y, b3z), (b2x, b2y, b2z), R_d, Omega_d,
                             e_x, e_v, z, V, self.last_rate_cmd)

    def update_fast(self, t_s, gyro, accel, mag, pos, vel, nav_t, xd, vd, ad, jd, sd, target=None):
        """:meth:`update` on plain float tuples, returning only the motor commands (the 250 Hz path).

        Parameters
        ----------
        t_s : float
            Vehicle time of the sensor frame (s).
        gyro, accel, mag : tuple of 3 floats
            Omega (rad/s), specific force (m/s^2), magnetic field (gauss), body FLU.
        pos, vel : sequence (3,)
            Position (m) and velocity (m/s of Python floats), world ENU.
        nav_t : float or None
            Time stamp of pos/vel (``Measurements.nav_time_s``).
        xd, vd, ad, jd, sd : sequence (3,)
            Reference position and its four derivatives (``Reference``), world ENU.
        target : sequence (3,) or None
            Pointing target S_p (None: the controller's).

        Returns
        -------
        tuple (4,)
            Normalised motor commands (``ControlOutput.motor_cmd``).

        Notes
        -----
        Side outputs: ``self.last_desired`` = (b1d, b2d, b3d, f) flattened
        (10 floats: the columns of R_d, world ENU, and the collective
        thrust, N), for logging. Raises ValueError where a measured or
        derived direction is zero or not finite.

        Every line is :meth:`update_reference` (the pure functions of this
        module composed) with the 3-vectors unrolled into float locals, the
        float operations kept in the same order so the result is identical
        to the last bit (``tests/test_control_fast.py`` checks it); shared
        sub-expressions (the TRIAD frames, computed three times by
        ``body_coordinates`` and once more by ``thrust_axis_estimate``) are
        computed once, and values only ``ControlOutput`` needs (V) are left
        to :meth:`update`. Rare branches (free fall, pointing undefined or
        along the thrust, the "paper" law) call the pure functions.
        """
        sqrt = math.sqrt
        m, g, kx, kv = self._m, self._g, self._kx, self._kv
        obs = self.observer
        if obs is not None:
            # the observer (companion.control.observer): bias-corrected rate, filtered p, v at t_s
            obs.update(t_s, gyro, accel, mag, pos, vel, nav_t, self._thrust_prev)
            if obs.t is None:        # no vertical yet (free fall at start-up): no estimate to act on
                raise ValueError("the observer has no attitude estimate yet")
            bx_, by_, bz_ = obs.b
            gyro = (gyro[0] - bx_, gyro[1] - by_, gyro[2] - bz_)
            pos, vel, nav_t = obs.p, obs.v, t_s
            # a_hat from the filter's velocity, low-passed over one fix interval: a 10 Hz fix's
            # correction step in v_hat must not reach F_dot as a one-frame spike
            fi = obs.fix_interval_s
            self.accel.tau_s = fi if fi > self._tau_a else self._tau_a
        wx, wy, wz = gyro

        # --- AccelerationEstimator.update (state kept in self.accel) -----------------
        acc = self.accel
        tn = t_s if nav_t is None else nav_t
        vx, vy, vz = vel
        t_prev = acc._t
        if t_prev is None:
            acc._t, acc._v = tn, (vx, vy, vz)
            ahx, ahy, ahz = acc._a
        else:
            dt = tn - t_prev
            if dt <= 0.0:
                ahx, ahy, ahz = acc._a
            else:
                px, py, pz = acc._v
                dx, dy, dz = (vx - px) / dt, (vy - py) / dt, (vz - pz) / dt
                tau_a = acc.tau_s
                if tau_a > 0.0:
                    beta = 1.0 - math.exp(-dt / tau_a)
                    ax, ay, az = acc._a
                    ax, ay, az = ax + beta * (dx - ax), ay + beta * (dy - ay), az + beta * (dz - az)
                else:
                    ax, ay, az = dx, dy, dz
                acc._a = (ax, ay, az)
                acc._t, acc._v = tn, (vx, vy, vz)
                lag = 0.5 * dt + tau_a
                ahx, ahy, ahz = ax + lag * jd[0], ay + lag * jd[1], az + lag * jd[2]

        # --- measurement_vectors(filtered accel, filtered mag, a_hat, ...) ------------
        if obs is not None:
            # virtual_pairs(R_hat, h): b_i = R_hat^T r_i, r_1 = e3, r_2 = h (horizontal field)
            R = obs.R
            hx, hy, hz = self._h
            m1x, m1y, m1z = R[6], R[7], R[8]
            r1x, r1y, r1z = 0.0, 0.0, 1.0
            m2x, m2y, m2z = (R[0] * hx + R[3] * hy + R[6] * hz, R[1] * hx + R[4] * hy + R[7] * hz,
                             R[2] * hx + R[5] * hy + R[8] * hz)
            r2x, r2y, r2z = hx, hy, hz
        else:
            x, y, z = accel
            n = sqrt(x * x + y * y + z * z)
            if not n > 0.0:
                raise ValueError("cannot normalise a zero (or non-finite) vector")
            fa = self._f_acc.step(t_s, x / n, y / n, z / n, wx, wy, wz)
            x, y, z = mag
            n = sqrt(x * x + y * y + z * z)
            if not n > 0.0:
                raise ValueError("cannot normalise a zero (or non-finite) vector")
            fm = self._f_mag.step(t_s, x / n, y / n, z / n, wx, wy, wz)
            # both filters have stepped before anything below may raise (as in update_reference)
            if not self._today:
                # the other sensor models / tilt sources (controller_vectors)
                pr = controller_vectors(fa, fm, (ahx, ahy, ahz), self._r2, g, self._perp, self._vectors, self._aided)
                m1x, m1y, m1z = pr.b1
                r1x, r1y, r1z = pr.r1
                m2x, m2y, m2z = pr.b2
                r2x, r2y, r2z = pr.r2
            else:
                x, y, z = fa
                n = sqrt(x * x + y * y + z * z)
                if not n > 0.0:
                    raise ValueError("cannot normalise a zero (or non-finite) vector")
                m1x, m1y, m1z = x / n, y / n, z / n                       # b_1 (body)
                z = ahz + g
                n = sqrt(ahx * ahx + ahy * ahy + z * z)
                if not n > 0.0:
                    raise ValueError("cannot normalise a zero (or non-finite) vector")
                r1x, r1y, r1z = ahx / n, ahy / n, z / n                   # r_1 (world)
                x, y, z = fm
                n = sqrt(x * x + y * y + z * z)
                if not n > 0.0:
                    raise ValueError("cannot normalise a zero (or non-finite) vector")
                m2x, m2y, m2z = x / n, y / n, z / n                       # b_2 (body)
                r2x, r2y, r2z = self._r2u                                  # r_2 (world)
                if self._perp:
                    c = m2x * m1x + m2y * m1y + m2z * m1z
                    x, y, z = m2x - c * m1x, m2y - c * m1y, m2z - c * m1z
                    n = sqrt(x * x + y * y + z * z)
                    if not n > 0.0:
                        raise ValueError("cannot normalise a zero (or non-finite) vector")
                    m2x, m2y, m2z = x / n, y / n, z / n
                    c = r2x * r1x + r2y * r1y + r2z * r1z
                    x, y, z = r2x - c * r1x, r2y - c * r1y, r2z - c * r1z
                    n = sqrt(x * x + y * y + z * z)
                    if not n > 0.0:
                        raise ValueError("cannot normalise a zero (or non-finite) vector")
                    r2x, r2y, r2z = x / n, y / n, z / n
        self._pairs = ((m1x, m1y, m1z), (m2x, m2y, m2z), (r1x, r1y, r1z), (r2x, r2y, r2z))
        self._pv = (tuple(pos), (vx, vy, vz))
        self._t_last = t_s

        # --- errors and F_d with its derivatives (eq. 23) ------------------------------
        xd0, xd1, xd2 = xd
        vd0, vd1, vd2 = vd
        ad0, ad1, ad2 = ad
        p0, p1, p2 = pos
        ex0, ex1, ex2 = p0 - xd0, p1 - xd1, p2 - xd2
        ev0, ev1, ev2 = vx - vd0, vy - vd1, vz - vd2
        ea0, ea1, ea2 = ahx - ad0, ahy - ad1, ahz - ad2            # e_v_dot
        ki = self._ki
        if ki > 0.0:
            # self._integrate / integral_step, inlined
            i0, i1, i2 = self._e_i
            active = False
            t_prev = self._t_i
            if t_prev is None:
                self._t_i = t_s
            else:
                dt = t_s - t_prev
                if dt > 0.0:
                    self._t_i = t_s
                    zone = self._i_zone
                    if ex0 * ex0 + ex1 * ex1 + ex2 * ex2 < zone * zone:
                        if dt > _INTEGRAL_DT_MAX_S:
                            dt = _INTEGRAL_DT_MAX_S
                        i0, i1, i2 = i0 + dt * ex0, i1 + dt * ex1, i2 + dt * ex2
                        n = ki * sqrt(i0 * i0 + i1 * i1 + i2 * i2)
                        lim = self._i_limit
                        if n > lim:
                            c = lim / n
                            i0, i1, i2 = i0 * c, i1 * c, i2 * c
                        else:
                            active = True
                        self._e_i = (i0, i1, i2)
            if active:                                             # e_i_dot = e_x, e_i_ddot = e_v
                id0, id1, id2, idd0, idd1, idd2 = ex0, ex1, ex2, ev0, ev1, ev2
            else:
                id0 = id1 = id2 = idd0 = idd1 = idd2 = 0.0
            ej0 = -(kx * ev0 + kv * ea0 + ki * id0) / m            # e_v_ddot
            ej1 = -(kx * ev1 + kv * ea1 + ki * id1) / m
            ej2 = -(kx * ev2 + kv * ea2 + ki * id2) / m
            F0 = -kx * ex0 - kv * ev0 - ki * i0 + m * ad0
            F1 = -kx * ex1 - kv * ev1 - ki * i1 + m * ad1
            F2 = -kx * ex2 - kv * ev2 - ki * i2 + m * (g + ad2)
            Fd0 = -kx * ev0 - kv * ea0 - ki * id0 + m * jd[0]
            Fd1 = -kx * ev1 - kv * ea1 - ki * id1 + m * jd[1]
            Fd2 = -kx * ev2 - kv * ea2 - ki * id2 + m * jd[2]
            Fdd0 = -kx * ea0 - kv * ej0 - ki * idd0 + m * sd[0]
            Fdd1 = -kx * ea1 - kv * ej1 - ki * idd1 + m * sd[1]
            Fdd2 = -kx * ea2 - kv * ej2 - ki * idd2 + m * sd[2]
        else:
            ej0 = -(kx * ev0 + kv * ea0) / m                       # e_v_ddot
            ej1 = -(kx * ev1 + kv * ea1) / m
            ej2 = -(kx * ev2 + kv * ea2) / m
            F0 = -kx * ex0 - kv * ev0 + m * ad0
            F1 = -kx * ex1 - kv * ev1 + m * ad1
            F2 = -kx * ex2 - kv * ev2 + m * (g + ad2)
            Fd0 = -kx * ev0 - kv * ea0 + m * jd[0]
            Fd1 = -kx * ev1 - kv * ea1 + m * jd[1]
            Fd2 = -kx * ev2 - kv * ea2 + m * jd[2]
            Fdd0 = -kx * ea0 - kv * ej0 + m * sd[0]
            Fdd1 = -kx * ea1 - kv * ej1 + m * sd[1]
            Fdd2 = -kx * ea2 - kv * ej2 + m * sd[2]

        # --- pointing u_s = S_p - x_d (eq. 21), governed ------------------------------
        Sp = self.target_enu_m if target is None else target
        u0, u1, u2 = Sp[0] - xd0, Sp[1] - xd1, Sp[2] - xd2
        ud0, ud1, ud2 = -vd0, -vd1, -vd2
        udd0, udd1, udd2 = -ad0, -ad1, -ad2
        uu = u0 * u0 + u1 * u1 + u2 * u2
        if self.pointing is not None and uu > 1e-12:
            # unit_d2(u_s, u_s_dot, u_s_ddot)
            r = sqrt(uu)
            n0, n1, n2 = u0 / r, u1 / r, u2 / r
            rd = n0 * ud0 + n1 * ud1 + n2 * ud2
            nd0, nd1, nd2 = (ud0 - n0 * rd) / r, (ud1 - n1 * rd) / r, (ud2 - n2 * rd) / r
            rdd = nd0 * ud0 + nd1 * ud1 + nd2 * ud2 + n0 * udd0 + n1 * udd1 + n2 * udd2
            s_, sd_, sdd_ = self.pointing.update(
                t_s, (n0, n1, n2), (nd0, nd1, nd2),
                ((udd0 - 2.0 * nd0 * rd - n0 * rdd) / r, (udd1 - 2.0 * nd1 * rd - n1 * rdd) / r,
                 (udd2 - 2.0 * nd2 * rd - n2 * rdd) / r))
            u0, u1, u2 = s_
            ud0, ud1, ud2 = sd_
            udd0, udd1, udd2 = sdd_
            uu = u0 * u0 + u1 * u1 + u2 * u2

        # --- desired_attitude (eqs. 21-26, 31) ---------------------------------------
        FF = F0 * F0 + F1 * F1 + F2 * F2
        fallback = not FF >= 1e-12 or not uu > 1e-12
        if not fallback:
            # b3 = unit_d2(F, F_dot, F_ddot)
            r = sqrt(FF)
            b3x, b3y, b3z = F0 / r, F1 / r, F2 / r
            rd = b3x * Fd0 + b3y * Fd1 + b3z * Fd2
            b3dx, b3dy, b3dz = (Fd0 - b3x * rd) / r, (Fd1 - b3y * rd) / r, (Fd2 - b3z * rd) / r
            rdd = b3dx * Fd0 + b3dy * Fd1 + b3dz * Fd2 + b3x * Fdd0 + b3y * Fdd1 + b3z * Fdd2
            b3ddx = (Fdd0 - 2.0 * b3dx * rd - b3x * rdd) / r
            b3ddy = (Fdd1 - 2.0 * b3dy * rd - b3y * rdd) / r
            b3ddz = (Fdd2 - 2.0 * b3dz * rd - b3z * rdd) / r
            # s = unit_d2(u_s, ...)
            r = sqrt(uu)
            s0, s1, s2 = u0 / r, u1 / r, u2 / r
            rd = s0 * ud0 + s1 * ud1 + s2 * ud2
            sd0, sd1, sd2 = (ud0 - s0 * rd) / r, (ud1 - s1 * rd) / r, (ud2 - s2 * rd) / r
            rdd = sd0 * ud0 + sd1 * ud1 + sd2 * ud2 + s0 * udd0 + s1 * udd1 + s2 * udd2
            sdd0 = (udd0 - 2.0 * sd0 * rd - s0 * rdd) / r
            sdd1 = (udd1 - 2.0 * sd1 * rd - s1 * rdd) / r
            sdd2 = (udd2 - 2.0 * sd2 * rd - s2 * rdd) / r
            # w = s - (s.b3) b3 (eq. 22) and its derivatives
            c = s0 * b3x + s1 * b3y + s2 * b3z
            cd = (sd0 * b3x + sd1 * b3y + sd2 * b3z) + (s0 * b3dx + s1 * b3dy + s2 * b3dz)
            cdd = ((sdd0 * b3x + sdd1 * b3y + sdd2 * b3z) + 2.0 * (sd0 * b3dx + sd1 * b3dy + sd2 * b3dz)
                   + (s0 * b3ddx + s1 * b3ddy + s2 * b3ddz))
            w0, w1, w2 = s0 - c * b3x, s1 - c * b3y, s2 - c * b3z
            fallback = w0 * w0 + w1 * w1 + w2 * w2 < 1e-12
        if not fallback:
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
            Od0 = b3x * b2dx + b3y * b2dy + b3z * b2dz
            Od1 = b1x * b3dx + b1y * b3dy + b1z * b3dz
            Od2 = b2x * b1dx + b2y * b1dy + b2z * b1dz
            Odd0 = (b3dx * b2dx + b3dy * b2dy + b3dz * b2dz) + (b3x * b2ddx + b3y * b2ddy + b3z * b2ddz)
            Odd1 = (b1dx * b3dx + b1dy * b3dy + b1dz * b3dz) + (b1x * b3ddx + b1y * b3ddy + b1z * b3ddz)
            Odd2 = (b2dx * b1dx + b2dy * b1dy + b2dz * b1dz) + (b2x * b1ddx + b2y * b1ddy + b2z * b1ddz)
        else:
            des = desired_attitude((F0, F1, F2), (Fd0, Fd1, Fd2), (Fdd0, Fdd1, Fdd2), (u0, u1, u2),
                                   (ud0, ud1, ud2), (udd0, udd1, udd2), self._b2_prev)
            b1x, b1y, b1z = des.b1d
            b2x, b2y, b2z = des.b2d
            b3x, b3y, b3z = des.b3d
            Od0, Od1, Od2 = des.Omega_d
            Odd0, Odd1, Odd2 = des.Omega_d_dot
        self._b2_prev = (b2x, b2y, b2z)

        # --- TRIAD frames of the two pairs (body_coordinates, thrust_axis_estimate) ---
        x, y, z = m1y * m2z - m1z * m2y, m1z * m2x - m1x * m2z, m1x * m2y - m1y * m2x
        n = sqrt(x * x + y * y + z * z)
        if not n > 0.0:
            raise ValueError("cannot normalise a zero (or non-finite) vector")
        mbx, mby, mbz = x / n, y / n, z / n
        x, y, z = r1y * r2z - r1z * r2y, r1z * r2x - r1x * r2z, r1x * r2y - r1y * r2x
        n = sqrt(x * x + y * y + z * z)
        if not n > 0.0:
            raise ValueError("cannot normalise a zero (or non-finite) vector")
        mrx, mry, mrz = x / n, y / n, z / n
        nbx, nby, nbz = m1y * mbz - m1z * mby, m1z * mbx - m1x * mbz, m1x * mby - m1y * mbx
        nrx, nry, nrz = r1y * mrz - r1z * mry, r1z * mrx - r1x * mrz, r1x * mry - r1y * mrx

        J0, J1, J2 = self._J
        if self._decoupled:
            # q_j = R^T b_jd (body_coordinates)
            c1 = b1x * r1x + b1y * r1y + b1z * r1z
            c2 = b1x * mrx + b1y * mry + b1z * mrz
            c3 = b1x * nrx + b1y * nry + b1z * nrz
            q10, q11, q12 = (c1 * m1x + c2 * mbx + c3 * nbx, c1 * m1y + c2 * mby + c3 * nby,
                             c1 * m1z + c2 * mbz + c3 * nbz)
            c1 = b2x * r1x + b2y * r1y + b2z * r1z
            c2 = b2x * mrx + b2y * mry + b2z * mrz
            c3 = b2x * nrx + b2y * nry + b2z * nrz
            q20, q21, q22 = (c1 * m1x + c2 * mbx + c3 * nbx, c1 * m1y + c2 * mby + c3 * nby,
                             c1 * m1z + c2 * mbz + c3 * nbz)
            c1 = b3x * r1x + b3y * r1y + b3z * r1z
            c2 = b3x * mrx + b3y * mry + b3z * mrz
            c3 = b3x * nrx + b3y * nry + b3z * nrz
            dx, dy, dz = (c1 * m1x + c2 * mbx + c3 * nbx, c1 * m1y + c2 * mby + c3 * nby,
                          c1 * m1z + c2 * mbz + c3 * nbz)   # q3 = R^T b3d
            # attitude_torque_decoupled (tilt angle not needed here)
            kx_, ky_ = -dy, dx
            if dz > -1.0 + 1e-9:
                kv0, kv1, kv2 = ky_ * q12, -kx_ * q12, kx_ * q11 - ky_ * q10
                kkv0, kkv1 = ky_ * kv2, -kx_ * kv2
                w = 1.0 / (1.0 + dz)
                psi = math.atan2(q11 - kv1 + w * kkv1, q10 - kv0 + w * kkv0)
            else:
                psi = 0.0
            rho1, rho2 = self._rho
            z0, z1, z2 = rho1 * kx_, rho1 * ky_, rho2 * math.sin(psi)
            o0 = Od0 * q10 + Od1 * q20 + Od2 * dx
            o1 = Od0 * q11 + Od1 * q21 + Od2 * dy
            o2 = Od0 * q12 + Od1 * q22 + Od2 * dz
            oo0 = Odd0 * q10 + Odd1 * q20 + Odd2 * dx
            oo1 = Odd0 * q11 + Odd1 * q21 + Odd2 * dy
            oo2 = Odd0 * q12 + Odd1 * q22 + Odd2 * dz
            e0, e1, e2 = wx - o0, wy - o1, wz - o2
            Jw0, Jw1, Jw2 = J0 * wx, J1 * wy, J2 * wz
            alpha = self._alpha
            tx = (wy * Jw2 - wz * Jw1) + J0 * (oo0 - (wy * o2 - wz * o1) + z0 - alpha * e0)
            ty = (wz * Jw0 - wx * Jw2) + J1 * (oo1 - (wz * o0 - wx * o2) + z1 - alpha * e1)
            tz = (wx * Jw1 - wy * Jw0) + J2 * (oo2 - (wx * o1 - wy * o0) + z2 - alpha * e2)
            zV = (z0, z1, z2, dz, psi, (e0, e1, e2))
            V = None
            ia = self._ialpha
            self.last_rate_cmd = (o0 + ia * z0, o1 + ia * z1, o2 + ia * z2)
        else:
            (tx, ty, tz), zV, V = attitude_torque(self._J, gyro, (Od0, Od1, Od2), (Odd0, Odd1, Odd2),
                                                  ((m1x, m1y, m1z), (m2x, m2y, m2z)),
                                                  ((r1x, r1y, r1z), (r2x, r2y, r2z)), (b1x, b1y, b1z),
                                                  (b2x, b2y, b2z), (b3x, b3y, b3z), self._rho, self._alpha)
            self.last_rate_cmd = rate_command((Od0, Od1, Od2), zV, self._alpha)
        # f = F . (R e3), R e3 = r1 b1_z + mr mb_z + nr nb_z (thrust_axis_estimate)
        f = (F0 * (r1x * m1z + mrx * mbz + nrx * nbz) + F1 * (r1y * m1z + mry * mbz + nry * nbz)
             + F2 * (r1z * m1z + mrz * mbz + nrz * nbz))
        cmd, saturated = self.mixer.mix_fast(f, tx, ty, tz)
        self._thrust_prev = (cmd[0] + cmd[1] + cmd[2] + cmd[3]) * self._fmax
        self.last_desired = (b1x, b1y, b1z, b2x, b2y, b2z, b3x, b3y, b3z, f)
        self._last_detail = ((tx, ty, tz), saturated, (Od0, Od1, Od2), (ex0, ex1, ex2), (ev0, ev1, ev2), zV, V)
        return cmd

    def update_reference(self, t_s: float, meas: Measurements, ref: Reference) -> ControlOutput:
        """:meth:`update` as the plain composition of this module's pure functions (slower; the specification).

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
        """
        m, g = self._m, self._g
        kx, kv = self.cfg.kx, self.cfg.kv
        gyro = meas.gyro_flu_rad_s
        Omega = (float(gyro[0]), float(gyro[1]), float(gyro[2]))
        p, v = meas.pos_enu_m, meas.vel_enu_m_s
        t_nav = t_s if meas.nav_time_s is None else meas.nav_time_s
        obs = self.observer
        if obs is not None:
            obs.update(t_s, Omega, meas.accel_flu_m_s2, meas.mag_flu_gauss, p, v, meas.nav_time_s,
                       self._thrust_prev)
            if obs.t is None:
                raise ValueError("the observer has no attitude estimate yet")
            Omega = (Omega[0] - obs.b[0], Omega[1] - obs.b[1], Omega[2] - obs.b[2])
            p, v, t_nav = obs.p, obs.v, t_s
            fi = obs.fix_interval_s
            self.accel.tau_s = fi if fi > self._tau_a else self._tau_a
        a_hat = self.accel.update(t_nav, v, ref.jerk_enu_m_s3)
        if obs is not None:
            pairs = virtual_pairs(obs.R, self._h)
        else:
            pairs = controller_vectors(self._f_acc.update(t_s, unit3(meas.accel_flu_m_s2), Omega),
                                       self._f_mag.update(t_s, unit3(meas.mag_flu_gauss), Omega),
                                       a_hat, self._r2, g, self.cfg.mag_perpendicular, self._vectors, self._aided)
        b1, b2, r1, r2 = pairs.b1, pairs.b2, pairs.r1, pairs.r2
        self._pairs = (b1, b2, r1, r2)
        self._pv = (tuple(p), tuple(v))
        self._t_last = t_s

        xd, vd, ad, jd, sd = ref.pos_enu_m, ref.vel_enu_m_s, ref.acc_enu_m_s2, ref.jerk_enu_m_s3, ref.snap_enu_m_s4
        e_x = (p[0] - xd[0], p[1] - xd[1], p[2] - xd[2])
        e_v = (v[0] - vd[0], v[1] - vd[1], v[2] - vd[2])
        ev_dot = (a_hat[0] - ad[0], a_hat[1] - ad[1], a_hat[2] - ad[2])
        ki = self._ki
        if ki > 0.0:
            # the integral term: F_d gains -ki e_i, F_d_dot -ki e_i_dot, F_d_ddot -ki e_i_ddot
            e_i, active = self._integrate(t_s, e_x)
            ei_dot, ei_ddot = (e_x, e_v) if active else (_ZERO, _ZERO)
            ev_ddot = tuple(-(kx * e_v[i] + kv * ev_dot[i] + ki * ei_dot[i]) / m for i in range(3))
            F = (-kx * e_x[0] - kv * e_v[0] - ki * e_i[0] + m * ad[0],
                 -kx * e_x[1] - kv * e_v[1] - ki * e_i[1] + m * ad[1],
                 -kx * e_x[2] - kv * e_v[2] - ki * e_i[2] + m * (g + ad[2]))
            F_dot = tuple(-kx * e_v[i] - kv * ev_dot[i] - ki * ei_dot[i] + m * jd[i] for i in range(3))
            F_ddot = tuple(-kx * ev_dot[i] - kv * ev_ddot[i] - ki * ei_ddot[i] + m * sd[i] for i in range(3))
        else:
            ev_ddot = tuple(-(kx * e_v[i] + kv * ev_dot[i]) / m for i in range(3))
            F = (-kx * e_x[0] - kv * e_v[0] + m * ad[0],
                 -kx * e_x[1] - kv * e_v[1] + m * ad[1],
                 -kx * e_x[2] - kv * e_v[2] + m * (g + ad[2]))
            F_dot = tuple(-kx * e_v[i] - kv * ev_dot[i] + m * jd[i] for i in range(3))
            F_ddot = tuple(-kx * ev_dot[i] - kv * ev_ddot[i] + m * sd[i] for i in range(3))
        Sp = self.target_enu_m if ref.target_enu_m is None else ref.target_enu_m
        u_s = (Sp[0] - xd[0], Sp[1] - xd[1], Sp[2] - xd[2])
        u_s_dot, u_s_ddot = (-vd[0], -vd[1], -vd[2]), (-ad[0], -ad[1], -ad[2])
        if self.pointing is not None and dot(u_s, u_s) > 1e-12:
            # eq. (21) made flyable (companion.control.pointing): a unit vector
            # with consistent derivatives passes desired_attitude's _unit_d2 unchanged.
            u_s, u_s_dot, u_s_ddot = self.pointing.update(t_s, *unit_d2(u_s, u_s_dot, u_s_ddot))
        des = desired_attitude(F, F_dot, F_ddot, u_s, u_s_dot, u_s_ddot, self._b2_prev)
        self._b2_prev = des.b2d

        if self._decoupled:
            q = [body_coordinates(bd, b1, b2, r1, r2) for bd in (des.b1d, des.b2d, des.b3d)]
            res = attitude_torque_decoupled(self._J, Omega, des.Omega_d, des.Omega_d_dot, q[0], q[1], q[2],
                                            self._rho, self.cfg.alpha)
            tau, z, V = res.tau, res.z, res.V
            Od = des.Omega_d
            Od_body = tuple(Od[0] * q[0][i] + Od[1] * q[1][i] + Od[2] * q[2][i] for i in range(3))   # Q Omega_d
        else:
            tau, z, V = attitude_torque(self._J, Omega, des.Omega_d, des.Omega_d_dot, (b1, b2), (r1, r2),
                                        des.b1d, des.b2d, des.b3d, self._rho, self.cfg.alpha)
            Od_body = des.Omega_d
        rates = rate_command(Od_body, z, self.cfg.alpha)
        f = dot(F, thrust_axis_estimate(b1, b2, r1, r2))
        mc = self.mixer.mix(f, tau)
        self._thrust_prev = (mc.cmd[0] + mc.cmd[1] + mc.cmd[2] + mc.cmd[3]) * self._fmax
        return ControlOutput(f, tau, mc.cmd, mc.saturated, des.b3d, des.b2d, des.R_d, des.Omega_d,
                             e_x, e_v, z, V, rates)
