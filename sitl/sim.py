"""The pure per-frame simulation: plant + wind + world + sensors.

No I/O, no clock: ``Simulation.step_frame(motor_cmd)`` advances one sensor
period (``physics_hz / sensor_hz`` physics steps with the commands held,
zero-order hold) and returns the sensor frame. The flight-stack shell
(``sitl.flightstack``) decides where the motor commands come from (the
companion's HIL_ACTUATOR_CONTROLS or ``Simulation.onboard``).

``sim.onboard_state: estimate`` (default): every frame also runs the
vehicle's own estimator (``sitl.estimator``) on the frame's measurements,
and ``step_onboard`` flies the cascaded controller on that estimate;
``truth``: on the true state (the SITL without an estimator). The ground
contact flag (``landed``) is the plant's in both modes: it stands for the
flight stack's land detector.
"""

from __future__ import annotations

import math
from dataclasses import FrozenInstanceError, dataclass

import numpy as np

from mavcore.mission.schema import Mission

from .estimator import Estimate, EstimatorConfig, OnboardEstimator
from mavcore.mission.sim import vehicle_radius_m

from .collision import CollisionMonitor, CrashEvent
from .onboard import CascadedController, OnboardGains, Setpoint  # noqa: F401  (re-export)
from mavcore.codec import RateSetpoint

from .rate_control import RateLoop, thrust_curve_inverse
from .plant import Plant, PlantParams
from .sensors import RangeReading, SensorSuite  # noqa: F401  (re-export)
from .wind import WindModel
from .world import World


_set = object.__setattr__


def _vec(x):
    """A float tuple as a fresh (3,)/(4,) array; an array (or anything else) as given."""
    return np.array(x) if type(x) is tuple else x


def _mat(x):
    """A row-major 9-tuple (or a tuple of rows) as a fresh (3, 3) array."""
    return np.array(x).reshape(3, 3) if type(x) is tuple else x


class _Lazy:
    """Immutable record whose vector fields are kept as float tuples and
    turned into numpy arrays on first access (cached).

    Building the arrays of every frame eagerly costs more than the onboard
    controller (about 0.4 us per ``np.array``), and most consumers read only
    a few fields. Reading a field always gives the same ndarray object.
    """

    __slots__ = ()

    def __setattr__(self, name, value):
        raise FrozenInstanceError(f"cannot assign to field {name!r}")

    def __delattr__(self, name):
        raise FrozenInstanceError(f"cannot delete field {name!r}")

    def __repr__(self) -> str:
        fields = ", ".join(f"{n}={getattr(self, n)!r}" for n in self._fields)
        return f"{type(self).__name__}({fields})"


def _lazy_field(slot: str, convert, doc: str):
    def get(self):
        x = getattr(self, slot)
        if type(x) is tuple:
            x = convert(x)
            _set(self, slot, x)
        return x
    return property(get, doc=doc)


class TrueState(_Lazy):
    """Ground truth of the vehicle (world ENU, body FLU); immutable.

    Attributes
    ----------
    pos_enu_m, vel_enu_m_s, acc_enu_m_s2 : (3,) ndarray
    R : (3, 3) ndarray, body FLU -> world ENU
    omega_flu_rad_s : (3,) ndarray
    landed : bool
    motor_thrust_n : (4,) ndarray, rotor thrusts (N), PX4 order

    Constructed like the former frozen dataclass (same field order); float
    tuples are accepted and become arrays when first read.
    """

    __slots__ = ("_p", "_v", "_R", "_w", "_a", "landed", "_f")
    _fields = ("pos_enu_m", "vel_enu_m_s", "R", "omega_flu_rad_s", "acc_enu_m_s2", "landed",
               "motor_thrust_n")

    def __init__(self, pos_enu_m, vel_enu_m_s, R, omega_flu_rad_s, acc_enu_m_s2, landed,
                 motor_thrust_n) -> None:
        _set(self, "_p", pos_enu_m)
        _set(self, "_v", vel_enu_m_s)
        _set(self, "_R", R)
        _set(self, "_w", omega_flu_rad_s)
        _set(self, "_a", acc_enu_m_s2)
        _set(self, "landed", landed)
        _set(self, "_f", motor_thrust_n)

    pos_enu_m = _lazy_field("_p", _vec, "(3,) position, world ENU (m)")
    vel_enu_m_s = _lazy_field("_v", _vec, "(3,) velocity, world ENU (m/s)")
    R = _lazy_field("_R", _mat, "(3, 3) rotation body FLU -> world ENU")
    omega_flu_rad_s = _lazy_field("_w", _vec, "(3,) body rate, FLU (rad/s)")
    acc_enu_m_s2 = _lazy_field("_a", _vec, "(3,) acceleration, world ENU (m/s^2)")
    motor_thrust_n = _lazy_field("_f", _vec, "(4,) rotor thrusts (N), PX4 order")


