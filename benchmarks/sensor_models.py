"""Sensor models for the in-process benchmarks (``track_inprocess.fly``), seeded.

The SITL's own sensors (``sitl.sensors``: the paper's white noise on the
unit vectors and on Omega, optional white position/velocity noise and
constant biases) cover the physical model at 250 Hz. What they do not
have (yet, on this branch) is reproduced here from the ground truth of
each frame, with its own ``numpy.random.Generator``:

- ``vectors="paper"``: the paper's sensor model (Section 3.4), as
  ``sim.vector_sensors: paper`` will send it: the accelerometer fields carry
  ``g (R^T e3 + n1)`` (a constant inertial direction, not the specific
  force), the magnetometer ``|m| (R^T m_hat + n2)``, each ``n_i`` white with
  variance ``vector_variance`` per component; the gyro is the SITL's.
- ``imu``: an IMU replacing the SITL's accelerometer and gyro: white noise
  of the given densities sampled at the frame rate (``sigma = density *
  sqrt(rate)``), a constant turn-on bias and a bias random walk (``b +=
  walk * sqrt(dt) * n`` every frame).
- ``mag_disturbance``: a constant hard-iron offset (body, gauss) plus a
  motor term proportional to the collective thrust, and white noise.
- ``gnss``: position/velocity fixes at ``rate_hz`` measured on the vehicle
  clock, white noise (``pos_std_m`` horizontal, ``pos_std_z_m`` vertical,
  ``vel_std_m_s``), delivered ``latency_s`` later; between deliveries the
  latest delivered fix is repeated with its measurement time (the
  LOCAL_POSITION_NED contract: ``time_boot_ms`` = measurement time).

``REALISTIC`` is the in-process stand-in for the SITL's realistic profile
(issue 7): RTK-like fixes (1 cm horizontal, 2 cm vertical, 2 cm/s, 10 Hz,
80 ms late), a BMI088-class IMU (gyro 0.014 deg/s/sqrt(Hz), accelerometer
175 ug/sqrt(Hz), as commonly quoted for that part; turn-on biases 0.01
rad/s and 0.05 m/s^2 per axis, bias walks 1e-4 rad/s/sqrt(s) and 1e-3
m/s^2/sqrt(s)) and a magnetometer with 3 mgauss noise, a 20 mgauss
hard-iron offset and 1 mgauss per 10 N of thrust.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ImuModel:
    """Noise densities (per sqrt(Hz)), turn-on biases (body FLU) and bias walks (per sqrt(s))."""

    gyro_density_rad_s: float
    accel_density_m_s2: float
    gyro_bias_rad_s: tuple = (0.0, 0.0, 0.0)
    accel_bias_m_s2: tuple = (0.0, 0.0, 0.0)
    gyro_walk_rad_s: float = 0.0
    accel_walk_m_s2: float = 0.0


@dataclass(frozen=True)
class MagModel:
    """Magnetometer noise (gauss, per sample), hard-iron offset (gauss, body FLU), motor term (gauss/N, body z)."""

    noise_gauss: float
    hard_iron_gauss: tuple = (0.0, 0.0, 0.0)
    motor_gauss_per_n: float = 0.0


@dataclass(frozen=True)
class GnssModel:
    """Fix rate (Hz), latency (s) and white noise (m, m/s)."""

    rate_hz: float
    latency_s: float
    pos_std_m: float
    pos_std_z_m: float
    vel_std_m_s: float


@dataclass(frozen=True)
class SensorSpec:
    """What the companion is given, frame by frame (None: the SITL's own sensor)."""

    vectors: str = "physical"                 # "physical" | "paper"
    vector_variance: float = 5e-4             # the paper's vectors (vectors="paper")
    imu: ImuModel | None = None
    mag: MagModel | None = None
    gnss: GnssModel | None = None
    label: str = ""


REALISTIC = SensorSpec(
    imu=ImuModel(gyro_density_rad_s=math.radians(0.014), accel_density_m_s2=175e-6 * 9.80665,
                 gyro_bias_rad_s=(0.01, -0.01, 0.01), accel_bias_m_s2=(0.05, -0.05, 0.05),
                 gyro_walk_rad_s=1e-4, accel_walk_m_s2=1e-3),
    mag=MagModel(noise_gauss=0.003, hard_iron_gauss=(0.02, -0.01, 0.01), motor_gauss_per_n=1e-4),
    gnss=GnssModel(rate_hz=10.0, latency_s=0.08, pos_std_m=0.01, pos_std_z_m=0.02, vel_std_m_s=0.02),
    label="realistic (RTK 10 Hz 80 ms, BMI088-class IMU, disturbed mag)")


class SensorModels:
    """Applies a :class:`SensorSpec` to the SITL's frames (see the module docstring).

    Parameters
    ----------
    spec : SensorSpec
    rng : numpy.random.Generator
    gravity_m_s2 : float
    mag_field_enu_gauss : sequence (3,)
    dt_s : float
        Frame period (s).
    """

    def __init__(self, spec: SensorSpec, rng: np.random.Generator, gravity_m_s2: float,
                 mag_field_enu_gauss, dt_s: float) -> None:
        self.spec = spec
        self.rng = rng
        self.g = float(gravity_m_s2)
        self.m = np.asarray(mag_field_enu_gauss, float)
        self.dt = float(dt_s)
        imu = spec.imu
        if imu is not None:
            self.bg = np.array(imu.gyro_bias_rad_s, float)
            self.ba = np.array(imu.accel_bias_m_s2, float)
        self._fixes: deque = deque()
        self._next_fix_us: int | None = None
        self._delivered = None

    def measure(self, frame):
        """(gyro, accel, mag, pos, vel, nav_time_s) for the companion, FLU/ENU float tuples."""
        spec, rng, tr = self.spec, self.rng, frame.truth
        R = tr.R
        gyro, accel, mag = frame.gyro_flu_rad_s, frame.accel_flu_m_s2, frame.mag_flu_gauss
        pos, vel = frame.pos_enu_m, frame.vel_enu_m_s
        nav_t = (frame.time_us // 1000) * 1e-3
        if spec.imu is not None:
            imu = spec.imu
            rate = 1.0 / self.dt
            sf = R.T @ (tr.acc_enu_m_s2 + np.array([0.0, 0.0, self.g]))
            gyro = tr.omega_flu_rad_s + self.bg + imu.gyro_density_rad_s * math.sqrt(rate) * rng.standard_normal(3)
            accel = sf + self.ba + imu.accel_density_m_s2 * math.sqrt(rate) * rng.standard_normal(3)
            self.bg = self.bg + imu.gyro_walk_rad_s * math.sqrt(self.dt) * rng.standard_normal(3)
            self.ba = self.ba + imu.accel_walk_m_s2 * math.sqrt(self.dt) * rng.standard_normal(3)
        if spec.vectors == "paper":
            s = math.sqrt(spec.vector_variance)
            accel = self.g * (R.T[:, 2] + s * rng.standard_normal(3))
            mn = float(np.linalg.norm(self.m))
            mag = mn * (R.T @ (self.m / mn) + s * rng.standard_normal(3))
        if spec.mag is not None:
            mm = spec.mag
            mag = (R.T @ self.m + np.array(mm.hard_iron_gauss)
                   + np.array([0.0, 0.0, mm.motor_gauss_per_n * float(np.sum(tr.motor_thrust_n))])
                   + mm.noise_gauss * rng.standard_normal(3))
        if spec.gnss is not None:
            pos, vel, nav_t = self._gnss(frame)
        f32 = np.float32
        return (tuple(float(x) for x in np.asarray(gyro, f32)), tuple(float(x) for x in np.asarray(accel, f32)),
                tuple(float(x) for x in np.asarray(mag, f32)), tuple(float(x) for x in np.asarray(pos, f32)),
                tuple(float(x) for x in np.asarray(vel, f32)), nav_t)

    def _gnss(self, frame):
        gn, rng, tr = self.spec.gnss, self.rng, frame.truth
        t_us = frame.time_us
        period_us = int(round(1e6 / gn.rate_hz))
        if self._next_fix_us is None:
            self._next_fix_us = t_us
        if t_us >= self._next_fix_us:
            self._next_fix_us += period_us
            p = tr.pos_enu_m + np.array([gn.pos_std_m, gn.pos_std_m, gn.pos_std_z_m]) * rng.standard_normal(3)
            v = tr.vel_enu_m_s + gn.vel_std_m_s * rng.standard_normal(3)
            self._fixes.append((t_us, p, v))
        lat_us = int(round(gn.latency_s * 1e6))
        while self._fixes and self._fixes[0][0] + lat_us <= t_us:
            self._delivered = self._fixes.popleft()
        if self._delivered is None:            # nothing delivered yet: the first fix, unaged (start-up)
            self._delivered = self._fixes[0]
        t_meas, p, v = self._delivered
        return p, v, (t_meas // 1000) * 1e-3
