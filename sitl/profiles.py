"""Sensor profiles of the SITL and the resolution of ``sim.noise`` against them.

``resolve_sensor_model(sim, sensor_hz)`` turns a mission's ``sim`` section
into the ``SensorModel`` the sensors use: every ``sim.noise`` key that is
given wins; otherwise the named profile's value (``sim.sensor_profile``);
otherwise the no-profile default ``PAPER_DEFAULTS`` (the paper's model,
Section 3.4: white noise of variance 5e-4 on the unit vectors and on Omega,
exact position and velocity every frame, no bias). Independent error
sources add: the per-sample white variances of a sensor are summed.

Profile ``icm42688p-bmm150-zedf9p`` (a current PX4 flight controller with an
RTK receiver)
-----------------------------------------------------------------------------
IMU: TDK InvenSense ICM-42688-P (Pixhawk 6C/6X and many others), datasheet
DS-000347:

- gyro rate noise spectral density 2.8 mdps/sqrt(Hz)
  = 2.8e-3 * pi/180 = 4.887e-5 rad/s/sqrt(Hz);
- accelerometer noise spectral density 70 ug/sqrt(Hz)
  = 70e-6 * 9.80665 = 6.865e-4 m/s^2/sqrt(Hz);
- gyro zero-rate output, initial tolerance +-0.5 dps -> turn-on bias, std
  0.5 dps = 8.727e-3 rad/s per axis (seeded draw);
- accelerometer zero-g output, initial tolerance +-20 mg: the flight stack
  calibrates it away before HIGHRES_IMU is published (PX4 applies its
  CAL_ACC* offsets), so the turn-on bias here is the calibration residual,
  sized by the datasheet's zero-g temperature coefficient +-0.15 mg/K for a
  20 K difference between calibration and flight: std 3 mg = 0.0294 m/s^2
  per axis (seeded draw). ``accel_bias_turn_on_std_m_s2: 0.196`` gives the
  uncalibrated part;
- the datasheet gives no bias instability; the drift is modelled as a
  random walk sized by the datasheet's temperature coefficients (gyro ZRO
  +-0.005 dps/K, accelerometer zero-g +-0.15 mg/K) for a 5 K change of the
  board temperature over a 600 s flight: 1-sigma drift after 600 s of
  0.025 dps and 0.75 mg, so walk = drift / sqrt(600 s):
  gyro 0.025 * pi/180 / sqrt(600) = 1.781e-5 rad/s/sqrt(s),
  accel 0.75e-3 * 9.80665 / sqrt(600) = 3.003e-4 m/s^2/sqrt(s).

Per-sample white std at the sensor rate f (250 Hz by default) is
density * sqrt(f) (the discrete equivalent of continuous white noise
sampled every 1/f): gyro 7.73e-4 rad/s, accel 1.085e-2 m/s^2 at 250 Hz.

Magnetometer: Bosch Sensortec BMM150 (Pixhawk 6X), datasheet
BST-BMM150-DS001: resolution about 0.3 uT; RMS noise 0.6 uT in the
"regular" preset -> 0.006 gauss white per sample and axis (the part runs
at 10-30 Hz; the SITL samples it every frame, a simplification). Local
disturbance (assumed, not from a datasheet): a hard-iron residual of
(0.8, -0.6, 1.2) uT in body FLU after calibration, and a motor-current
field of 5 % of the Earth field (0.47 gauss) at full thrust (100 N),
along body (0.3, 0.2, 0.93): 2.35e-4 gauss/N * that direction.

GNSS: u-blox ZED-F9P RTK receiver (datasheet UBX-17051259: RTK position
accuracy 0.01 m + 1 ppm CEP, navigation rate up to 20 Hz in RTK). White
noise per sample of 0.01 m horizontally per axis (a CEP of 1 cm is a
per-axis std of 0.85 cm: rounded up), 0.02 m vertically, 0.02 m/s per
axis on velocity; 10 Hz; 80 ms from measurement to delivery (typical
RTK output latency is 50-100 ms).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from mavcore.mission.sim import SENSOR_PROFILES, NoiseConfig, SimConfig

_DEG = math.pi / 180.0
_G0 = 9.80665          # standard gravity (datasheets' "g")

#: No-profile defaults: the paper's sensor model (every ``NoiseConfig`` key).
PAPER_DEFAULTS: dict = {
    "vector_variance": 5.0e-4,
    "gyro_variance": 5.0e-4,
    "gyro_noise_density_rad_s_rthz": 0.0,
    "accel_noise_density_m_s2_rthz": 0.0,
    "gyro_bias_rad_s": (0.0, 0.0, 0.0),
    "accel_bias_m_s2": (0.0, 0.0, 0.0),
    "gyro_bias_turn_on_std_rad_s": 0.0,
    "accel_bias_turn_on_std_m_s2": 0.0,
    "gyro_bias_walk_rad_s_rts": 0.0,
    "accel_bias_walk_m_s2_rts": 0.0,
    "mag_noise_std_gauss": 0.0,
    "mag_hard_iron_gauss": (0.0, 0.0, 0.0),
    "mag_thrust_gauss_per_n": (0.0, 0.0, 0.0),
    "position_std_m": 0.0,
    "position_z_std_m": None,          # None: same as position_std_m
    "velocity_std_m_s": 0.0,
    "gnss_rate_hz": None,              # None: every sensor frame
    "gnss_latency_s": 0.0,
    "range_std_m": 0.01,
    "range_dropout_probability": 0.0,
}

_MOTOR_DIR = (0.3, 0.2, 0.93)
_MOTOR_K = 0.05 * 0.47 / 100.0          # gauss per newton: 5 % of 0.47 G at 100 N
_MOTOR_N = math.sqrt(sum(x * x for x in _MOTOR_DIR))

#: The named profiles (module docstring for the sources of every figure).
PROFILES: dict[str, dict] = {
    "icm42688p-bmm150-zedf9p": dict(
        PAPER_DEFAULTS,
        vector_variance=0.0,
        gyro_variance=0.0,
        gyro_noise_density_rad_s_rthz=2.8e-3 * _DEG,
        accel_noise_density_m_s2_rthz=70e-6 * _G0,
        gyro_bias_turn_on_std_rad_s=0.5 * _DEG,
        accel_bias_turn_on_std_m_s2=0.15e-3 * 20.0 * _G0,
        gyro_bias_walk_rad_s_rts=0.005 * 5.0 * _DEG / math.sqrt(600.0),
        accel_bias_walk_m_s2_rts=0.15e-3 * 5.0 * _G0 / math.sqrt(600.0),
        mag_noise_std_gauss=0.006,
        mag_hard_iron_gauss=(0.008, -0.006, 0.012),
        mag_thrust_gauss_per_n=tuple(_MOTOR_K * x / _MOTOR_N for x in _MOTOR_DIR),
        position_std_m=0.01,
        position_z_std_m=0.02,
        velocity_std_m_s=0.02,
        gnss_rate_hz=10.0,
        gnss_latency_s=0.08,
    ),
}
assert tuple(PROFILES) == SENSOR_PROFILES, "profile names must match mavcore.mission.sim.SENSOR_PROFILES"


@dataclass(frozen=True)
class SensorModel:
    """Resolved sensor errors of one run (SI units, body FLU, per sample).

    Attributes
    ----------
    sensor_hz : int
        Sensor frame rate (Hz).
    vector_sensors : str
        ``physical`` (specific force and Earth field) or ``paper`` (unit
        vectors of constant inertial directions, ``sitl.sensors``).
    accel_rel_std : float
        Std of the accelerometer/magnetometer direction noise (-), sqrt(vector_variance).
    accel_std_m_s2 : float
        Absolute white accelerometer std per sample (density * sqrt(rate)).
    gyro_std_rad_s : float
        White gyro std per sample, sqrt(gyro_variance + density^2 * rate).
    mag_std_gauss : float
        Absolute white magnetometer std per sample and axis.
    gyro_bias_rad_s, accel_bias_m_s2 : (3,) tuple
        Constant biases.
    gyro_bias_turn_on_std_rad_s, accel_bias_turn_on_std_m_s2 : float
    gyro_bias_walk_rad_s_rts, accel_bias_walk_m_s2_rts : float
    mag_hard_iron_gauss, mag_thrust_gauss_per_n : (3,) tuple
    position_std_xy_m, position_std_z_m, velocity_std_m_s : float
    gnss_period_us : int
        Time between GNSS measurements (us), at least one sensor period.
    gnss_latency_us : int
        Measurement-to-delivery delay (us).
    range_std_m : float
    range_dropout_probability : float
        Probability that a due rangefinder reading is lost.
    """

    sensor_hz: int
    vector_sensors: str
    accel_rel_std: float
    accel_std_m_s2: float
    gyro_std_rad_s: float
    mag_std_gauss: float
    gyro_bias_rad_s: tuple
    accel_bias_m_s2: tuple
    gyro_bias_turn_on_std_rad_s: float
    accel_bias_turn_on_std_m_s2: float
    gyro_bias_walk_rad_s_rts: float
    accel_bias_walk_m_s2_rts: float
    mag_hard_iron_gauss: tuple
    mag_thrust_gauss_per_n: tuple
    position_std_xy_m: float
    position_std_z_m: float
    velocity_std_m_s: float
    gnss_period_us: int
    gnss_latency_us: int
    range_std_m: float
    range_dropout_probability: float = 0.0


def noise_values(sim: SimConfig) -> dict:
    """Every ``NoiseConfig`` key's value for this mission: given > profile > paper default."""
    base = PROFILES[sim.sensor_profile] if sim.sensor_profile is not None else PAPER_DEFAULTS
    out = {}
    for f in fields(NoiseConfig):
        v = getattr(sim.noise, f.name)
        out[f.name] = base[f.name] if v is None else v
    return out