class SensorFrame(_Lazy):
    """Everything the vehicle measures at one sensor instant; immutable.

    Attributes
    ----------
    time_us : int
        Vehicle time since boot (us).
    accel_flu_m_s2 : (3,) ndarray, accelerometer fields, body FLU (specific
        force; g R^T e3 with ``sim.vector_sensors: paper``)
    gyro_flu_rad_s : (3,) ndarray
    mag_flu_gauss : (3,) ndarray
    pos_enu_m, vel_enu_m_s : (3,) ndarray, the latest delivered position/velocity sample
    ranges : tuple of RangeReading (only those due this frame)
    truth : TrueState
    pos_time_us : int
        Measurement time of ``pos_enu_m``/``vel_enu_m_s`` (us; older than
        ``time_us`` by the GNSS latency and the hold since then).
    estimate : sitl.estimator.Estimate or None
        The onboard estimator's output (None with ``sim.onboard_state: truth``).

    Constructed like the former frozen dataclass (same field order); float
    tuples are accepted and become arrays when first read.
    """

    __slots__ = ("time_us", "_acc", "_gyro", "_mag", "_pos", "_vel", "ranges", "truth", "pos_time_us",
                 "estimate")
    _fields = ("time_us", "accel_flu_m_s2", "gyro_flu_rad_s", "mag_flu_gauss", "pos_enu_m",
               "vel_enu_m_s", "ranges", "truth", "pos_time_us", "estimate")

    def __init__(self, time_us, accel_flu_m_s2, gyro_flu_rad_s, mag_flu_gauss, pos_enu_m,
                 vel_enu_m_s, ranges, truth, pos_time_us=None, estimate=None) -> None:
        _set(self, "time_us", time_us)
        _set(self, "_acc", accel_flu_m_s2)
        _set(self, "_gyro", gyro_flu_rad_s)
        _set(self, "_mag", mag_flu_gauss)
        _set(self, "_pos", pos_enu_m)
        _set(self, "_vel", vel_enu_m_s)
        _set(self, "ranges", ranges)
        _set(self, "truth", truth)
        _set(self, "pos_time_us", time_us if pos_time_us is None else pos_time_us)
        _set(self, "estimate", estimate)

    accel_flu_m_s2 = _lazy_field("_acc", _vec, "(3,) accelerometer fields, body FLU (m/s^2)")
    gyro_flu_rad_s = _lazy_field("_gyro", _vec, "(3,) body rate measurement, FLU (rad/s)")
    mag_flu_gauss = _lazy_field("_mag", _vec, "(3,) magnetic field, body FLU (gauss)")
    pos_enu_m = _lazy_field("_pos", _vec, "(3,) position measurement, world ENU (m)")
    vel_enu_m_s = _lazy_field("_vel", _vec, "(3,) velocity measurement, world ENU (m/s)")


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
        Default: the mission's ``sim.start_enu_m``, else the free OGM cell
        nearest to the centroid of the free space (``World.start_cell_enu``),
        else the origin; on the terrain.
    world : World, optional
        Terrain, rows and obstacles (``sitl.world.load_world(mission)`` reads
        the mission's maps). Default: flat ground at z = 0 with the mission's
        obstacles and no rows.
    start_yaw_rad : float
        Initial heading (ENU, from east).
    gains : OnboardGains
        Gains of ``onboard``.

    The vehicle starts landed with the motors stopped.

    Crashes (issue 8, ``sitl.collision``; off with ``sim.collision.enabled:
    false``): after every frame the vehicle sphere's path over the frame is
    checked against the obstacles and rows, and a touchdown against the
    touchdown limits (``landing_intent``, a callable set by the flight-stack
    shell, says whether the vehicle was landing; without one every touchdown
    counts as a landing and only the speed limits apply). A crash stops the
    rotors for good (``Plant.crash``) and is kept in ``crash`` (a
    ``CrashEvent``) until ``reset``. Movers (``sim.movers``) are posed on the
    vehicle clock after every frame (``World.set_time``) and a contact with
    one is a crash named ``walker #k`` / ``tractor #k`` (``sitl.movers``).
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
            None, None, sim.obstacles, sim.canopy_height_m, sim.movers)
        plant_params = PlantParams(mission.vehicle, drag_n_s_m=sim.wind.drag_n_s_m)
        self.params = SimParams(physics_hz, sensor_hz, plant_params, gains)
        self.plant = Plant(plant_params, self.world.ground_height, self.world.terrain.max_height_m)
        self.wind = WindModel(sim.wind, rng)
        self.sensors = SensorSuite(sim, self.world, rng, sensor_hz)
        self.onboard = CascadedController(mission.vehicle, gains, plant_params.gravity_m_s2)
        #: The inner rate loop for attitude-rate setpoints (``sitl.rate_control``) and the motor
        #: curve factor its thrust goes through (THR_MDL_FAC; 0 for the simulated linear motors).
        self.rates = RateLoop(mission.vehicle.inertia_kg_m2)
        self.thrust_model_factor = 0.0
        md = self.sensors.model
        #: Configuration of the onboard estimator (None: ``sim.onboard_state: truth``).
        self.estimator_config = None if sim.onboard_state == "truth" else EstimatorConfig(
            accel_mode="inclinometer" if sim.vector_sensors == "paper" else "specific_force",
            mag_enu_gauss=tuple(sim.magnetic_field_enu_gauss), gravity_m_s2=plant_params.gravity_m_s2,
            pos_std_xy_m=md.position_std_xy_m, pos_std_z_m=md.position_std_z_m,
            vel_std_m_s=md.velocity_std_m_s,
            # an inclinometer gives no acceleration: a looser motion model
            accel_noise_m_s2_rthz=0.5 if sim.vector_sensors == "paper" else EstimatorConfig.accel_noise_m_s2_rthz)
        self.estimator: OnboardEstimator | None = None
        self.sensor_period_us = 1_000_000 // sensor_hz
        self.substeps = physics_hz // sensor_hz
        self.dt_physics_s = 1.0 / physics_hz
        self.dt_frame_s = self.sensor_period_us * 1e-6
        self.time_us = 0
        col = sim.collision
        self.vehicle_radius_m = vehicle_radius_m(sim, mission.vehicle.arm_m)
        self.collisions = (CollisionMonitor(self.world.geometry, self.vehicle_radius_m, col)
                           if col.enabled and self.world.geometry is not None else None)
        self.landing_intent = None
        self.crash: CrashEvent | None = None
        self.reset(start_enu_m, start_yaw_rad)

    # ----------------------------------------------------------------------
    def reset(self, start_enu_m=None, yaw_rad: float = 0.0) -> None:
        """Put the vehicle landed at ``start_enu_m`` (see the constructor)."""
        if start_enu_m is None:
            xy = self.mission.sim.start_enu_m or self.world.start_cell_enu() or (0.0, 0.0)
            start = (float(xy[0]), float(xy[1]), -math.inf)
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
        self.rates.reset()
        self.world.set_time(self.time_us * 1e-6)
        self.crash = None
        self._truth = None
        pl = self.plant
        self.sensors.gnss.reset(pl.p, pl.v)
        self.estimator = (None if self.estimator_config is None
                          else OnboardEstimator(self.estimator_config))
        self.estimate: Estimate | None = None

    @property
    def truth(self) -> TrueState:
        """Current ground truth."""
        if self._truth is None:
            pl = self.plant
            # the plant's state tuples are immutable: holding them is a snapshot
            self._truth = TrueState(pl.p, pl.v, pl.R, pl.w, pl.acc, pl.landed, pl.f)
        return self._truth

    def step_frame(self, motor_cmd_norm) -> SensorFrame:
        """Advance one sensor period with the motor commands held, then sample.

        Parameters
        ----------
        motor_cmd_norm : (4,) array-like
            Normalised motor commands in [0, 1], PX4 quad-X order
            (``mavcore.vehicle``); values outside are clipped.

        Returns
        -------
        SensorFrame
        """
        cmd = (float(motor_cmd_norm[0]), float(motor_cmd_norm[1]),
               float(motor_cmd_norm[2]), float(motor_cmd_norm[3]))
        wind = self.wind.step(self.dt_frame_s)
        pl = self.plant
        p0, landed0, touchdowns0 = pl.p, pl.landed, pl.touchdowns
        pl.advance(cmd, self.dt_physics_s, self.substeps, wind)
        if self.collisions is not None and not pl.crashed:
            self._check_contacts(p0, landed0, touchdowns0)
        self.time_us += self.sensor_period_us
        self.world.set_time(self.time_us * 1e-6)     # movers where they are now, on the vehicle clock
        self._truth = None
        return self._sample()

    def _check_contacts(self, p0, landed0: bool, touchdowns0: int) -> None:
        """Crash the vehicle if this frame's motion hit something (module notes)."""
        pl = self.plant
        mon = self.collisions
        if not (landed0 and pl.landed):
            c = mon.sweep(p0, pl.p)
            if c is not None:
                f = c.fraction
                pos = tuple(a + f * (b - a) for a, b in zip(p0, pl.p))
                self._crashed(c.kind, c.obstacle_index, pos, pl.v, f)
                return
        # movers walk into a parked vehicle too
        if self.world.moving is not None and self._mover_contact(p0):
            return
        if pl.touchdowns != touchdowns0:
            landing = True if self.landing_intent is None else bool(self.landing_intent())
            if mon.touchdown_is_crash(pl.impact_vel_enu_m_s, landing):
                self._crashed("terrain", None, pl.p, pl.impact_vel_enu_m_s, 1.0)

    def _mover_contact(self, p0) -> bool:
        """Crash on a mover (``sim.movers``, ``sitl.movers``) hit during this frame."""
        pl = self.plant
        t0 = self.time_us * 1e-6
        hit = self.world.moving.sweep(p0, pl.p, t0, t0 + self.dt_frame_s, self.vehicle_radius_m)
        if hit is None:
            return False
        f, k = hit
        pos = tuple(a + f * (b - a) for a, b in zip(p0, pl.p))
        self._crashed(self.world.moving.movers[k].type, k, pos, pl.v, f)
        return True

    def _crashed(self, kind: str, index, pos, vel, fraction: float) -> None:
        t_us = self.time_us + int(round(fraction * self.sensor_period_us))
        self.crash = CrashEvent(t_us, kind, index, tuple(float(x) for x in pos), tuple(float(v) for v in vel))
        self.plant.crash(pos, self.collisions.rest_height_m(*pos))

    def step_onboard(self, sp: Setpoint) -> SensorFrame:
        """One frame flown by the onboard controller on the estimate (or, with
        ``sim.onboard_state: truth``, the true state): the plain-float fast
        path of ``step_frame(onboard.update(state, sp, dt))``."""
        pl = self.plant
        e = self.estimate
        if self.estimator is not None and e is not None:
            cmd = self.onboard.update_floats(e.pos_enu_m, e.vel_enu_m_s, e.R, e.omega_flu_rad_s, sp,
                                             self.dt_frame_s, pl.landed)
        else:
            cmd = self.onboard.update_floats(pl.p, pl.v, pl.R, pl.w, sp, self.dt_frame_s, pl.landed)
        return self.step_frame(cmd)

    def step_rates(self, sp: RateSetpoint) -> SensorFrame:
        """One frame flown by the inner rate loop on an attitude-rate setpoint
        (``sitl.rate_control``): the rate loop's torques on the estimate's body
        rates (or the true ones with ``sim.onboard_state: truth``), the collective
        ``thrust * 4 f_max``, mixed with the cascade's priorities, each rotor's
        relative thrust through the inverse motor curve."""
        pl = self.plant
        e = self.estimate
        w = e.omega_flu_rad_s if self.estimator is not None and e is not None else pl.w
        tx, ty, tz = self.rates.update(w, sp.rates_flu_rad_s, self.dt_frame_s, pl.landed)
        rel = self.onboard.mix(sp.thrust * 4.0 * self.onboard.fmax, tx, ty, tz)
        k = self.thrust_model_factor
        return self.step_frame(rel if k == 0.0 else tuple(thrust_curve_inverse(t, k) for t in rel))

    def _sample(self) -> SensorFrame:
        pl = self.plant
        p, R = pl.p, pl.R
        truth = self._truth = TrueState(p, pl.v, R, pl.w, pl.acc, pl.landed, pl.f)
        sensors = self.sensors
        f = pl.f
        # Same draws, same order as ``imu`` then the GNSS then ``ranges``.
        acc, gyro, mag = sensors.imu_tuples(R, pl.acc, pl.w, self.params.plant.gravity_m_s2,
                                            f[0] + f[1] + f[2] + f[3])
        fix = sensors.gnss.step(self.time_us, p, pl.v)
        ranges = sensors.ranges(self.time_us, p, R)
        est = None
        if self.estimator is not None:
            est = self.estimate = self.estimator.update(self.time_us, self.dt_frame_s, gyro, acc, mag, fix)
        return SensorFrame(self.time_us, acc, gyro, mag, fix.pos_enu_m, fix.vel_enu_m_s, ranges, truth,
                           fix.time_us, est)
