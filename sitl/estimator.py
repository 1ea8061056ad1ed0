"""The SITL's onboard state estimator (PX4-style, small): what the vehicle's
own cascaded controller flies on when ``sim.onboard_state: estimate``.

It reads only what the vehicle measures (the IMU, magnetometer and the
delivered position/velocity samples, ``sitl.sensors``/``sitl.gnss``), never
the true state. Pure: floats in, named result out, no clock (times are
the vehicle's, handed in). World ENU, body FLU, R maps body to world.

Attitude: a complementary filter on SO(3) with gyro-bias estimation
(Mahony, Hamel & Pflimlin, IEEE TAC 2008, "explicit complementary
filter"), its corrections written as world-frame rotation vectors sigma::

    R <- R Exp([(W_m - b) dt + R^T sigma]x)          (propagation + correction)
    b <- b - k_b R^T sigma                            (bias: integral of the correction)

The correction computed at one frame enters the next frame's propagation
(one exponential per frame; R^T sigma is the body-frame form of the
world-frame rotation sigma, Exp(sigma) R = R Exp(R^T sigma)); each bias
component is clamped to +-0.15 rad/s (PX4's EKF2_GYR_B_LIM). The first
attitude comes from one accelerometer/magnetometer sample at rest
(``initial_attitude``, TRIAD with the vertical first); for the first 2 s the
time constants are ten times shorter and the bias is not integrated
(alignment). k_b = 0.3 /s. (For a correction acting directly, k_b = 0.51/tau
would give the bias-error dynamics ``e'' + e'/tau + k_b e/tau = 0`` a
damping of 0.7; the tilt correction below passes through the velocity
filter's bias estimate, a further lag, so k_b is lower: with tau = 0.7 s
and the filter's q_b = 0.1 m/s^2/sqrt(s) the tests' 30 deg / 60 deg
initial errors decay without overshoot to rounding in 40 s.)

- Tilt (``accel_mode = "specific_force"``, the physical accelerometer).
  On a drag-free multirotor the accelerometer reads the thrust direction,
  not gravity, so tilt comes from the velocity measurements, through the
  position/velocity filter below: a tilt error delta (world frame, R =
  Exp(delta) R_est) makes the predicted acceleration R_est f - g e3 miss
  ``g delta x e3`` (f ~ g R^T e3 near hover), which the filter's
  acceleration bias b_a estimates, ``b_a = -g delta x e3``, so the
  horizontal tilt error is ``delta = (b_a x e3) / g``. At every fused
  sample a fraction ``kappa = 1 - exp(-T / tau)`` (T the time since the
  previous one) of it is moved from b_a into the attitude:
  ``sigma = kappa (b_a x e3) / g`` and ``b_a,xy <- (1 - kappa) b_a,xy``
  (the kept frames' accelerations are corrected alike). The GNSS velocity
  thus informs tilt once, through the filter (as in PX4's EKF2, where
  velocity innovations correct the tilt states), and the horizontal
  accelerometer bias ends up in the tilt, which is indistinguishable from
  it in steady flight.
- Tilt (``accel_mode = "inclinometer"``, ``sim.vector_sensors: paper``:
  the accelerometer fields already carry the gravity-reaction direction):
  every frame, the rotation taking ``R a_m/|a_m|`` onto e3, scaled by
  ``dt / tau``.
- Yaw: every frame, the heading error of the horizontal part of
  ``R m_m`` against the horizontal part of the Earth field, about e3 only
  (the magnetometer never tilts the estimate), scaled by ``dt / tau_yaw``.

Position and velocity: per axis a Kalman filter on (p, v, b_a) (b_a an
acceleration bias in the world frame, which absorbs the accelerometer
bias and the residual tilt error)::

    p' = v,  v' = a - b_a,  b_a' = w_b,  a = R f - g e3

(for an inclinometer, which carries no acceleration, a = g (R_02, R_12, 0)/R_22:
the thrust along body z balancing gravity; the vertical acceleration is left
to the process noise and b_a)
discretised exactly for a held ``a`` (F = [[1, dt, -dt^2/2], [0, 1, -dt],
[0, 0, 1]]) with the white-acceleration process noise
``Q = q_a^2 [[dt^3/3, dt^2/2, 0], [dt^2/2, dt, 0], [0, 0, 0]] + diag(0, 0, q_b^2 dt)``,
corrected by the position and velocity of each delivered sample as two
scalar updates. Delay compensation (PX4 EKF2's delayed horizon): the
filter (state and covariance) lives at the time of the last fused
measurement; the accelerations of later frames are kept, so a sample
measured at t_m (delivered later) is fused at t_m and the current
estimate is then re-predicted through the kept frames (state only). x and
y share one covariance (same noise), z has its own. Memory: the kept
frames span at most ``max_history_s``.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass

from mavcore.so3 import polar_step, rotate_right


@dataclass(frozen=True)
class EstimatorConfig:
    """Gains and noise model of ``OnboardEstimator``.

    Attributes
    ----------
    accel_mode : str
        ``specific_force`` (physical accelerometer) or ``inclinometer``
        (accelerometer fields carry g R^T e3: ``sim.vector_sensors: paper``).
    mag_enu_gauss : 3-tuple
        Earth field reference (world ENU).
    gravity_m_s2 : float
    tilt_time_constant_s, yaw_time_constant_s : float
        tau of the tilt and yaw corrections (s).
    accel_noise_m_s2_rthz : float
        q_a, process noise of the position/velocity filter.
    accel_bias_walk_m_s2_rts : float
        q_b, random walk of its acceleration bias.
    pos_std_xy_m, pos_std_z_m, vel_std_m_s : float
        Measurement noise the filter assumes (floored at 1 mm and 1 mm/s).
    max_history_s : float
        Longest span of kept frames (bounds memory without deliveries).
    align_s : float
        Initial alignment: for this long after the first frame both time
        constants are divided by ``align_speedup`` and the gyro bias is not
        integrated (the first attitude comes from one noisy sample; PX4's
        EKF2 likewise starts with a large tilt variance).
    align_speedup : float
    gyro_bias_gain_per_s : float
        k_b of the bias integral (1/s).
    gyro_bias_limit_rad_s : float
        Clamp of each gyro-bias component (PX4's EKF2_GYR_B_LIM is 0.15 rad/s).
    """

    accel_mode: str = "specific_force"
    mag_enu_gauss: tuple = (0.0, 0.21, -0.42)
    gravity_m_s2: float = 9.81
    tilt_time_constant_s: float = 0.7
    yaw_time_constant_s: float = 1.0
    accel_noise_m_s2_rthz: float = 0.05
    accel_bias_walk_m_s2_rts: float = 0.1
    pos_std_xy_m: float = 0.0
    pos_std_z_m: float = 0.0
    vel_std_m_s: float = 0.0
    max_history_s: float = 2.0
    align_s: float = 2.0
    gyro_bias_limit_rad_s: float = 0.15
    gyro_bias_gain_per_s: float = 0.3
    align_speedup: float = 10.0

    def __post_init__(self) -> None:
        if self.accel_mode not in ("specific_force", "inclinometer"):
            raise ValueError("accel_mode must be specific_force or inclinometer")
        if min(self.tilt_time_constant_s, self.yaw_time_constant_s, self.max_history_s) <= 0:
            raise ValueError("estimator time constants must be > 0")
        if min(self.accel_noise_m_s2_rthz, self.accel_bias_walk_m_s2_rts, self.pos_std_xy_m, self.pos_std_z_m,
               self.vel_std_m_s, self.align_s, self.gyro_bias_gain_per_s) < 0:
            raise ValueError("estimator noise figures and gains must be >= 0")
        if not (self.gyro_bias_limit_rad_s > 0 and self.align_speedup >= 1):
            raise ValueError("gyro_bias_limit_rad_s must be > 0 and align_speedup >= 1")


@dataclass(frozen=True, slots=True)
class Estimate:
    """The estimator's output at one frame (world ENU, body FLU).

    Attributes
    ----------
    time_us : int
    R : 9-tuple
        Row-major rotation body FLU -> world ENU.
    omega_flu_rad_s : 3-tuple
        Gyro minus the estimated bias.
    pos_enu_m, vel_enu_m_s : 3-tuple
        Current (delay-compensated) position and velocity.
    gyro_bias_rad_s : 3-tuple
        Estimated gyro bias (body FLU).
    """

    time_us: int
    R: tuple
    omega_flu_rad_s: tuple
    pos_enu_m: tuple
    vel_enu_m_s: tuple
    gyro_bias_rad_s: tuple

    @property
    def yaw_enu_rad(self) -> float:
        """Heading of body x from east, CCW."""
        return math.atan2(self.R[3], self.R[0])

    @property
    def tilt_rad(self) -> float:
        """Angle between body z and world z."""
        return math.acos(max(-1.0, min(1.0, self.R[8])))


def initial_attitude(accel_flu, mag_flu, mag_enu) -> tuple:
    """R (row-major 9-tuple) from one accelerometer and magnetometer sample
    at rest: body z along the accelerometer, heading from the magnetometer's
    horizontal part against the Earth field's (TRIAD with the vertical first)."""
    ax, ay, az = accel_flu
    n = math.sqrt(ax * ax + ay * ay + az * az)
    if not n > 0:
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    z = (ax / n, ay / n, az / n)                     # world up in body coordinates
    mx, my, mz = mag_flu
    d = mx * z[0] + my * z[1] + mz * z[2]
    h = (mx - d * z[0], my - d * z[1], mz - d * z[2])    # horizontal field, body
    hn = math.sqrt(h[0] ** 2 + h[1] ** 2 + h[2] ** 2)
    en = math.hypot(mag_enu[0], mag_enu[1])
    if not (hn > 0 and en > 0):
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    hb = (h[0] / hn, h[1] / hn, h[2] / hn)
    yb = (z[1] * hb[2] - z[2] * hb[1], z[2] * hb[0] - z[0] * hb[2], z[0] * hb[1] - z[1] * hb[0])
    # body-frame images of world axes: the field's horizontal heading psi_m (ENU)
    psi = math.atan2(mag_enu[1], mag_enu[0])
    c, s = math.cos(psi), math.sin(psi)
    # world e1 (east) and e2 (north) expressed in body
    ex = tuple(c * hb[i] - s * yb[i] for i in range(3))
    ey = tuple(s * hb[i] + c * yb[i] for i in range(3))
    # R rows are the world axes in body coordinates
    return (ex[0], ex[1], ex[2], ey[0], ey[1], ey[2], z[0], z[1], z[2])


def _kf_predict_cov(P, dt, qa2, qb2):
    """F P F^T + Q for F = [[1, dt, -dt^2/2], [0, 1, -dt], [0, 0, 1]] (P as 6-tuple pp, pv, pb, vv, vb, bb)."""
    pp, pv, pb, vv, vb, bb = P
    h = -0.5 * dt * dt
    # A = F P
    a_pp = pp + dt * pv + h * pb
    a_pv = pv + dt * vv + h * vb
    a_pb = pb + dt * vb + h * bb
    a_vp = pv - dt * pb
    a_vv = vv - dt * vb
    a_vb = vb - dt * bb
    # (F P) F^T
    npp = a_pp + dt * a_pv + h * a_pb
    npv = a_pv - dt * a_pb
    nvv = a_vv - dt * a_vb
    dt2 = dt * dt
    return (npp + qa2 * dt2 * dt / 3.0, npv + qa2 * 0.5 * dt2, a_pb,
            nvv + qa2 * dt, a_vb, bb + qb2 * dt)


def _kf_gains(P, idx, r):
    """Kalman gain (3-tuple) and updated covariance for a scalar measurement
    of state[idx] (0 position, 1 velocity) with variance r."""
    pp, pv, pb, vv, vb, bb = P
    c0, c1, c2 = (pp, pv, pb) if idx == 0 else (pv, vv, vb)
    s = (c0 if idx == 0 else c1) + r
    k0, k1, k2 = c0 / s, c1 / s, c2 / s
    return (k0, k1, k2), (pp - k0 * c0, pv - k0 * c1, pb - k0 * c2, vv - k1 * c1, vb - k1 * c2, bb - k2 * c2)


def _predict9(x, ax, ay, az, dt):
    """Held-acceleration prediction of the 9 filter states (p, v, b per axis x, y, z)."""
    h = 0.5 * dt * dt
    ux, uy, uz = ax - x[2], ay - x[5], az - x[8]
    return [x[0] + x[1] * dt + ux * h, x[1] + ux * dt, x[2],
            x[3] + x[4] * dt + uy * h, x[4] + uy * dt, x[5],
            x[6] + x[7] * dt + uz * h, x[7] + uz * dt, x[8]]


_ZERO3 = (0.0, 0.0, 0.0)
_NAN3 = (math.nan, math.nan, math.nan)


class OnboardEstimator:
    """Attitude + position/velocity estimator of the SITL's flight stack.

    Parameters
    ----------
    config : EstimatorConfig
    R0 : row-major 9-tuple, optional
        Initial attitude; None: from the first accelerometer/magnetometer
        sample (``initial_attitude``).

    Call ``update`` once per sensor frame; the first delivered
    position/velocity sample initialises the position filter.
    """

    def __init__(self, config: EstimatorConfig = EstimatorConfig(), R0=None) -> None:
        self.config = config
        c = config
        self._R = None if R0 is None else tuple(float(x) for x in R0)
        self._b = (0.0, 0.0, 0.0)
        self._kb = 0.0                   # no bias integration while aligning
        self._aligning = True
        self._align_until_us = 0
        self._qa2 = c.accel_noise_m_s2_rthz ** 2
        self._qb2 = c.accel_bias_walk_m_s2_rts ** 2
        self._rpxy = max(c.pos_std_xy_m, 1e-3) ** 2
        self._rpz = max(c.pos_std_z_m, 1e-3) ** 2
        self._rv = max(c.vel_std_m_s, 1e-3) ** 2
        mx, my = c.mag_enu_gauss[0], c.mag_enu_gauss[1]
        self._mag_psi = math.atan2(my, mx)
        self._x_d = None               # delayed state: 3 axes x (p, v, b)
        self._P_h = self._P_v = None
        self._t_d = 0
        self._x_now = None
        self._hist: collections.deque = collections.deque()   # kept frames: (t_us, dt, ax, ay, az)
        self._last_fused_us = None
        self._n = 0
        self._phi = _ZERO3               # pending body-frame correction
        self._inclinometer = c.accel_mode == "inclinometer"
        self._k_tilt = c.align_speedup / c.tilt_time_constant_s
        self._k_yaw = c.align_speedup / c.yaw_time_constant_s
        self.last: Estimate | None = None

    # ------------------------------------------------------------------
    def _init_pos(self, t_us, pos, vel) -> None:
        self._x_d = [pos[0], vel[0], 0.0, pos[1], vel[1], 0.0, pos[2], vel[2], 0.0]
        self._P_h = (self._rpxy, 0.0, 0.0, self._rv, 0.0, 0.25)
        self._P_v = (self._rpz, 0.0, 0.0, self._rv, 0.0, 0.25)
        self._t_d = int(t_us)
        self._x_now = self._x_d
        self._hist.clear()
        self._last_fused_us = int(t_us)

    def update(self, time_us: int, dt_s: float, gyro_flu, accel_flu, mag_flu, gnss=None) -> Estimate:
        """One sensor frame.

        Parameters
        ----------
        time_us : int
            Vehicle time of the frame (us).
        dt_s : float
            Time since the previous frame (s).
        gyro_flu, accel_flu, mag_flu : 3-tuples
            The frame's measurements (rad/s, m/s^2, gauss), body FLU.
        gnss : sitl.gnss.GnssSample or None
            The latest delivered position/velocity sample (fused once, when
            its measurement time is new).

        Returns
        -------
        Estimate
        """
        c = self.config
        if self._x_d is None and gnss is not None:
            self._init_pos(gnss.time_us, gnss.pos_enu_m, gnss.vel_enu_m_s)
        R = self._R
        if R is None:
            R = initial_attitude(accel_flu, mag_flu, c.mag_enu_gauss)
            self._align_until_us = time_us + int(c.align_s * 1e6)
        aligning = time_us < self._align_until_us
        if self._aligning and not aligning:
            self._aligning = False
            self._k_tilt = 1.0 / c.tilt_time_constant_s
            self._k_yaw = 1.0 / c.yaw_time_constant_s
            self._kb = c.gyro_bias_gain_per_s
        b = self._b
        # -- propagate with the bias-corrected gyro and the previous frame's
        # correction (body frame phi = R^T sigma): one Exp per frame
        ph = self._phi
        wx, wy, wz = gyro_flu[0] - b[0], gyro_flu[1] - b[1], gyro_flu[2] - b[2]
        R = rotate_right(R, wx * dt_s + ph[0], wy * dt_s + ph[1], wz * dt_s + ph[2])
        self._n += 1
        if self._n & 63 == 0:
            R = polar_step(R)
        self._R = R
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
        # -- world specific force and the acceleration input
        fx, fy, fz = accel_flu
        ux = r00 * fx + r01 * fy + r02 * fz
        uy = r10 * fx + r11 * fy + r12 * fz
        uz = r20 * fx + r21 * fy + r22 * fz
        sx = sy = sz = 0.0               # world-frame correction
        # -- yaw from the magnetometer's horizontal part
        mx, my, mz = mag_flu
        hx = r00 * mx + r01 * my + r02 * mz
        hy = r10 * mx + r11 * my + r12 * mz
        if hx * hx + hy * hy > 0:
            err = self._mag_psi - math.atan2(hy, hx)
            if err > math.pi:
                err -= 2.0 * math.pi
            elif err < -math.pi:
                err += 2.0 * math.pi
            sz = err * self._k_yaw * dt_s
        if self._inclinometer:
            # thrust along body z balancing gravity: horizontal acceleration g tan(tilt)
            k = c.gravity_m_s2 / r22 if r22 > 0.1 else 0.0
            ax, ay, az = k * r02, k * r12, 0.0
            # tilt: rotate the measured up-direction onto e3
            n = math.sqrt(ux * ux + uy * uy + uz * uz)
            if n > 0:
                cx, cy = uy / n, -ux / n         # (u/|u|) x e3
                sn = math.hypot(cx, cy)
                if sn > 1e-12:
                    k = self._k_tilt * dt_s * math.atan2(sn, uz / n) / sn
                    sx, sy = k * cx, k * cy
        else:
            ax, ay, az = ux, uy, uz - c.gravity_m_s2
        # -- position/velocity filter (and the tilt window), delay-compensated
        if self._x_d is not None:
            self._hist.append((time_us, dt_s, ax, ay, az))
            if gnss is not None and gnss.time_us > self._last_fused_us:
                tilt = self._fuse(gnss)        # also re-predicts _x_now through this frame
                if tilt is not None and not self._inclinometer:
                    sx += tilt[0]
                    sy += tilt[1]
            else:
                self._x_now = _predict9(self._x_now, ax, ay, az, dt_s)
                if (time_us - self._hist[0][0]) * 1e-6 > c.max_history_s:
                    self._advance_delayed(self._hist[0][0])
        # -- the correction, applied at the next propagation; bias integral
        if sx or sy or sz:
            px = r00 * sx + r10 * sy + r20 * sz
            py = r01 * sx + r11 * sy + r21 * sz
            pz = r02 * sx + r12 * sy + r22 * sz
            self._phi = (px, py, pz)
            kb = self._kb
            lim = c.gyro_bias_limit_rad_s
            self._b = b = (min(lim, max(-lim, b[0] - kb * px)), min(lim, max(-lim, b[1] - kb * py)),
                           min(lim, max(-lim, b[2] - kb * pz)))
        else:
            self._phi = _ZERO3
        xn = self._x_now
        if xn is None:
            pos = vel = _NAN3
        else:
            pos, vel = (xn[0], xn[3], xn[6]), (xn[1], xn[4], xn[7])
        est = self.last = Estimate(time_us, R, (gyro_flu[0] - b[0], gyro_flu[1] - b[1], gyro_flu[2] - b[2]),
                                   pos, vel, b)
        return est

    # ------------------------------------------------------------------
    def _advance_delayed(self, until_us: int) -> None:
        """Predict the delayed state and covariance through the kept frames up to ``until_us``."""
        hist = self._hist
        x = self._x_d
        Ph, Pv = self._P_h, self._P_v
        qa2, qb2 = self._qa2, self._qb2
        while hist and hist[0][0] <= until_us:
            t, dt, ax, ay, az = hist.popleft()
            x = _predict9(x, ax, ay, az, dt)
            Ph = _kf_predict_cov(Ph, dt, qa2, qb2)
            Pv = _kf_predict_cov(Pv, dt, qa2, qb2)
            self._t_d = t
        self._x_d = x
        self._P_h, self._P_v = Ph, Pv

    def _fuse(self, sample):
        """Fuse a delivered sample at its measurement time, move part of the
        horizontal acceleration bias into the tilt, re-predict to now.
        Returns the tilt correction (sigma_x, sigma_y) or None."""
        c = self.config
        t_m = sample.time_us
        T = (t_m - self._last_fused_us) * 1e-6
        self._last_fused_us = t_m
        self._advance_delayed(t_m)
        x = self._x_d
        p, v = sample.pos_enu_m, sample.vel_enu_m_s
        (k0, k1, k2), Ph = _kf_gains(self._P_h, 0, self._rpxy)     # x and y share P
        e0, e1 = p[0] - x[0], p[1] - x[3]
        x = [x[0] + k0 * e0, x[1] + k1 * e0, x[2] + k2 * e0, x[3] + k0 * e1, x[4] + k1 * e1, x[5] + k2 * e1,
             x[6], x[7], x[8]]
        (k0, k1, k2), Ph = _kf_gains(Ph, 1, self._rv)
        e0, e1 = v[0] - x[1], v[1] - x[4]
        x = [x[0] + k0 * e0, x[1] + k1 * e0, x[2] + k2 * e0, x[3] + k0 * e1, x[4] + k1 * e1, x[5] + k2 * e1,
             x[6], x[7], x[8]]
        (k0, k1, k2), Pv = _kf_gains(self._P_v, 0, self._rpz)
        e2 = p[2] - x[6]
        x[6], x[7], x[8] = x[6] + k0 * e2, x[7] + k1 * e2, x[8] + k2 * e2
        (k0, k1, k2), Pv = _kf_gains(Pv, 1, self._rv)
        e2 = v[2] - x[7]
        x[6], x[7], x[8] = x[6] + k0 * e2, x[7] + k1 * e2, x[8] + k2 * e2
        tilt = None
        if not self._inclinometer and T > 0:
            kap = 1.0 - math.exp(-T * self._k_tilt)
            bx, by = kap * x[2], kap * x[5]
            x[2] -= bx
            x[5] -= by
            g = c.gravity_m_s2
            tilt = (by / g, -bx / g)                 # kappa (b_a x e3) / g
            # the kept frames' accelerations under the corrected attitude
            self._hist = collections.deque((t, dt, ax + bx, ay + by, az) for (t, dt, ax, ay, az) in self._hist)
        self._x_d, self._P_h, self._P_v = x, Ph, Pv
        for (_, dt, ax, ay, az) in self._hist:
            x = _predict9(x, ax, ay, az, dt)
        self._x_now = x
        return tilt