def resolve_sensor_model(sim: SimConfig, sensor_hz: int = 250) -> SensorModel:
    """The ``SensorModel`` of a mission's ``sim`` section at ``sensor_hz``."""
    v = noise_values(sim)
    rate = float(sensor_hz)
    period_us = 1_000_000 // int(sensor_hz)
    gnss_hz = v["gnss_rate_hz"]
    gnss_period_us = period_us if gnss_hz is None else max(period_us, int(round(1e6 / gnss_hz)))
    pos_xy = float(v["position_std_m"])
    pos_z = pos_xy if v["position_z_std_m"] is None else float(v["position_z_std_m"])
    return SensorModel(
        sensor_hz=int(sensor_hz),
        vector_sensors=sim.vector_sensors,
        accel_rel_std=math.sqrt(v["vector_variance"]),
        accel_std_m_s2=v["accel_noise_density_m_s2_rthz"] * math.sqrt(rate),
        gyro_std_rad_s=math.sqrt(v["gyro_variance"] + v["gyro_noise_density_rad_s_rthz"] ** 2 * rate),
        mag_std_gauss=float(v["mag_noise_std_gauss"]),
        gyro_bias_rad_s=tuple(float(x) for x in v["gyro_bias_rad_s"]),
        accel_bias_m_s2=tuple(float(x) for x in v["accel_bias_m_s2"]),
        gyro_bias_turn_on_std_rad_s=float(v["gyro_bias_turn_on_std_rad_s"]),
        accel_bias_turn_on_std_m_s2=float(v["accel_bias_turn_on_std_m_s2"]),
        gyro_bias_walk_rad_s_rts=float(v["gyro_bias_walk_rad_s_rts"]),
        accel_bias_walk_m_s2_rts=float(v["accel_bias_walk_m_s2_rts"]),
        mag_hard_iron_gauss=tuple(float(x) for x in v["mag_hard_iron_gauss"]),
        mag_thrust_gauss_per_n=tuple(float(x) for x in v["mag_thrust_gauss_per_n"]),
        position_std_xy_m=pos_xy,
        position_std_z_m=pos_z,
        velocity_std_m_s=float(v["velocity_std_m_s"]),
        gnss_period_us=gnss_period_us,
        gnss_latency_us=int(round(float(v["gnss_latency_s"]) * 1e6)),
        range_std_m=float(v["range_std_m"]),
        range_dropout_probability=float(v["range_dropout_probability"]),
    )
