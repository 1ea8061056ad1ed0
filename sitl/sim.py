"""The pure per-frame simulation: plant + wind + world + sensors.

No I/O, no clock: ``Simulation.step_frame(motor_cmd)`` advances one sensor
period (``physics_hz / sensor_hz`` physics steps with the commands held,
zero-order hold) and returns the sensor frame. The flight-stack shell
(``sitl.flightstack``) decides where the motor commands come from (the
companion's HIL_ACTUATOR_CONTROLS or ``Simulation.onboard``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.mission.schema import Mission

from .onboard import CascadedController, OnboardGains, Setpoint  # noqa: F401  (re-export)
from .plant import Plant, PlantParams
from .sensors import RangeReading, SensorSuite
from .wind import WindModel
from .world import World


@dataclass(frozen=True)
class TrueState:
    """Ground truth of the vehicle (world ENU, body FLU).

    Attributes
    ----------
    pos_enu_m, vel_enu_m_s, acc_enu_m_s2 : (3,)
    R : (3, 3) body FLU -> world ENU
    omega_flu_rad_s : (3,)
    landed : bool
    motor_thrust_n : (4,) rotor thrusts (N), PX4 order
    """

    pos_enu_m: np.ndarray
    vel_enu_m_s: np.ndarray
    R: np.ndarray
    omega_flu_rad_s: np.ndarray
    acc_enu_m_s2: np.ndarray
    landed: bool
    motor_thrust_n: np.ndarray


@dataclass(frozen=True)
class SensorFrame:
    """Everything the vehicle measures at one sensor instant.

    Attributes
    ----------
    time_us : int
        Vehicle time since boot (us).
    accel_flu_m_s2 : (3,) specific force, body FLU
    gyro_flu_rad_s : (3,)
    mag_flu_gauss : (3,)
    pos_enu_m, vel_enu_m_s : (3,) position/velocity measurements
    ranges : tuple of RangeReading (only those due this frame)
    truth : TrueState
    """

    time_us: int
    accel_flu_m_s2: np.ndarray
    gyro_flu_rad_s: np.ndarray
    mag_flu_gauss: np.ndarray
    pos_enu_m: np.ndarray
    vel_enu_m_s: np.ndarray
    ranges: tuple[RangeReading, ...]
    truth: TrueState


@dataclass(frozen=True)
class SimParams:
    """Rates and physics of a ``Simulation``."""

    physics_hz: int
    sensor_hz: int
    plant: PlantParams
    gains: OnboardGains


class Simulation:
    """Plant, wind, world and sensors stepped frame by frame (pure, seeded).

    Parameters
    ----------
    mission : Mission
        ``vehicle`` and ``sim`` sections are used.
    rng : numpy.random.Generator
        The only source of randomness (wind gusts, sensor noise).
    physics_hz, sensor_hz : int
        Physics rate and sensor frame rate; physics_hz must be a multiple of sensor_hz.
    start_enu_m : (3,) or (2,), optional
        Start position; (x, y) or a z below the terrain: on the terrain.
        Default: the first free OGM cell (or the origin), on the terrain.
    world : World, optional
        Terrain, rows and obstacles (``sitl.world.load_world(mission)`` reads
        the mission's maps). Default: flat ground at z = 0 with the mission's
        obstacles and no rows.
    start_yaw_rad : float
        Initial heading (ENU, from east).
    gains : OnboardGains
        Gains of ``onboard``.

    The vehicle starts landed with the motors stopped.
    """

    def __init__(self, mission: Mission, rng: np.random.Generator, *, physics_hz: int = 1000,
                 sensor_hz: int = 250, start_enu_m=None, world: World | None = None,
                 start_yaw_rad: float = 0.0, gains: OnboardGains = OnboardGains()) -> None:
        if physics_hz <= 0 or sensor_hz <= 0 or physics_hz % sensor_hz:
            raise ValueError("physics_hz must be a positive multiple of sensor_hz")
        if 1_000_000 % sensor_hz:
            raise ValueError("sensor_hz must divide 1e6 (integer microsecond frames)")
        self.mission = mission
        self.rng = rng
        sim = mission.sim
        self.world = world if world is not None else World.build(
            None, None, sim.obstacles, sim.canopy_height_m)
        plant_params = PlantParams(mission.vehicle, drag_n_s_m=sim.wind.drag_n_s_m)
        self.params = SimParams(physics_hz, sensor_hz, plant_params, gains)
        self.plant = Plant(plant_params, self.world.ground_height, self.world.terrain.max_height_m)
        self.wind = WindModel(sim.wind, rng)
        self.sensors = SensorSuite(sim, self.world, rng)
        self.onboard = CascadedController(mission.vehicle, gains, plant_params.gravity_m_s2)
        self.sensor_period_us = 1_000_000 // sensor_hz
        self.substeps = physics_hz // sensor_hz
        self.dt_physics_s = 1.0 / physics_hz
        self.dt_frame_s = self.sensor_period_us * 1e-6
        self.time_us = 0
        self.reset(start_enu_m, start_yaw_rad)

    # ----------------------------------------------------------------------
    def reset(self, start_enu_m=None, yaw_rad: float = 0.0) -> None:
        """Put the vehicle landed at ``start_enu_m`` (see the constructor)."""
        if start_enu_m is None:
            xy = self.world.first_free_cell_enu() or (0.0, 0.0)
            start = (xy[0], xy[1], -math.inf)
        else:
            s = [float(x) for x in start_enu_m]
            start = (s[0], s[1], s[2] if len(s) > 2 else -math.inf)
        zg = self.world.ground_height(start[0], start[1])
        c, s_ = math.cos(yaw_rad), math.sin(yaw_rad)
        R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
        if start[2] <= zg:
            self.plant.set_state((start[0], start[1], zg), R=R, landed=True)
        else:
            self.plant.set_state(start, R=R, landed=False)
        self.onboard.reset()
        self._truth = None

    @property
    def truth(self) -> TrueState:
        """Current ground truth."""
        if self._truth is None:
            pl = self.plant
            p, v, R, w, a, f = pl.state_arrays()
            self._truth = TrueState(p, v, R, w, a, pl.landed, f)
        return self._truth

    def step_frame(self, motor_cmd_norm) -> SensorFrame:
        """Advance one sensor period with the motor commands held, then sample.

        Parameters
        ----------
        motor_cmd_norm : (4,) array-like
            Normalised motor commands in [0, 1], PX4 quad-X order
            (``companion.vehicle``); values outside are clipped.

        Returns
        -------
        SensorFrame
        """
        cmd = (float(motor_cmd_norm[0]), float(motor_cmd_norm[1]),
               float(motor_cmd_norm[2]), float(motor_cmd_norm[3]))
        wind = self.wind.step(self.dt_frame_s)
        step = self.plant.step
        h = self.dt_physics_s
        for _ in range(self.substeps):
            step(cmd, h, wind)
        self.time_us += self.sensor_period_us
        self._truth = None
        return self._sample()

    def step_onboard(self, sp: Setpoint) -> SensorFrame:
        """One frame flown by the onboard controller on the true state
        (the plain-float fast path; equivalent to
        ``step_frame(onboard.update(truth, sp, dt))``)."""
        pl = self.plant
        cmd = self.onboard.update_floats(pl.p, pl.v, pl.R, pl.w, sp, self.dt_frame_s, pl.landed)
        return self.step_frame(cmd)

    def _sample(self) -> SensorFrame:
        pl = self.plant
        truth = self.truth
        imu = self.sensors.imu_floats(pl.R, pl.acc, pl.w, self.params.plant.gravity_m_s2)
        pos, vel = self.sensors.position(truth.pos_enu_m, truth.vel_enu_m_s)
        ranges = self.sensors.ranges(self.time_us, pl.p, pl.R)
        return SensorFrame(self.time_us, imu.accel_flu_m_s2, imu.gyro_flu_rad_s, imu.mag_flu_gauss,
                           pos, vel, ranges, truth)
