r"""Velocity-aided attitude observer on SO(3) and translational filter.

What it is for
--------------
The paper's law (eqs. 27-28) acts on body-frame vector measurements ``b_i =
R^T r_i`` of known world directions ``r_i``. A real vehicle does not have
such clean vectors: its accelerometer measures the specific force ``R^T (a
+ g e3)``, whose world direction turns with the acceleration, and its gyro
has a bias. This observer builds, from the IMU and the (noisy, slow,
delayed) position/velocity fix, an attitude estimate ``R_hat`` so that the
controller keeps working on vector pairs: the "virtual" measurements
``b_i = R_hat^T r_i`` of the constant directions ``r_1 = e3`` and ``r_2 =``
the horizontal Earth field (:func:`virtual_pairs`), with the bias-corrected
gyro. No full-state EKF: a complementary filter on SO(3) (Mahony, Hamel &
Pflimlin, IEEE TAC 53(5), 2008) whose tilt innovation is velocity-aided
(Hua, Control Eng. Practice 18(7), 2010; Hua, Martin & Hamel, Automatica
63, 2016), and a separate linear translational filter for the position and
velocity errors of eq. (23).

Frames: world ENU, body FLU, ``R`` body -> world, e3 up, SI units. Time is
the vehicle's, passed in; nothing here reads a clock, a file or a socket.

Attitude: propagation and the three innovations
-------------------------------------------------
Propagation with the bias-corrected gyro (trapezoidal rate over the frame,
exact exponential)::

    R_hat <- R_hat exp(S((Omega_k-1 + Omega_k)/2 - b_hat) dt)

Corrections (Mahony's passive filter: ``R_hat_dot = R_hat S(Omega_y - b_hat
+ sigma)``, ``b_hat_dot = -k_b sigma``, sigma the body-frame innovation):

1. Velocity-aided tilt (``velocity_aided``). For the specific force ``s_b``
   (body), ``v_dot = R s_b - g e3``, so over a window ``[tau_0, tau_1]``
   between two position/velocity fixes::

       u_meas = v(tau_1) - v(tau_0) + g e3 (tau_1 - tau_0)   (world, from the fixes)
       u_pred = int_{tau_0}^{tau_1} R_hat s_b dt              (world, from the IMU)

   and ``u_pred = u_meas`` when ``R_hat = R``. The innovation is the
   rotation that takes ``u_pred`` onto ``u_meas`` (axis ``u_pred x u_meas``,
   their angle ``phi``), applied as the world-frame correction ``R_hat <-
   exp(S(k_t dtau phi n)) R_hat`` (``dtau`` the time since the previous fix).
   This is the specific force compared with ``dv/dt + g e3`` on the
   vehicle's clock, integrated over the window so that the white noise of
   the velocity cancels between successive windows instead of being
   differentiated. The comparison is made at the fixes' *measurement* times
   (``nav_t``, which lags the IMU by the GNSS latency): the running integral
   ``int R_hat s_b`` is kept for a short history (``history_s``) and read
   at ``tau_0`` and ``tau_1``. A world-frame correction commutes with the
   body-frame gyro propagation (``E R_hat(tau) Phi = E R_hat(t)``), so the
   correction found at ``tau_1`` applies unchanged to the current estimate,
   and the stored integral is rotated with it (kept in a corrected frame,
   O(1)), so the next window sees only the remaining error.
   ``s_b`` is the accelerometer for ``vectors = "physical"``; for the
   paper's sensor model (``vectors = "paper"``, whose accelerometer fields
   carry ``g R^T e3``, not the specific force) it is the thrust axis ``e3``
   of the drag-free plant (eq. 20): only directions are compared.
   Gain: ``k_t`` (rad/s) from :func:`tilt_gain`, a scalar steady-state
   Kalman gain for a tilt that random-walks with the gyro noise and is
   measured with the window's velocity noise, capped at ``tilt_gain_max``.
   The fix noise is the assumed one or, by default, estimated online from
   the fixes (:meth:`VelocityAidedObserver.noise_std`), and the window
   grows with it (:meth:`VelocityAidedObserver.window`: one fix interval
   for exact fixes, ``window_s`` from 5 mm/s): the same defaults serve
   exact 250 Hz mocap fixes (k_t = 100/s) and 10 Hz RTK (k_t ~ 0.4/s). The
   aiding starts after 10 fixes (the noise estimate has samples).
2. Gravity (``gravity_gain``; used when velocity aiding is off, or with the
   paper's vectors): the accelerometer direction against ``e3``,
   ``sigma += k_g a_m x R_hat^T e3`` (|a_m| = 1). Right for the paper's
   inclinometer vectors; for a real accelerometer under a sustained
   acceleration ``a`` it converges to the wrong tilt ``atan(|a_h|/g)``
   (the test suite shows the difference).
3. Magnetometer, heading only: with ``z = R_hat^T e3`` and the measured
   field's component normal to it ``m_perp``, against the horizontal Earth
   field ``h`` (unit), ``sigma += k_m ((m_perp x R_hat^T h) . z) z``: a
   disturbed or inclined field never tilts the estimate.

Bias: ``b_hat <- b_hat - k_b dtheta_b`` for every body-frame correction
angle ``dtheta_b`` (``= sigma dt``, or ``R_hat^T`` the world correction), so
``b_hat_dot = -k_b sigma``; ``|b_hat|`` is projected onto ``bias_max``, and
only innovations below 0.1 rad are integrated (a 0.01 rad/s bias leaves
``b/k`` = 25 mrad at the slowest tilt rate, 0.4/s; the large errors of a
start-up or a wrong initialisation would wind the integral up).

Why it is stable
----------------
With two non-collinear constant directions and ``k_i > 0``, Mahony et al.
(2008, Thm 5.1) show that the passive complementary filter with bias
estimation converges almost globally (the unstable set has measure zero:
180 deg errors about the eigen-axes), locally exponentially; the linearised
error per axis, for a correction rate ``k`` and ``k_b``, is ``d_dot = b~ -
k d``, ``b~_dot = -k_b k d``: ``s^2 + k s + k k_b``, stable for every
positive ``k``, ``k_b``, critically damped at ``k = 4 k_b``. Velocity
aiding replaces the constant ``r_1 = e3`` by the measured direction of
``dv/dt + g e3``; Hua (2010) and Hua, Martin & Hamel (2016) show such
velocity-aided observers keep the (semi-)global convergence as long as the
specific force stays away from zero (no free fall: a hovering multirotor
has ``|s| ~ g``) and is not collinear with the field; windows whose
``|u_meas|`` is below ``g/2`` per second are skipped. Here the tilt loop is
``d_dot = -k_t d`` per fix (``k_t dtau <= 1``: the discrete step never
overshoots) and the heading loop ``-k_m``; the bias couples them as above.
For a large initial error ``phi_0`` (not 180 deg), the innovation is the
exact angle, so the error angle decreases monotonically at the rate ``k``:
``phi(t) <= phi_0 exp(-k t)`` without bias (the tests check it).

Translational filter (position/velocity for eq. 23)
----------------------------------------------------
Per world axis, the state ``(p, v, c)`` with ``p_dot = v``, ``v_dot = a_in +
c``, ``c`` a random-walk acceleration bias (the attitude error and the
accelerometer bias seen in the world); ``a_in = R_hat s_b - g e3`` (the
specific force; with the paper's vectors, the thrust model ``R_hat e3
f/m`` from the commanded rotor thrusts and the motors' time constant).
Propagated every IMU frame; each fix ``(p_y, v_y)`` at time ``tau`` is
compared with the state interpolated from the history at ``tau``, and the
steady-state Kalman correction ``K (y - H x(tau))`` (``K`` from the
discrete algebraic Riccati equation for the fix interval, solved by the
structure-preserving doubling algorithm in plain float arithmetic,
:func:`dare3`: the same bits on every machine, where LAPACK's QZ solve of
these 3x3 blocks depends on the BLAS build and, at the exact-fix corner,
is itself only good to ~1e-7) is carried forward to now exactly through the
kinematics (``dp + dv T + dc T^2/2``). Noise model: white acceleration
``accel_noise`` (m/s^2/sqrt(Hz)), bias walk ``accel_bias_walk``
(m/s^3/sqrt(Hz)), fix noise ``pos_std``, ``vel_std`` (floored at 1e-4:
float32 resolution). With exact fixes every frame ``K`` is ~identity and the
filter returns the fix itself (the paper's mocap assumption); with a 10 Hz,
100 ms-late RTK fix it gives the current position between fixes.

All state is bounded: the history keeps ``history_s`` of frames.

Degraded measurements
---------------------
A value physics allows never raises here; the observer skips what it cannot
use and counts it in ``faults`` (kind: number of frames):

- ``free_fall``: specific force below ``FREE_FALL_FRACTION`` g (a falling
  vehicle: its accelerometer reads ~0). The specific force itself is right
  (the translational filter integrates ``v_dot = -g e3``); only its direction
  is undefined: no gravity innovation, the tilt vector keeps its last value,
  the attitude propagates on the gyro (the velocity-aided tilt already skips
  windows near free fall);
- ``accel``: a non-finite accelerometer sample: the last valid specific
  force is used, no gravity innovation;
- ``gyro``: a non-finite rate: the last valid rate propagates the attitude;
- ``mag``: a zero, non-finite or vertical (along the estimated up) field:
  no heading innovation (a saturated but finite one is used: the heading
  innovation cannot tilt the estimate);
- ``fix``: a non-finite position, velocity or fix time: the fix is skipped;
- ``time``: a non-finite frame time: the frame is skipped.

Initialisation waits for an accelerometer with a direction and a finite fix
(the controller raises ValueError until then: the flight core lets the
vehicle fly those frames); without a usable
magnetometer it takes the heading of the body x axis as the world x axis
(TRIAD with that pair) and the heading innovation corrects it once the field
is usable.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import deque
from dataclasses import dataclass
from operator import itemgetter


from mavcore.so3 import Mat3, Vec3, mat_apply, mat_apply_t, mat_mul, orthonormalise, so3_exp, triad_rotation, unit
from .vectors import BodyVectorFilter

_E3 = (0.0, 0.0, 1.0)
_POS_STD_FLOOR_M = 1e-6
_VEL_STD_FLOOR_M_S = 1e-6
_N_NOISE_MIN = 10        # fixes seen before the velocity-aided tilt starts (noise estimate settled)
_BIAS_GATE_RAD = 0.1     # the bias integrates only innovations smaller than this (no wind-up on transients)
_TIME = itemgetter(0)    # the time of a history or fix entry (both deques are sorted by it)
#: Below this fraction of g the specific force has no usable direction (free fall, a falling
#: vehicle with its motors stopped): its vector is skipped, the attitude propagates on the gyro.
FREE_FALL_FRACTION = 0.1
#: Kinds of degraded frames counted in ``VelocityAidedObserver.faults`` (docs: module docstring).
FAULT_KINDS = ("free_fall", "accel", "gyro", "mag", "fix", "time")


def _finite3(x: float, y: float, z: float) -> bool:
    return math.isfinite(x) and math.isfinite(y) and math.isfinite(z)


def horizontal_field(mag_field_enu) -> Vec3:
    """The unit horizontal direction of the Earth field (ENU); ValueError if the field is vertical."""
    return unit(float(mag_field_enu[0]), float(mag_field_enu[1]), 0.0)


def heading_from_accel_mag(accel_flu, mag_flu, mag_field_enu_gauss) -> float:
    """Heading of the body x axis (ENU yaw, rad, CCW from east) of a vehicle at rest.

    At rest the accelerometer measures the reaction to gravity, ``R^T g e3``
    (body up), and the magnetometer ``R^T m`` with ``m`` the Earth field
    (world ENU, e.g. pointing north and down). TRIAD with the vertical as the
    exact pair gives ``R``; the heading is ``atan2(R[1,0], R[0,0])``, the
    direction of the body x axis projected on the horizontal, whatever the
    tilt. The field's declination is in ``mag_field_enu_gauss`` (its
    horizontal part need not point north). Used for the take-off instead
    of the vehicle's attitude report.

    Parameters
    ----------
    accel_flu : sequence (3,)
        Accelerometer, body FLU (m/s^2; only the direction is used). With
        the paper's vector sensors (``g R^T e3``) the same.
    mag_flu : sequence (3,)
        Magnetometer, body FLU (any unit).
    mag_field_enu_gauss : sequence (3,)
        The Earth field, world ENU (not vertical).

    Returns
    -------
    float
        Yaw in (-pi, pi] (rad), ENU: 0 = body x east, pi/2 = north.
    """
    R = triad_rotation(accel_flu, mag_flu, _E3, mag_field_enu_gauss)
    return math.atan2(R[3], R[0])


@dataclass(frozen=True, slots=True)
class VirtualPairs:
    """The controller's vector pairs from the attitude estimate: ``b_i = R_hat^T r_i``.

    Attributes
    ----------
    b1, r1 : tuple (3,)
        Body FLU / world ENU unit vectors of the vertical (``r1 = e3``).
    b2, r2 : tuple (3,)
        Body FLU / world ENU unit vectors of the horizontal Earth field.
    """

    b1: Vec3
    b2: Vec3
    r1: Vec3
    r2: Vec3


def virtual_pairs(R_hat: Mat3, h_enu: Vec3) -> VirtualPairs:
    """``(R_hat^T e3, R_hat^T h)`` against ``(e3, h)``; ``R_hat`` row-major 9-tuple, ``h`` horizontal unit (ENU)."""
    b1 = (R_hat[6], R_hat[7], R_hat[8])
    hx, hy, hz = h_enu
    b2 = (R_hat[0] * hx + R_hat[3] * hy + R_hat[6] * hz, R_hat[1] * hx + R_hat[4] * hy + R_hat[7] * hz,
          R_hat[2] * hx + R_hat[5] * hy + R_hat[8] * hz)
    return VirtualPairs(b1, b2, _E3, (hx, hy, hz))


# --- gains --------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class NavGains:
    """Steady-state Kalman gain of the per-axis translational filter for one fix interval.

    Attributes
    ----------
    K : tuple of 3 rows of 2
        ``K[i][j]``: state i (p m, v m/s, c m/s^2) per innovation j (p m, v m/s).
    """

    K: tuple


def nav_gains(dt_s: float, pos_std_m: float, vel_std_m_s: float, accel_noise: float,
              accel_bias_walk: float) -> NavGains:
    """Steady-state Kalman gain of the ``(p, v, c)`` filter (one axis) for fixes every ``dt_s``.

    Model: ``p_dot = v``, ``v_dot = a_in + c + w_a``, ``c_dot = w_c``
    (white ``w_a`` of density ``accel_noise`` m/s^2/sqrt(Hz), ``w_c`` of
    density ``accel_bias_walk`` m/s^3/sqrt(Hz)), discretised exactly over
    ``dt_s``; measurement ``(p, v)`` with white noise ``pos_std_m``,
    ``vel_std_m_s`` (each floored at 1e-4). The a-priori covariance solves
    the discrete algebraic Riccati equation (:func:`dare3`);
    ``K = P H^T (H P H^T + R)^-1`` (a 2x2 inverse, written out).

    Returns
    -------
    NavGains
    """
    T = float(dt_s)
    A = ((1.0, T, 0.5 * T * T), (0.0, 1.0, T), (0.0, 0.0, 1.0))
    qa, qc = float(accel_noise) ** 2, float(accel_bias_walk) ** 2
    T2, T3, T4, T5 = T * T, T ** 3, T ** 4, T ** 5
    Q = ((qa * T3 / 3 + qc * T5 / 20, qa * T2 / 2 + qc * T4 / 8, qc * T3 / 6),
         (qa * T2 / 2 + qc * T4 / 8, qa * T + qc * T3 / 3, qc * T2 / 2),
         (qc * T3 / 6, qc * T2 / 2, qc * T))
    rp = max(pos_std_m, _POS_STD_FLOOR_M) ** 2
    rv = max(vel_std_m_s, _VEL_STD_FLOOR_M_S) ** 2
    # the filter's equation in the control form of dare3: a = A^T, G = H^T R^-1 H
    P = dare3(_t3(A), ((1.0 / rp, 0.0, 0.0), (0.0, 1.0 / rv, 0.0), (0.0, 0.0, 0.0)), Q)
    s00, s01, s10, s11 = P[0][0] + rp, P[0][1], P[1][0], P[1][1] + rv
    det = s00 * s11 - s01 * s10
    i00, i01, i10, i11 = s11 / det, -s01 / det, -s10 / det, s00 / det
    return NavGains(tuple((P[r][0] * i00 + P[r][1] * i10, P[r][0] * i01 + P[r][1] * i11) for r in range(3)))


def _t3(X):
    return tuple(tuple(X[c][r] for c in range(3)) for r in range(3))


def _mm3(X, Y):
    return tuple(tuple(X[r][0] * Y[0][c] + X[r][1] * Y[1][c] + X[r][2] * Y[2][c] for c in range(3))
                 for r in range(3))


def _add3(X, Y):
    return tuple(tuple(X[r][c] + Y[r][c] for c in range(3)) for r in range(3))


def _inv3(M):
    """Inverse of a 3x3 matrix by its cofactors (ValueError when singular)."""
    (a, b, c), (d, e, f), (g, h, i) = M
    A, B, C = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * A + b * B + c * C
    if not (det != 0.0 and math.isfinite(det)):
        raise ValueError("singular matrix")
    return ((A / det, (c * h - b * i) / det, (b * f - c * e) / det),
            (B / det, (a * i - c * g) / det, (c * d - a * f) / det),
            (C / det, (b * g - a * h) / det, (a * e - b * d) / det))


_I3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def dare3(a, G, Q, max_iter: int = 64):
    """Stabilising solution ``X`` of ``X = a^T X (I + G X)^-1 a + Q`` (3x3, tuples of rows).

    With ``G = b r^-1 b^T`` this is the discrete algebraic Riccati equation
    ``X = a^T X a - a^T X b (r + b^T X b)^-1 b^T X a + Q`` (scipy's
    ``solve_discrete_are(a, b, Q, r)``, which the tests compare). Solved by
    the structure-preserving doubling algorithm (Chu, Fan, Lin & Wang,
    J. Phys. A 37, 2004): ``W = I + G_k H_k``, ``A_k+1 = A_k W^-1 A_k``,
    ``G_k+1 = G_k + A_k W^-1 G_k A_k^T``, ``H_k+1 = H_k + A_k^T H_k W^-1 A_k``
    from ``(a, G, Q)``; ``H_k`` converges quadratically to ``X`` (8-25
    iterations for the observer's gains). Plain float arithmetic in a fixed
    order: the result is the same bits on every IEEE-754 machine.

    Raises
    ------
    ValueError
        No convergence in ``max_iter`` doublings (or a singular step).
    """
    A, Gk, Hk = a, G, Q
    for _ in range(max_iter):
        Wi = _inv3(_add3(_I3, _mm3(Gk, Hk)))
        AW = _mm3(A, Wi)
        G1 = _add3(Gk, _mm3(_mm3(AW, Gk), _t3(A)))
        H1 = _add3(Hk, _mm3(_mm3(_t3(A), Hk), _mm3(Wi, A)))
        A = _mm3(AW, A)
        step = max(abs(H1[r][c] - Hk[r][c]) for r in range(3) for c in range(3))
        size = max(abs(H1[r][c]) for r in range(3) for c in range(3))
        Gk, Hk = G1, H1
        if step <= 1e-15 * size:
            return Hk
        if not math.isfinite(step):
            break
    raise ValueError("Riccati doubling did not converge")


def tilt_gain(dt_s: float, window_s: float, vel_std_m_s: float, gyro_noise: float, gravity_m_s2: float,
              gain_max_rad_s: float) -> float:
    """Correction rate ``k_t`` (rad/s) of the velocity-aided tilt innovation for one fix.

    A scalar steady-state Kalman gain: the tilt error random-walks with the
    gyro noise (density ``gyro_noise`` rad/s/sqrt(Hz): variance ``q =
    gyro_noise^2 dt`` per fix) and each window measures it with the noise
    of two velocity fixes, ``r = 2 vel_std^2 / (g window)^2`` (rad^2);
    ``P = (q + sqrt(q^2 + 4 q r)) / 2`` (a priori), ``K = P / (P + r)``,
    ``k_t = K / dt``, capped at ``gain_max_rad_s`` and at ``1/dt``. Overlapping
    windows are treated as independent: a gain schedule, not an optimal
    filter. ``vel_std_m_s`` is floored at 1e-4.
    """
    if not dt_s > 0.0:
        return 0.0
    q = gyro_noise * gyro_noise * dt_s
    r = 2.0 * max(vel_std_m_s, _VEL_STD_FLOOR_M_S) ** 2 / (gravity_m_s2 * max(window_s, dt_s)) ** 2
    P = 0.5 * (q + math.sqrt(q * q + 4.0 * q * r))
    k = P / (P + r) / dt_s
    return min(k, gain_max_rad_s, 1.0 / dt_s)


# --- the observer ---------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class AttitudeEstimate:
    """The observer's (or the vector pairs') current estimate.

    Attributes
    ----------
    time_s : float
        Vehicle time of the estimate (s).
    R_enu_flu : tuple (9,)
        Attitude, body FLU -> world ENU, row-major.
    gyro_bias_flu_rad_s : tuple (3,)
        Estimated gyro bias (rad/s, body FLU); zeros without the observer.
    pos_enu_m, vel_enu_m_s : tuple (3,)
        Position (m) and velocity (m/s) used by the controller, world ENU.
    """

    time_s: float
    R_enu_flu: Mat3
    gyro_bias_flu_rad_s: Vec3
    pos_enu_m: Vec3
    vel_enu_m_s: Vec3


class VelocityAidedObserver:
    """The observer of the module docstring (a pure state machine on the vehicle clock).

    Parameters
    ----------
    mag_field_enu_gauss : sequence (3,)
        Earth field, world ENU (only its horizontal direction is used).
    gravity_m_s2 : float
    paper_vectors : bool
        The accelerometer fields carry the paper's ``g R^T e3`` (not the specific force).
    velocity_aided : bool
        Use the velocity-aided tilt innovation.
    tilt_gain_max_rad_s, gravity_gain_rad_s, mag_gain_rad_s : float
        Cap of the velocity-aided tilt rate; rates of the gravity and heading innovations (1/s).
    bias_gain_1_s, bias_max_rad_s : float
        ``k_b`` and the bound of ``|b_hat|``.
    window_s : float
        Velocity window of the tilt innovation (s) once the fixes are noisy
        (:meth:`window`); one fix interval with exact fixes.
    history_s : float
        Length of the kept history (s): the longest fix latency + window handled.
    pos_std_m, vel_std_m_s : float
        Fix noise assumed (floors of the online estimate with ``adaptive``).
    accel_noise, accel_bias_walk, gyro_noise : float
        Noise densities of the gains (see :func:`nav_gains`, :func:`tilt_gain`).
    mass_kg, motor_time_constant_s : float
        For the thrust model with the paper's vectors.
    accel_direction_gain_rad_s : float
        Body-frame low-pass gain on the accelerometer direction used by the
        tilt innovation (0: raw). The specific force of a drag-free
        multirotor is fixed in the body (``e3``): its noise is pure noise.
    adaptive : bool
        Estimate the fix noise online (:meth:`noise_std`) and use it when it
        exceeds the assumed one.
    """

    def __init__(self, mag_field_enu_gauss, gravity_m_s2: float, *, paper_vectors: bool, velocity_aided: bool,
                 tilt_gain_max_rad_s: float, gravity_gain_rad_s: float, mag_gain_rad_s: float,
                 bias_gain_1_s: float, bias_max_rad_s: float, window_s: float, history_s: float,
                 pos_std_m: float, vel_std_m_s: float, accel_noise: float, accel_bias_walk: float,
                 gyro_noise: float, mass_kg: float, motor_time_constant_s: float,
                 accel_direction_gain_rad_s: float = 0.0, adaptive: bool = True) -> None:
        self.field = tuple(float(x) for x in mag_field_enu_gauss)
        self.h = horizontal_field(self.field)
        self.g = float(gravity_m_s2)
        self.paper = bool(paper_vectors)
        self.aided = bool(velocity_aided)
        self.k_t_max = float(tilt_gain_max_rad_s)
        self.k_g = float(gravity_gain_rad_s) if (self.paper or not self.aided) else 0.0
        self.k_m = float(mag_gain_rad_s)
        self.k_b = float(bias_gain_1_s)
        self.b_max = float(bias_max_rad_s)
        self.window_max_s = float(window_s)
        self.history_s = float(history_s)
        self.pos_std, self.vel_std = float(pos_std_m), float(vel_std_m_s)
        self.accel_noise, self.accel_bias_walk = float(accel_noise), float(accel_bias_walk)
        self.gyro_noise = float(gyro_noise)
        self.m = float(mass_kg)
        self.tau_m = float(motor_time_constant_s)
        self.accel_direction_gain = float(accel_direction_gain_rad_s)
        self.adaptive = bool(adaptive)
        self._gains: dict = {}
        self.reset()

    def reset(self) -> None:
        """Forget everything: the next :meth:`update` initialises from its measurements (at rest)."""
        self.t: float | None = None
        self.R: Mat3 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
        self.b: Vec3 = (0.0, 0.0, 0.0)
        self.p: Vec3 = (0.0, 0.0, 0.0)
        self.v: Vec3 = (0.0, 0.0, 0.0)
        self.c: Vec3 = (0.0, 0.0, 0.0)
        self._w: Vec3 = (0.0, 0.0, 0.0)      # previous gyro
        self._fw: Vec3 = (0.0, 0.0, 0.0)     # previous R_hat s_b (world)
        self._uw: Vec3 = (0.0, 0.0, 0.0)     # previous R_hat u_b (world), u_b the tilt body vector
        self._S: Vec3 = (0.0, 0.0, 0.0)      # int R_hat u_b dt, in the current frame
        self._A: Vec3 = (0.0, 0.0, 0.0)      # int a_in dt (the IMU's velocity increments, world)
        self._C: Mat3 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
        # (t, S_raw, p, v, A) per frame; S_raw = C^T S when stored, so C S_raw follows later corrections
        self._hist: deque = deque()
        self._fixes: deque = deque()         # (tau, p, v, A(tau)) of past fixes
        self._tau: float | None = None
        self.fix_interval_s = 0.0            # time between the last two fixes (s)
        self._f_model: float | None = None
        self._ub_filter = BodyVectorFilter(self.accel_direction_gain, propagate=False)
        self._var_v = [0.0, 0.0]             # running means of the fix-noise variances: horizontal, vertical
        self._var_p = [0.0, 0.0]
        self._n_noise = 0
        self._n = 0
        self.n_late_fixes = 0
        self.n_tilt_updates = 0
        #: Degraded frames per kind (module docstring, "Degraded measurements").
        self.faults = dict.fromkeys(FAULT_KINDS, 0)
        self._sb: Vec3 = (0.0, 0.0, 0.0)     # last valid body specific force
        self._ub: Vec3 = _E3                 # last tilt body vector (unit)

    # -- outputs ------------------------------------------------------------------------

    @property
    def initialised(self) -> bool:
        """An update has initialised the state."""
        return self.t is not None

    def estimate(self) -> AttitudeEstimate:
        """The current estimate (:class:`AttitudeEstimate`); ValueError before the first update."""
        if self.t is None:
            raise ValueError("the observer has no measurement yet")
        return AttitudeEstimate(self.t, self.R, self.b, self.p, self.v)

    def noise_std(self, axis: int = 0) -> tuple[float, float]:
        """(position m, velocity m/s) fix noise used by the gains, horizontal (``axis`` 0,
        per axis) or vertical (1): the assumed values or, with ``adaptive``, the online
        estimates when larger (GNSS is noisier vertically).

        Online estimate, per axis, from fixes ``k-2, k-1, k`` (intervals
        ``T1``, ``T``): the second divided difference of ``w = v - A``, ``A =
        int a_in`` the IMU's predicted velocity (so the vehicle's jerk and a
        constant attitude error cancel), ``d = (w_k - w_k-1)/T - (w_k-1 -
        w_k-2)/T1``, has variance ``sigma_v^2 (1/T^2 + (1/T + 1/T1)^2 +
        1/T1^2) + accel_noise^2 (1/T + 1/T1)``; the position residual ``p_k -
        p_k-1 - T (v_k + v_k-1)/2`` has ``2 sigma_p^2 + T^2 sigma_v^2 / 2``.
        The variance samples are averaged over ~5 s (a running mean at first),
        over x and y for the horizontal figure, z for the vertical one.
        """
        sv, sp = self.vel_std, self.pos_std
        if self.adaptive and self._n_noise >= 1:
            if self._var_v[axis] > sv * sv:
                sv = math.sqrt(self._var_v[axis])
            if self._var_p[axis] > sp * sp:
                sp = math.sqrt(self._var_p[axis])
        return sp, sv

    def window(self, vel_std_m_s: float) -> float:
        """Velocity window of the tilt innovation (s): ``window_s`` scaled by
        ``min(1, vel_std / 5 mm/s)`` (0: one fix interval, right for exact fixes)."""
        return self.window_max_s * min(1.0, vel_std_m_s / 0.005)

    # -- one frame -------------------------------------------------------------------------

    def update(self, t_s: float, gyro, accel, mag, pos, vel, nav_t: float | None, thrust_n: float | None = None):
        """Feed one IMU frame and the latest position/velocity fix.

        Parameters
        ----------
        t_s : float
            Vehicle time of the IMU frame (s).
        gyro, accel, mag : sequence (3,)
            Body FLU: rate (rad/s), accelerometer (m/s^2), field (gauss).
        pos, vel : sequence (3,)
            The latest fix, world ENU (m, m/s).
        nav_t : float or None
            Its measurement time (s); a value later than the previous one is
            a new fix. None: measured at ``t_s`` (a new fix every frame).
        thrust_n : float or None
            Collective thrust (N) the previous motor commands asked for (the
            thrust model with the paper's vectors); None: keep the last.

        Returns
        -------
        None (read :attr:`R`, :attr:`b`, :attr:`p`, :attr:`v` or :meth:`estimate`).
        """
        faults = self.faults
        if not math.isfinite(t_s):
            faults["time"] += 1
            return
        wx, wy, wz = float(gyro[0]), float(gyro[1]), float(gyro[2])
        ax, ay, az = float(accel[0]), float(accel[1]), float(accel[2])
        if not _finite3(wx, wy, wz):
            faults["gyro"] += 1
            wx, wy, wz = self._w
        a_ok = _finite3(ax, ay, az)
        if not a_ok:
            faults["accel"] += 1
            ax, ay, az = self._sb
        a_dir = a_ok and ax * ax + ay * ay + az * az >= (FREE_FALL_FRACTION * self.g) ** 2
        if a_ok and not a_dir:
            faults["free_fall"] += 1
        fix_ok = (nav_t is None or math.isfinite(nav_t)) and _finite3(*(float(x) for x in pos)) \
            and _finite3(*(float(x) for x in vel))
        if not fix_ok:
            faults["fix"] += 1
        if self.t is None:
            if not (a_dir and fix_ok):
                return                       # no vertical (or no position) yet: wait for one
            if thrust_n is not None:
                self._f_model = float(thrust_n)
            self._initialise(t_s, (wx, wy, wz), (ax, ay, az), mag, pos, vel, t_s if nav_t is None else
                             min(float(nav_t), t_s))
            return
        tau = (t_s if nav_t is None else min(float(nav_t), t_s)) if fix_ok else self._tau
        dt = t_s - self.t
        if not dt > 0.0:
            return
        self._sb = (ax, ay, az)
        g = self.g
        # --- thrust model (paper's vectors) -------------------------------------------
        if self.paper and thrust_n is not None:
            f = self._f_model
            beta = 1.0 - math.exp(-dt / self.tau_m) if self.tau_m > 0.0 else 1.0
            self._f_model = f + beta * (float(thrust_n) - f)
        # --- attitude propagation -----------------------------------------------------
        bx, by, bz = self.b
        pw = self._w
        h = 0.5 * dt
        R = mat_mul(self.R, so3_exp(h * (pw[0] + wx) - dt * bx, h * (pw[1] + wy) - dt * by, h * (pw[2] + wz) - dt * bz))
        # --- frame innovations: gravity, heading ---------------------------------------
        sx = sy = sz = 0.0
        if self.k_g > 0.0 and a_dir:
            ux, uy, uz = unit(ax, ay, az)
            zx, zy, zz = R[6], R[7], R[8]                       # R^T e3
            k = self.k_g
            sx, sy, sz = k * (uy * zz - uz * zy), k * (uz * zx - ux * zz), k * (ux * zy - uy * zx)
        if self.k_m > 0.0:
            zx, zy, zz = R[6], R[7], R[8]
            mx, my, mz = float(mag[0]), float(mag[1]), float(mag[2])
            c = mx * zx + my * zy + mz * zz
            px, py, pz = mx - c * zx, my - c * zy, mz - c * zz
            n = math.sqrt(px * px + py * py + pz * pz)
            if not n > 0.0:                 # zero, non-finite or vertical: no heading this frame
                faults["mag"] += 1
            else:
                px, py, pz = px / n, py / n, pz / n
                hx, hy, hz = mat_apply_t(R, *self.h)               # R^T h (normal to R^T e3)
                k = self.k_m * ((py * hz - pz * hy) * zx + (pz * hx - px * hz) * zy + (px * hy - py * hx) * zz)
                sx, sy, sz = sx + k * zx, sy + k * zy, sz + k * zz
        if sx != 0.0 or sy != 0.0 or sz != 0.0:
            R = mat_mul(R, so3_exp(sx * dt, sy * dt, sz * dt))
            if sx * sx + sy * sy + sz * sz < (_BIAS_GATE_RAD * (self.k_g + self.k_m)) ** 2:
                self._bias_step(sx * dt, sy * dt, sz * dt)
        self._n += 1
        if self._n % 64 == 0:
            R = orthonormalise(R)
        self.R = R
        # --- translational propagation and the tilt integral ---------------------------
        if self.paper:
            sbx, sby, sbz = 0.0, 0.0, self._f_model / self.m
            ubx, uby, ubz = _E3
        else:
            sbx, sby, sbz = ax, ay, az
            if a_dir:
                self._ub = self._ub_filter.step(t_s, *unit(ax, ay, az), 0.0, 0.0, 0.0)
            ubx, uby, ubz = self._ub
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = R
        fw = (r0 * sbx + r1 * sby + r2 * sbz, r3 * sbx + r4 * sby + r5 * sbz, r6 * sbx + r7 * sby + r8 * sbz)
        uw = (r0 * ubx + r1 * uby + r2 * ubz, r3 * ubx + r4 * uby + r5 * ubz, r6 * ubx + r7 * uby + r8 * ubz)
        cx, cy, cz = self.c
        a0 = 0.5 * (self._fw[0] + fw[0]) + cx
        a1 = 0.5 * (self._fw[1] + fw[1]) + cy
        a2 = 0.5 * (self._fw[2] + fw[2]) - g + cz
        p, v = self.p, self.v
        self.p = (p[0] + dt * v[0] + h * dt * a0, p[1] + dt * v[1] + h * dt * a1, p[2] + dt * v[2] + h * dt * a2)
        self.v = (v[0] + dt * a0, v[1] + dt * a1, v[2] + dt * a2)
        A = self._A
        self._A = (A[0] + dt * a0, A[1] + dt * a1, A[2] + dt * a2)
        S = self._S
        self._S = (S[0] + h * (self._uw[0] + uw[0]), S[1] + h * (self._uw[1] + uw[1]), S[2] + h * (self._uw[2] + uw[2]))
        self._fw, self._uw, self._w, self.t = fw, uw, (wx, wy, wz), t_s
        self._push(t_s)
        # --- a new fix ---------------------------------------------------------------------
        if tau > self._tau:
            self._fix(tau, pos, vel)

    # -- pieces ------------------------------------------------------------------------------

    def _body_vectors(self, t_s: float, ax: float, ay: float, az: float):
        """(s_b, u_b): the body specific force of the translational filter and the tilt vector."""
        if self.paper:
            return (0.0, 0.0, self._f_model / self.m), _E3
        self._ub = self._ub_filter.step(t_s, *unit(ax, ay, az), 0.0, 0.0, 0.0)
        return (ax, ay, az), self._ub

    def _initialise(self, t_s, w, a, mag, pos, vel, tau) -> None:
        """At rest: R from TRIAD (accelerometer as the vertical, magnetometer), zero bias.
        ``a`` has a direction (the caller checks); a magnetometer without a usable direction
        (zero, non-finite, along ``a``) gives the heading of the body x axis as world x."""
        mx, my, mz = float(mag[0]), float(mag[1]), float(mag[2])
        a0, a1, a2 = a
        cx, cy, cz = a1 * mz - a2 * my, a2 * mx - a0 * mz, a0 * my - a1 * mx
        if _finite3(mx, my, mz) and cx * cx + cy * cy + cz * cz > 1e-12 * (a0 * a0 + a1 * a1 + a2 * a2) * (
                mx * mx + my * my + mz * mz):
            self.R = triad_rotation(a, (mx, my, mz), _E3, self.field)
        else:
            self.faults["mag"] += 1
            ex = (1.0, 0.0, 0.0) if abs(a0) < 0.9 * math.sqrt(a0 * a0 + a1 * a1 + a2 * a2) else (0.0, 1.0, 0.0)
            self.R = triad_rotation(a, ex, _E3, ex)
        self._sb = (float(a0), float(a1), float(a2))
        self.t = t_s
        self._w = w
        self.p = (float(pos[0]), float(pos[1]), float(pos[2]))
        self.v = (float(vel[0]), float(vel[1]), float(vel[2]))
        if self._f_model is None:
            self._f_model = self.m * self.g          # hover until a command says otherwise
        sb, ub = self._body_vectors(t_s, *a)
        self._fw = mat_apply(self.R, *sb)
        self._uw = mat_apply(self.R, *ub)
        self._push(t_s)
        self._tau = tau
        self._fixes.append((tau, self.p, self.v, self._A))

    def _bias_step(self, dx: float, dy: float, dz: float) -> None:
        """``b_hat -= k_b dtheta_b`` (body correction angle), projected onto ``|b_hat| <= bias_max``."""
        k = self.k_b
        if k <= 0.0:
            return
        bx, by, bz = self.b[0] - k * dx, self.b[1] - k * dy, self.b[2] - k * dz
        n = math.sqrt(bx * bx + by * by + bz * bz)
        if n > self.b_max:
            s = self.b_max / n
            bx, by, bz = bx * s, by * s, bz * s
        self.b = (bx, by, bz)

    def _push(self, t_s: float) -> None:
        hist = self._hist
        hist.append((t_s, mat_apply_t(self._C, *self._S), self.p, self.v, self._A))
        t_old = t_s - self.history_s
        while len(hist) > 2 and hist[1][0] <= t_old:
            hist.popleft()

    def _at(self, tau: float):
        """(i, w): tau between hist[i] and hist[i+1] at weight w (0: at hist[i]); None: older than the history."""
        hist = self._hist
        i = len(hist) - 1
        if tau >= hist[i][0]:
            return i, 0.0
        # the times increase strictly: hist[i - 1] <= tau < hist[i] (a NaN tau: the last interval)
        i = min(bisect_right(hist, tau, key=_TIME), i)
        if i == 0:
            return None
        t0, t1 = hist[i - 1][0], hist[i][0]
        return i - 1, (tau - t0) / (t1 - t0)

    def _interp(self, i: int, w: float, field: int) -> Vec3:
        a = self._hist[i][field]
        if w == 0.0:
            return a
        b = self._hist[i + 1][field]
        return (a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1]), a[2] + w * (b[2] - a[2]))

    def _fix(self, tau: float, pos, vel) -> None:
        dtau = tau - self._tau
        self._tau = tau
        self.fix_interval_s = dtau
        py = (float(pos[0]), float(pos[1]), float(pos[2]))
        vy = (float(vel[0]), float(vel[1]), float(vel[2]))
        hist = self._hist
        last = hist[-1]
        if tau >= last[0]:                   # measured at the latest frame (no latency): that entry
            i, w = len(hist) - 1, 0.0
            pt, vt, At = last[2], last[3], last[4]
        else:
            at = self._at(tau)
            if at is None:                   # older than the history: cannot be placed
                self.n_late_fixes += 1
                return
            i, w = at
            At = self._interp(i, w, 4)
            pt, vt = self._interp(i, w, 2), self._interp(i, w, 3)
        self._noise_step(dtau, py, vy, At)
        sp, sv = self.noise_std(0)
        # --- translational filter: innovation at tau, carried to every later frame -----
        (k00, k01), (k10, k11), (k20, k21) = self._nav_gains(dtau, sp, sv)        # x and y
        (z00, z01), (z10, z11), (z20, z21) = self._nav_gains(dtau, *self.noise_std(1))   # z
        ep0, ep1, ep2 = py[0] - pt[0], py[1] - pt[1], py[2] - pt[2]
        ev0, ev1, ev2 = vy[0] - vt[0], vy[1] - vt[1], vy[2] - vt[2]
        dp0, dp1, dp2 = k00 * ep0 + k01 * ev0, k00 * ep1 + k01 * ev1, z00 * ep2 + z01 * ev2
        dv0, dv1, dv2 = k10 * ep0 + k11 * ev0, k10 * ep1 + k11 * ev1, z10 * ep2 + z11 * ev2
        dc0, dc1, dc2 = k20 * ep0 + k21 * ev0, k20 * ep1 + k21 * ev1, z20 * ep2 + z21 * ev2
        for j in range(i + (1 if w > 0.0 else 0), len(hist)):
            tj, Sj, pj, vj, Aj = hist[j]
            T = tj - tau
            hT = 0.5 * T * T
            hist[j] = (tj, Sj,
                       (pj[0] + dp0 + T * dv0 + hT * dc0, pj[1] + dp1 + T * dv1 + hT * dc1,
                        pj[2] + dp2 + T * dv2 + hT * dc2),
                       (vj[0] + dv0 + T * dc0, vj[1] + dv1 + T * dc1, vj[2] + dv2 + T * dc2), Aj)
        self.p, self.v = hist[-1][2], hist[-1][3]
        c = self.c
        self.c = (c[0] + dc0, c[1] + dc1, c[2] + dc2)
        # --- velocity-aided tilt (once the noise of the fixes is known) --------------------------
        if self.aided and (self._n_noise >= _N_NOISE_MIN or not self.adaptive):
            self._tilt(tau, dtau, i, w, vy, sv)
        fixes = self._fixes
        fixes.append((tau, py, vy, At))
        t_old = tau - self.history_s
        while len(fixes) > 2 and fixes[1][0] <= t_old:
            fixes.popleft()

    def _noise_step(self, T: float, py: Vec3, vy: Vec3, At: Vec3) -> None:
        """Update the running means of the fix-noise variance samples (see :meth:`noise_std`)."""
        fixes = self._fixes
        if not self.adaptive or len(fixes) < 2 or not T > 0.0:
            return
        tau1, p1, v1, A1 = fixes[-1]
        tau0, _, v0, A0 = fixes[-2]
        T1 = tau1 - tau0
        if not T1 > 0.0:
            return
        # second divided difference of w = v - A: d = (w2 - w1)/T - (w1 - w0)/T1
        c = 1.0 / (T * T) + (1.0 / T + 1.0 / T1) ** 2 + 1.0 / (T1 * T1)
        qa = self.accel_noise * self.accel_noise * (1.0 / T + 1.0 / T1)
        # per axis k: ((vy - At - v1 + A1) / T - (v1 - A1 - v0 + A0) / T1) ** 2 and
        # (py - p1 - T/2 (vy + v1)) ** 2, written out (the 250 Hz path)
        d20 = ((vy[0] - At[0] - v1[0] + A1[0]) / T - (v1[0] - A1[0] - v0[0] + A0[0]) / T1) ** 2
        d21 = ((vy[1] - At[1] - v1[1] + A1[1]) / T - (v1[1] - A1[1] - v0[1] + A0[1]) / T1) ** 2
        d22 = ((vy[2] - At[2] - v1[2] + A1[2]) / T - (v1[2] - A1[2] - v0[2] + A0[2]) / T1) ** 2
        hT = 0.5 * T
        rp0 = (py[0] - p1[0] - hT * (vy[0] + v1[0])) ** 2
        rp1 = (py[1] - p1[1] - hT * (vy[1] + v1[1])) ** 2
        rp2 = (py[2] - p1[2] - hT * (vy[2] + v1[2])) ** 2
        n = self._n_noise + 1
        self._n_noise = n
        beta = max(1.0 - math.exp(-T / 5.0), 1.0 / n)
        var_v, var_p = self._var_v, self._var_p
        sv2_min = self.vel_std * self.vel_std
        hTT = 0.5 * T * T
        for a, d2a, rpa in ((0, 0.5 * (d20 + d21), 0.5 * (rp0 + rp1)), (1, d22, rp2)):
            var_v[a] += beta * ((d2a - qa) / c - var_v[a])
            sv2_now = max(var_v[a], sv2_min)
            var_p[a] += beta * (0.5 * (rpa - hTT * sv2_now) - var_p[a])

    def _tilt(self, tau: float, dtau: float, i: int, w: float, vy: Vec3, sv: float) -> None:
        # the most recent fix at least one window before tau
        t0 = tau - self.window(sv)
        fixes = self._fixes
        j = bisect_right(fixes, t0, key=_TIME) - 1       # fix times increase strictly
        fix0 = fixes[j] if j >= 0 and fixes[j][0] <= t0 else None
        if fix0 is None:                      # no fix a whole window old yet: the oldest one
            if not fixes or not fixes[0][0] < tau:
                return
            fix0 = fixes[0]
        at0 = self._at(fix0[0])
        if at0 is None:
            return
        tau0, v0 = fix0[0], fix0[2]
        span = tau - tau0
        g = self.g
        um = (vy[0] - v0[0], vy[1] - v0[1], vy[2] - v0[2] + g * span)
        if not um[0] * um[0] + um[1] * um[1] + um[2] * um[2] > (0.5 * g * span) ** 2:
            return                            # near free fall: no direction
        C = self._C
        S1 = mat_apply(C, *self._interp(i, w, 1))
        S0 = mat_apply(C, *self._interp(at0[0], at0[1], 1))
        up = (S1[0] - S0[0], S1[1] - S0[1], S1[2] - S0[2])
        cr = (up[1] * um[2] - up[2] * um[1], up[2] * um[0] - up[0] * um[2], up[0] * um[1] - up[1] * um[0])
        s = math.sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2])
        d = up[0] * um[0] + up[1] * um[1] + up[2] * um[2]
        if not s > 0.0:
            return
        k = tilt_gain(dtau, span, sv, self.gyro_noise, g, self.k_t_max)
        phi = math.atan2(s, d)
        a = k * dtau * phi / s
        E = so3_exp(a * cr[0], a * cr[1], a * cr[2])
        self.R = mat_mul(E, self.R)
        self._C = mat_mul(E, C)
        if self.n_tilt_updates % 64 == 63:
            self._C = orthonormalise(self._C)
        self._S = mat_apply(E, *self._S)
        self._fw = mat_apply(E, *self._fw)
        self._uw = mat_apply(E, *self._uw)
        if phi < _BIAS_GATE_RAD:
            self._bias_step(*mat_apply_t(self.R, a * cr[0], a * cr[1], a * cr[2]))
        self.n_tilt_updates += 1

    def _nav_gains(self, dtau: float, sp: float, sv: float):
        # buckets: 0.1 ms of interval, 10 per decade of noise
        key = (round(dtau * 1e4), round(10.0 * math.log10(max(sp, _POS_STD_FLOOR_M))),
               round(10.0 * math.log10(max(sv, _VEL_STD_FLOOR_M_S))))
        K = self._gains.get(key)
        if K is None:
            if len(self._gains) >= 64:
                self._gains.clear()
            K = nav_gains(max(key[0], 1) * 1e-4, 10.0 ** (key[1] / 10.0), 10.0 ** (key[2] / 10.0),
                          self.accel_noise, self.accel_bias_walk).K
            self._gains[key] = K
        return K
