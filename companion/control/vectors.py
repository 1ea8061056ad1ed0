"""Vector measurements for the geometric controller (paper eqs. 27-28).

The controller never reads the attitude. It sees the rotation ``R`` (body FLU
-> world ENU) only through k = 2 pairs (b_i, r_i) with ``b_i = R^T r_i``:
b_i a unit vector measured in the body frame, r_i its direction in the world
frame, known without the attitude.

Pair 1, specific force (accelerometer).
    The accelerometer measures the specific force ``R^T (a + g e3)``, with
    ``a`` the vehicle's acceleration (ENU). Its world direction is therefore
    ``r_1 = (a + g e3) / |a + g e3|``, known once ``a`` is known from outside
    the attitude: here from the measured velocity (LOCAL_POSITION_NED),
    differentiated on the vehicle clock and low-passed
    (:class:`AccelerationEstimator`). Whatever the forces (rotors, drag, wind),
    ``b_1 = R^T r_1`` holds exactly, so the pair is physically consistent.
    For a drag-free quadrotor the specific force is the rotor thrust, ``b_1 =
    e3`` at all times: the accelerometer then carries no attitude information
    of its own, the tilt information is all in ``r_1`` (i.e. in the velocity).
    This is why ``b_1`` can be low-passed in the body frame without any lag on
    the attitude (:class:`BodyVectorFilter` with ``propagate=False``).

Pair 2, magnetic field (magnetometer).
    ``b_2`` is the normalised magnetometer reading, ``r_2`` the normalised
    Earth field ``ControlConfig.mag_field_enu_gauss`` (a configuration input,
    default the bundled SITL's). ``r_2`` is constant, so ``b_2`` obeys
    ``b2_dot = b2 x Omega`` and can be filtered with the gyro (a
    complementary filter: propagate with the gyro, correct toward the
    measurement), :class:`BodyVectorFilter` with ``propagate=True``.

Pair 2 is by default replaced by the field's component normal to the
specific force, ``b_2' = unit(b_2 - (b_2.b_1) b_1)`` against ``r_2' =
unit(r_2 - (r_2.r_1) r_1)``: projection commutes with the rotation, so
``b_2' = R^T r_2'`` still holds exactly and the pair is a valid vector
measurement. Why: the Earth field is steep (63 deg below the horizon at the
default field), so with the raw field a yaw error alone makes a torque about
a horizontal axis twice the yaw torque (``r2 x (psi e3 x r2) = psi (e3 - r2_z
r2)``); this vehicle's yaw authority is tiny (``c_tau`` = 0.8 mm: about 0.25
rad/s^2), its yaw torque saturates on the sensor noise, and the saturated yaw
then drags the tilt, hence the position. With ``r_2' ⟂ r_1``, a yaw error
gives a pure yaw torque (``W_rho`` has ``r_1`` as eigenvector, eigenvalue
rho_2). ``ControlConfig.mag_perpendicular = False`` keeps the raw field.

The two filters are optional (gains 0 give the paper's raw, unfiltered
vectors). All objects here are pure state machines: no clock, no I/O; time
is the vehicle's, passed in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mavcore.so3 import Vec3, reject, unit3


@dataclass(frozen=True, slots=True)
class VectorPairs:
    """Two body/world unit-vector pairs ``b_i = R^T r_i`` (eq. 28), FLU/ENU.

    Attributes
    ----------
    b1, r1 : tuple (3,)
        Specific-force direction, body FLU and world ENU (unitless).
    b2, r2 : tuple (3,)
        Magnetic-field direction, body FLU and world ENU (unitless).
    """

    b1: Vec3
    b2: Vec3
    r1: Vec3
    r2: Vec3


def specific_force_direction_enu(accel_enu_m_s2, gravity_m_s2: float) -> Vec3:
    """World direction ``(a + g e3)/|a + g e3|`` of the specific force (ENU, unit)."""
    return unit3((accel_enu_m_s2[0], accel_enu_m_s2[1], accel_enu_m_s2[2] + gravity_m_s2))


def measurement_vectors(accel_flu_m_s2, mag_flu_gauss, accel_est_enu_m_s2,
                        mag_field_enu_gauss, gravity_m_s2: float, mag_perpendicular: bool = True) -> VectorPairs:
    """Sensor readings -> the two unit-vector pairs of eq. (28).

    The readings may be raw or already filtered (:class:`BodyVectorFilter`):
    only their directions are used.

    Parameters
    ----------
    accel_flu_m_s2 : sequence (3,)
        Accelerometer (specific force), body FLU, m/s^2.
    mag_flu_gauss : sequence (3,)
        Magnetometer, body FLU, gauss (any unit: only the direction is used).
    accel_est_enu_m_s2 : sequence (3,)
        The vehicle's acceleration, world ENU, m/s^2, known without the
        attitude (e.g. :class:`AccelerationEstimator`).
    mag_field_enu_gauss : sequence (3,)
        The Earth field, world ENU.
    gravity_m_s2 : float
        g.
    mag_perpendicular : bool
        Use the field's component normal to the specific force (both frames)
        instead of the field itself; see the module docstring.

    Returns
    -------
    VectorPairs
    """
    return controller_vectors(accel_flu_m_s2, mag_flu_gauss, accel_est_enu_m_s2, mag_field_enu_gauss,
                              gravity_m_s2, mag_perpendicular, "physical", True)


_E3 = (0.0, 0.0, 1.0)


def controller_vectors(accel_flu_m_s2, mag_flu_gauss, accel_est_enu_m_s2, mag_field_enu_gauss,
                       gravity_m_s2: float, mag_perpendicular: bool, vectors: str,
                       velocity_aided: bool) -> VectorPairs:
    """The two vector pairs of eq. (28) for each sensor model and tilt source (no observer).

    =========================  ====================================  =====================================
    ``vectors``, aided         b_1 (body FLU)                        r_1 (world ENU)
    =========================  ====================================  =====================================
    physical, True (default)   accelerometer (specific force)        unit(a_hat + g e3), a_hat from v
    physical, False            accelerometer                         e3: "accelerometer as gravity", wrong
                                                                     under acceleration (r_1 turns with a)
    paper, True                e3, the thrust axis of the drag-free   unit(a_hat + g e3), a_hat from v
                               plant (eq. 20; the paper's IMU
                               vectors carry no specific force)
    paper, False (the paper)   accelerometer fields = g R^T e3        e3
    =========================  ====================================  =====================================

    Pair 2 is the magnetometer against ``mag_field_enu_gauss``, both taken
    normal to pair 1 with ``mag_perpendicular``. Parameters as
    :func:`measurement_vectors`, plus ``vectors`` ("physical" | "paper":
    what the accelerometer fields carry, as the SITL's
    ``sim.vector_sensors``) and ``velocity_aided``.
    """
    if vectors == "paper" and velocity_aided:
        b1 = _E3
    else:
        b1 = unit3(accel_flu_m_s2)
    r1 = specific_force_direction_enu(accel_est_enu_m_s2, gravity_m_s2) if velocity_aided else _E3
    b2, r2 = unit3(mag_flu_gauss), unit3(mag_field_enu_gauss)
    if mag_perpendicular:
        b2, r2 = reject(b2, b1), reject(r2, r1)
    return VectorPairs(b1=b1, b2=b2, r1=r1, r2=r2)


class AccelerationEstimator:
    """World acceleration from the measured velocity, on the vehicle clock.

    A backward difference of successive velocity samples, followed by a
    first-order low-pass of time constant ``tau_s`` discretised exactly
    (``y += (1 - exp(-dt/tau)) (x - y)``); ``tau_s = 0`` keeps the raw
    difference (right for the noise-free, mocap-like velocity of the SITL: the
    difference over one 4 ms frame lags the acceleration by half a frame).
    A sample whose time stamp does not advance (a repeated or late
    LOCAL_POSITION_NED) leaves the estimate unchanged. Before two samples the
    estimate is zero (the vehicle is assumed at rest: on the ground or
    hovering), which makes ``r_1`` gravity's direction.

    Parameters
    ----------
    tau_s : float
        Low-pass time constant (s), >= 0.
    """

    __slots__ = ("tau_s", "_t", "_v", "_a")

    def __init__(self, tau_s: float) -> None:
        if not tau_s >= 0.0:
            raise ValueError("tau_s must be >= 0")
        self.tau_s = float(tau_s)
        self._t: float | None = None
        self._v: Vec3 = (0.0, 0.0, 0.0)
        self._a: Vec3 = (0.0, 0.0, 0.0)

    @property
    def accel_enu_m_s2(self) -> Vec3:
        """Current estimate (3,), world ENU, m/s^2."""
        return self._a

    def update(self, t_s: float, vel_enu_m_s, jerk_enu_m_s3=None) -> Vec3:
        """Feed one velocity sample (ENU, m/s) stamped ``t_s`` (vehicle clock, s).

        ``jerk_enu_m_s3`` (3,), optional: the expected jerk (the reference's),
        used to advance the estimate over its lag (``dt/2 + tau_s``).

        Returns the acceleration estimate (3,), world ENU, m/s^2.
        """
        vx, vy, vz = float(vel_enu_m_s[0]), float(vel_enu_m_s[1]), float(vel_enu_m_s[2])
        t_prev = self._t
        if t_prev is None:
            self._t, self._v = t_s, (vx, vy, vz)
            return self._a
        dt = t_s - t_prev
        if dt <= 0.0:
            return self._a
        px, py, pz = self._v
        dx, dy, dz = (vx - px) / dt, (vy - py) / dt, (vz - pz) / dt
        if self.tau_s > 0.0:
            beta = 1.0 - math.exp(-dt / self.tau_s)
            ax, ay, az = self._a
            self._a = (ax + beta * (dx - ax), ay + beta * (dy - ay), az + beta * (dz - az))
        else:
            self._a = (dx, dy, dz)
        self._t, self._v = t_s, (vx, vy, vz)
        if jerk_enu_m_s3 is None:
            return self._a
        lag = 0.5 * dt + self.tau_s
        ax, ay, az = self._a
        return (ax + lag * jerk_enu_m_s3[0], ay + lag * jerk_enu_m_s3[1], az + lag * jerk_enu_m_s3[2])


class BodyVectorFilter:
    """Noise filter for a measured body-frame unit vector.

    ``propagate=True`` (a vector fixed in the world frame, e.g. the magnetic
    field): the complementary filter ``bh_dot = bh x Omega + k (b - bh)``,
    i.e. the body-frame kinematics of a constant world vector driven by the
    gyro, corrected toward the measurement with gain ``k`` (rad/s); its error
    is the measurement noise low-passed at ``k`` plus the gyro noise
    integrated over ``1/k``, without lag on the rotation.
    ``propagate=False`` (a vector fixed in the body frame, e.g. the specific
    force of a drag-free multirotor): the plain low-pass ``bh_dot = k (b - bh)``.
    One explicit Euler step per sample, then renormalised. The gain starts as
    a running mean (``max(1 - exp(-k dt), 1/n)`` after n samples). ``k = 0``
    passes the measurement through (the paper's unfiltered vectors).

    Parameters
    ----------
    gain_rad_s : float
        Correction gain k (1/s), >= 0.
    propagate : bool
        Propagate with the gyro (see above).
    """

    __slots__ = ("gain_rad_s", "propagate", "_t", "_b", "_n")

    def __init__(self, gain_rad_s: float, propagate: bool) -> None:
        if not gain_rad_s >= 0.0:
            raise ValueError("gain_rad_s must be >= 0")
        self.gain_rad_s = float(gain_rad_s)
        self.propagate = bool(propagate)
        self._t: float | None = None
        self._b: Vec3 | None = None
        self._n = 0

    def update(self, t_s: float, b_meas: Vec3, gyro_flu_rad_s) -> Vec3:
        """One sample: measured unit vector (3,), body FLU; gyro (3,) rad/s.

        Returns the filtered unit vector (3,), body FLU.
        """
        if self.propagate:
            wx, wy, wz = float(gyro_flu_rad_s[0]), float(gyro_flu_rad_s[1]), float(gyro_flu_rad_s[2])
        else:
            wx = wy = wz = 0.0
        return self.step(t_s, b_meas[0], b_meas[1], b_meas[2], wx, wy, wz)

    def step(self, t_s: float, mx: float, my: float, mz: float, wx: float, wy: float, wz: float) -> Vec3:
        """:meth:`update` on floats: measured unit vector (mx, my, mz) and gyro (rad/s), body FLU.

        Returns the filtered unit vector (3,), body FLU.
        """
        k = self.gain_rad_s
        if k == 0.0 or self._b is None or self._t is None:
            b = (mx, my, mz)
            self._t, self._b, self._n = t_s, b, 1
            return b
        dt = t_s - self._t
        if dt <= 0.0:
            return self._b
        self._t = t_s
        n = self._n + 1
        self._n = n
        bx, by, bz = self._b
        # Exact first-order blend (stable for any dt); while fewer than
        # 1/(k dt) samples have been seen, the running mean instead, so a small
        # k does not keep the noise of the first sample for 1/k seconds.
        beta = 1.0 - math.exp(-k * dt)
        mean = 1.0 / n
        if mean > beta:        # max(beta, 1/n)
            beta = mean
        if self.propagate:
            # b_dot = b x Omega (a world-fixed vector seen from a rotating body).
            bx, by, bz = (bx + dt * (by * wz - bz * wy),
                          by + dt * (bz * wx - bx * wz),
                          bz + dt * (bx * wy - by * wx))
        bx += beta * (mx - bx)
        by += beta * (my - by)
        bz += beta * (mz - bz)
        n = math.sqrt(bx * bx + by * by + bz * bz)
        b = (bx / n, by / n, bz / n)
        self._b = b
        return b
