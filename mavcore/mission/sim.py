"""The ``sim:`` section of a mission: known to the SITL only, never to the planner.

Owned by the simulator (issue 3); the companion only parses it so that a
mission file is validated in one place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Literal


@dataclass(frozen=True)
class ObstacleConfig:
    """An unknown obstacle, ENU metres on the map frame, standing on the terrain.

    ``cylinder`` uses ``radius``; ``box`` uses ``size_x``/``size_y`` (m) and
    ``yaw_deg`` (rotation about z, ENU, CCW from east).
    """

    type: Literal["cylinder", "box"]
    x: float
    y: float
    height: float
    radius: float = 0.0
    size_x: float = 0.0
    size_y: float = 0.0
    yaw_deg: float = 0.0

    def __post_init__(self) -> None:
        if self.height <= 0:
            raise ValueError("obstacle height must be > 0")
        if self.type == "cylinder" and self.radius <= 0:
            raise ValueError("cylinder radius must be > 0")
        if self.type == "box" and (self.size_x <= 0 or self.size_y <= 0):
            raise ValueError("box size_x and size_y must be > 0")


#: Moving obstacle kinds (``sim.movers[].type``) and their solids: a
#: ``walker`` (a worker) is a vertical cylinder of ``WALKER_RADIUS_M`` x
#: ``WALKER_HEIGHT_M``; a ``tractor`` a box ``TRACTOR_WIDTH_M`` wide,
#: ``TRACTOR_LENGTH_M`` long along its heading, ``TRACTOR_HEIGHT_M`` tall.
MOVER_TYPES = ("walker", "tractor")
WALKER_RADIUS_M = 0.25
WALKER_HEIGHT_M = 1.8
TRACTOR_WIDTH_M = 1.5
TRACTOR_LENGTH_M = 3.0
TRACTOR_HEIGHT_M = 2.5
#: Fastest scripted speed (m/s) of a walker (a brisk walk) and of a tractor.
WALKER_MAX_SPEED_M_S = 1.5
TRACTOR_MAX_SPEED_M_S = 5.0


@dataclass(frozen=True)
class MoverConfig:
    """A moving obstacle on a scripted path (``sim.movers[]``), ENU metres on
    the map frame, standing on the terrain under its centre.

    It waits at ``path[0]`` until ``start_s`` (vehicle clock, s since the
    SITL's boot), then moves along the polyline at ``speed_m_s``; at the end
    it stops (``loop: false``) or walks back and forth along it (``loop:
    true``). Kinematics: ``mavcore.movers``.
    """

    type: Literal["walker", "tractor"]
    path: tuple[tuple[float, float], ...]
    speed_m_s: float
    loop: bool = False
    start_s: float = 0.0

    def __post_init__(self) -> None:
        if self.type not in MOVER_TYPES:
            raise ValueError(f"mover type must be one of {', '.join(MOVER_TYPES)}")
        if len(self.path) < 2:
            raise ValueError("mover path needs at least 2 points")
        if not all(math.isfinite(c) and abs(c) <= 1e6 for p in self.path for c in p):
            raise ValueError("mover path points must be finite, within 1e6 m")
        if any(math.hypot(b[0] - a[0], b[1] - a[1]) <= 0.0 for a, b in zip(self.path, self.path[1:])):
            raise ValueError("mover path has two equal consecutive points")
        top = WALKER_MAX_SPEED_M_S if self.type == "walker" else TRACTOR_MAX_SPEED_M_S
        if not (math.isfinite(self.speed_m_s) and 0.0 < self.speed_m_s <= top):
            raise ValueError(f"mover speed_m_s must be in (0, {top:g}] m/s for a {self.type}")
        if not (math.isfinite(self.start_s) and self.start_s >= 0.0):
            raise ValueError("mover start_s must be >= 0 s")


#: Named sensor profiles (``sim.sensor_profile``). Their datasheet values
#: live with the simulator (``sitl.profiles``); the schema only knows the names.
SENSOR_PROFILES = ("icm42688p-bmm150-zedf9p",)

#: Keys of ``NoiseConfig`` that are 3-vectors.
_VECTOR_KEYS = ("gyro_bias_rad_s", "accel_bias_m_s2", "mag_hard_iron_gauss", "mag_thrust_gauss_per_n")


@dataclass(frozen=True)
class NoiseConfig:
    """Sensor errors: ``sim.noise``. Every key is optional.

    A key that is given replaces the value of the sensor profile
    (``sim.sensor_profile``); a key given nowhere takes the no-profile
    default, the paper's model (Section 3.4): white noise of variance 5e-4
    on the unit-vector measurements and on Omega, exact position and
    velocity in every sensor frame, no bias. Independent error sources add
    (variances add). Units are in the names; body vectors are FLU.

    Attributes
    ----------
    vector_variance : float
        Per-component variance of white noise on the accelerometer and
        magnetometer *directions* (-): the raw vectors get a standard
        deviation ``sqrt(vector_variance) * |vector|``. Default 5e-4 (paper);
        0 with a profile.
    gyro_variance : float
        White gyro noise variance per sample ((rad/s)^2). Default 5e-4; 0
        with a profile.
    gyro_noise_density_rad_s_rthz, accel_noise_density_m_s2_rthz : float
        White-noise densities (rad/s/sqrt(Hz), m/s^2/sqrt(Hz)); per-sample
        std = density * sqrt(sensor rate). Default 0.
    gyro_bias_rad_s, accel_bias_m_s2 : (3,)
        Constant biases (body FLU). Default 0.
    gyro_bias_turn_on_std_rad_s, accel_bias_turn_on_std_m_s2 : float
        Std of a turn-on bias drawn once per run and axis (seeded). Default 0.
    gyro_bias_walk_rad_s_rts, accel_bias_walk_m_s2_rts : float
        Bias random walk (rad/s/sqrt(s), m/s^2/sqrt(s)): the bias moves by a
        N(0, walk^2 dt) step every sample of the vehicle clock. Default 0.
    mag_noise_std_gauss : float
        Absolute white magnetometer noise per sample and axis (gauss). Default 0.
    mag_hard_iron_gauss : (3,)
        Constant field of the airframe added to the magnetometer (body FLU, gauss).
    mag_thrust_gauss_per_n : (3,)
        Field of the motor currents per newton of total rotor thrust (body
        FLU, gauss/N).
    position_std_m : float
        White position noise per sample, x and y (and z unless
        ``position_z_std_m`` is given) (m). Default 0.
    position_z_std_m : float
        White vertical position noise (m). Default: ``position_std_m``.
    velocity_std_m_s : float
        White velocity noise per sample and axis (m/s). Default 0.
    gnss_rate_hz : float
        Rate of the position/velocity (GNSS) samples (Hz, > 0). Default:
        every sensor frame.
    gnss_latency_s : float
        Delay from a GNSS sample's measurement to its delivery (s, in
        [0, 1)). Default 0.
    range_std_m : float
        Rangefinder white noise (m). Default 0.01.
    range_dropout_probability : float
        Probability that a due rangefinder reading is lost (no DISTANCE_SENSOR
        sent), each reading independently, in [0, 1]. Default 0.
    """

    vector_variance: float | None = None
    gyro_variance: float | None = None
    gyro_noise_density_rad_s_rthz: float | None = None
    accel_noise_density_m_s2_rthz: float | None = None
    gyro_bias_rad_s: tuple[float, float, float] | None = None
    accel_bias_m_s2: tuple[float, float, float] | None = None
    gyro_bias_turn_on_std_rad_s: float | None = None
    accel_bias_turn_on_std_m_s2: float | None = None
    gyro_bias_walk_rad_s_rts: float | None = None
    accel_bias_walk_m_s2_rts: float | None = None
    mag_noise_std_gauss: float | None = None
    mag_hard_iron_gauss: tuple[float, float, float] | None = None
    mag_thrust_gauss_per_n: tuple[float, float, float] | None = None
    position_std_m: float | None = None
    position_z_std_m: float | None = None
    velocity_std_m_s: float | None = None
    gnss_rate_hz: float | None = None
    gnss_latency_s: float | None = None
    range_std_m: float | None = None
    range_dropout_probability: float | None = None

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None:
                continue
            vals = v if f.name in _VECTOR_KEYS else (v,)
            if not all(math.isfinite(x) for x in vals):
                raise ValueError(f"sim.noise.{f.name} must be finite")
            if f.name not in _VECTOR_KEYS and v < 0:
                raise ValueError(f"sim.noise.{f.name} must be >= 0")
        if self.gnss_rate_hz is not None and not self.gnss_rate_hz > 0:
            raise ValueError("sim.noise.gnss_rate_hz must be > 0")
        if self.gnss_latency_s is not None and not self.gnss_latency_s < 1.0:
            raise ValueError("sim.noise.gnss_latency_s must be in [0, 1) s")
        if self.vector_variance is not None and self.vector_variance >= 1.0:
            raise ValueError("sim.noise.vector_variance must be < 1 (a variance on unit vectors)")


# MAV_SENSOR_ORIENTATION values a body-fixed rangefinder may use (pymavlink
# common dialect): NONE (forward) 0, YAW_45..YAW_315 1..7, PITCH_90 (up) 24,
# PITCH_270 (down) 25, CUSTOM 100 (the mounting rotation is given).
SENSOR_ROTATION_CUSTOM = 100
RANGEFINDER_ORIENTATIONS = (0, 1, 2, 3, 4, 5, 6, 7, 24, 25, SENSOR_ROTATION_CUSTOM)


@dataclass(frozen=True)
class RangefinderConfig:
    """A body-fixed rangefinder (one DISTANCE_SENSOR id).

    ``orientation`` is a MAV_SENSOR_ORIENTATION: 0 forward, 2 right (yaw 90,
    FRD convention, as PX4), 4 back, 6 left, 25 down (pitch 270), 24 up
    (pitch 90), odd values the diagonals; 100 (MAV_SENSOR_ROTATION_CUSTOM):
    the mounting rotation is given by exactly one of

    - ``rotation_flu_deg``: [roll, pitch, yaw] (deg), Z-Y-X Euler angles about
      the body **FLU** axes (x forward, y left, z up; right-handed), taking
      the sensor frame (beam along its x, horizontal field of view across its
      y, vertical across its z) to the body: yaw +90 looks left, pitch -30
      looks forward and 30 deg up, pitch +30 forward and 30 deg down;
    - ``quaternion_flu_wxyz``: the same rotation as a quaternion [w, x, y, z]
      (sensor frame -> body FLU; normalised when used).

    (On the wire MAVLink gives the CUSTOM quaternion in body FRD; the SITL's
    codec converts.) ``position_flu_m``: where the sensor sits, body FLU (m)
    from the centre of mass; rays start there. Fields of view are full
    angles (deg).
    """

    id: int
    orientation: int = 0
    min_m: float = 0.1
    max_m: float = 10.0
    hfov_deg: float = 5.0
    vfov_deg: float = 5.0
    rate_hz: float = 25.0
    position_flu_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation_flu_deg: tuple[float, float, float] | None = None
    quaternion_flu_wxyz: tuple[float, float, float, float] | None = None

    def __post_init__(self) -> None:
        if not 0 <= self.id <= 255:
            raise ValueError("rangefinder id must be in [0, 255]")
        if self.orientation not in RANGEFINDER_ORIENTATIONS:
            raise ValueError(f"rangefinder orientation must be one of {RANGEFINDER_ORIENTATIONS}")
        if not 0 <= self.min_m < self.max_m:
            raise ValueError("rangefinder needs 0 <= min_m < max_m")
        if self.max_m > 655.0:
            raise ValueError("rangefinder max_m must be <= 655 m (DISTANCE_SENSOR carries uint16 cm)")
        if not (0 <= self.hfov_deg < 180 and 0 <= self.vfov_deg < 180):
            raise ValueError("rangefinder fields of view must be in [0, 180) deg")
        if self.rate_hz <= 0:
            raise ValueError("rangefinder rate_hz must be > 0")
        if not all(math.isfinite(x) and abs(x) <= 10.0 for x in self.position_flu_m):
            raise ValueError("rangefinder position_flu_m must be finite, within 10 m of the centre")
        given = (self.rotation_flu_deg is not None) + (self.quaternion_flu_wxyz is not None)
        if self.orientation == SENSOR_ROTATION_CUSTOM and given != 1:
            raise ValueError("rangefinder orientation 100 (custom) needs exactly one of "
                             "rotation_flu_deg or quaternion_flu_wxyz")
        if self.orientation != SENSOR_ROTATION_CUSTOM and given:
            raise ValueError("rangefinder rotation_flu_deg/quaternion_flu_wxyz need orientation 100 (custom)")
        if self.quaternion_flu_wxyz is not None and not math.hypot(*self.quaternion_flu_wxyz) > 1e-6:
            raise ValueError("rangefinder quaternion_flu_wxyz must not be zero")


#: The default suite (a mission that lists no ``sim.rangefinders``): a closed
#: level ring of ``DEFAULT_RING_BEAMS`` beams, ``DEFAULT_RING_HFOV_DEG`` wide
#: (the ring overlaps by 1.5 deg) and ``DEFAULT_RING_VFOV_DEG`` tall, one beam
#: looking down, and a closed low ring like the level one pitched
#: ``DEFAULT_LOW_PITCH_DEG`` down. The pointing law turns body y toward the
#: pointing target, so the direction of travel can lie anywhere round the
#: body; a ring sees it whatever the heading (``companion.replan.coverage_check``,
#: docs/replan.md).
#: +-5 deg vertically and 6 m of range for the level ring: from 1.5 m over
#: flat ground the lower edge meets it beyond the range even with the vehicle
#: pitched 8 deg, and a beam whose edge runs nearly along a corridor sees the
#: row face only where it is at least asin(1 / 6) = 10 deg off it (nearer
#: grazing returns, placed with a slightly stale attitude over a lossy link,
#: read as phantom obstacles in the companion); 6 m still covers stopping from
#: the 3 m/s transit speed (``coverage_check``: 3.03 m/s allowed).
#: The low ring: obstacles stand on the ground, and one lower than the
#: vehicle's centre still enters its clearance sphere (0.942 m: 0.5 m clearance
#: + the 0.442 m airframe). The level ring never sees a top 0.6-0.9 m below the
#: centre within its range, and saw a 1.5 m post on a descending slope only
#: 1.3 m away (fresh-seed flight 7 of seed 20261128: 0.13 m of true
#: clearance; ``intruder_cover``). From -4 to -14 deg, the deepest such top
#: (0.942 m down) is in view from 0.942 / tan 14 = 3.8 m, and over flat ground
#: from the 1.5 m flight height the nearest ground in view (1.5 / sin 14 =
#: 6.2 m) is out of range: level flight gets no ground returns, and the 3 m/s
#: transit stays covered. A separate ring, not the level one pitched down: the
#: heading estimate from the rows (``companion.replan.heading_bias``) reads the
#: beams not pitched down below their own field, and a ring pitched down voted for a wrong heading
#: on the sloped field with the realistic profile.
DEFAULT_RING_BEAMS = 16
DEFAULT_RING_HFOV_DEG = 24.0
DEFAULT_RING_VFOV_DEG = 10.0
DEFAULT_RING_MAX_M = 6.0
DEFAULT_LOW_PITCH_DEG = 9.0
#: The down array: a multizone time-of-flight sensor looking down (as the 4x4 /
#: 8x8-zone ToF modules of small vehicles), modelled as a 3 x 3 grid of zones,
#: each its own DISTANCE_SENSOR id. Zone (i, j), i, j in {-1, 0, 1}, looks along
#: (i t, j t, -1) in body FLU, t = ``DEFAULT_DOWN_ZONE_TAN``, with a square field
#: of ``DEFAULT_DOWN_ZONE_FOV_DEG``. Together they see every direction within
#: ``DEFAULT_DOWN_CONE_DEG`` of straight down (``tests/test_descent_sight.py``
#: checks it on a dense grid of directions). Why: the rings look 14 deg down
#: at most and the single down beam 2.5 deg off the vertical, so a descent came
#: down unseen beside a box under the vehicle (0.158 m of true clearance on
#: obstacles-under flight 10). Whatever lies within the clearance sphere's
#: footprint below (radius r = R + c, the 0.942 m of the paper's vehicle) is in
#: view from a depth of r / tan 45 deg = r, from the array's 4 m range down.
DEFAULT_DOWN_ZONES = 3
DEFAULT_DOWN_ZONE_TAN = math.tan(math.radians(30.0))
DEFAULT_DOWN_ZONE_FOV_DEG = 36.0
DEFAULT_DOWN_CONE_DEG = 45.0
DEFAULT_DOWN_MAX_M = 4.0
DEFAULT_DOWN_RATE_HZ = 10.0


def default_rangefinders() -> tuple[RangefinderConfig, ...]:
    """The default suite: ids 0..15 the level ring (id k looks 22.5 k deg left of
    forward, ``MAV_SENSOR_ROTATION_CUSTOM``), id 16 down (20 m), ids 17..32 the
    low ring (id 17 + k looks 22.5 k deg left of forward and 9 deg down), ids
    33..41 the down array (zone (i, j) is id 37 + 3 i + j)."""
    step = 360.0 / DEFAULT_RING_BEAMS

    def ring(first: int, pitch_deg: float):
        return tuple(RangefinderConfig(id=first + k, orientation=SENSOR_ROTATION_CUSTOM,
                                       rotation_flu_deg=(0.0, pitch_deg, step * k), hfov_deg=DEFAULT_RING_HFOV_DEG,
                                       vfov_deg=DEFAULT_RING_VFOV_DEG, rate_hz=20.0, max_m=DEFAULT_RING_MAX_M)
                     for k in range(DEFAULT_RING_BEAMS))

    def down_array(first: int):
        out = []
        half = DEFAULT_DOWN_ZONES // 2
        for i in range(-half, half + 1):
            for j in range(-half, half + 1):
                dx, dy = i * DEFAULT_DOWN_ZONE_TAN, j * DEFAULT_DOWN_ZONE_TAN
                yaw = math.degrees(math.atan2(dy, dx))          # 0 for the nadir zone
                pitch = math.degrees(math.atan2(1.0, math.hypot(dx, dy)))
                out.append(RangefinderConfig(id=first + len(out), orientation=SENSOR_ROTATION_CUSTOM,
                                             rotation_flu_deg=(0.0, pitch, yaw), hfov_deg=DEFAULT_DOWN_ZONE_FOV_DEG,
                                             vfov_deg=DEFAULT_DOWN_ZONE_FOV_DEG, rate_hz=DEFAULT_DOWN_RATE_HZ,
                                             max_m=DEFAULT_DOWN_MAX_M))
        return tuple(out)

    down = RangefinderConfig(id=DEFAULT_RING_BEAMS, orientation=25, max_m=20.0)
    return (ring(0, 0.0) + (down,) + ring(DEFAULT_RING_BEAMS + 1, DEFAULT_LOW_PITCH_DEG)
            + down_array(2 * DEFAULT_RING_BEAMS + 1))


@dataclass(frozen=True)
class WindConfig:
    """Wind (ENU, m/s) acting through a linear drag ``F = -drag (v - w)``.

    Gusts are a first-order Gauss-Markov process per axis (stationary std
    ``gust_std_m_s``, correlation time ``gust_time_constant_s``), the
    simplest Dryden-like model. ``drag_n_s_m`` = 0 keeps the paper's
    eq. (20) (no aerodynamic force), so wind then has no effect.
    """

    mean_enu_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gust_std_m_s: float = 0.0
    gust_time_constant_s: float = 2.0
    drag_n_s_m: float = 0.0

    def __post_init__(self) -> None:
        if self.gust_std_m_s < 0 or self.drag_n_s_m < 0:
            raise ValueError("wind.gust_std_m_s and wind.drag_n_s_m must be >= 0")
        if self.gust_time_constant_s <= 0:
            raise ValueError("wind.gust_time_constant_s must be > 0")


#: Propeller radius (m) assumed for the vehicle sphere when
#: ``sim.collision.vehicle_radius_m`` is not given: a 10-inch propeller.
DEFAULT_PROP_RADIUS_M = 0.127


@dataclass(frozen=True)
class CollisionConfig:
    """What counts as a crash in the SITL (issue 8).

    The vehicle is a sphere of ``vehicle_radius_m`` about its centre of mass
    (None: ``vehicle.arm_m`` + a 10-inch propeller, 0.315 + 0.127 = 0.442 m
    for the paper's vehicle). Touching an obstacle or a vine row (the OGM's
    occupied cells extruded to ``sim.canopy_height_m``) is a crash. A
    touchdown (the centre of mass reaching the terrain, where the landing gear
    is) is a crash when faster than ``touchdown_max_down_m_s`` downward or
    ``touchdown_max_horizontal_m_s`` sideways, or, when the vehicle was not
    landing (see ``sitl.collision``), faster than ``touchdown_unplanned_max_m_s``.
    ``enabled: false`` turns all of it off (the SITL then lets the vehicle
    pass through obstacles, as before issue 8).
    """

    enabled: bool = True
    vehicle_radius_m: float | None = None
    touchdown_max_down_m_s: float = 1.0
    touchdown_max_horizontal_m_s: float = 0.5
    touchdown_unplanned_max_m_s: float = 0.1

    def __post_init__(self) -> None:
        if self.vehicle_radius_m is not None and not 0 < self.vehicle_radius_m <= 10.0:
            raise ValueError("sim.collision.vehicle_radius_m must be in (0, 10] m")
        for name in ("touchdown_max_down_m_s", "touchdown_max_horizontal_m_s", "touchdown_unplanned_max_m_s"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"sim.collision.{name} must be >= 0")


@dataclass(frozen=True)
class SimConfig:
    """Simulation-only settings of a mission.

    ``rangefinders`` None: the default suite (``default_rangefinders``: a closed ring of 16 and one down);
    an empty list: none. ``canopy_height_m``: the OGM's occupied cells are
    extruded from the DEM to this height for the rangefinders.
    ``magnetic_field_enu_gauss``: Earth field (default about Bordeaux's).
    ``start_enu_m``: where the vehicle starts, landed, (x, y) on the map
    frame (m); z is the terrain there. None: the SITL picks the free OGM
    cell nearest to the centroid of the free space (it never plans).
    ``collision``: the crash rules (``CollisionConfig``).
    ``movers``: moving obstacles on scripted paths (``MoverConfig``).
    """

    obstacles: tuple[ObstacleConfig, ...] = ()
    movers: tuple[MoverConfig, ...] = ()
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    seed: int = 0
    rangefinders: tuple[RangefinderConfig, ...] | None = None
    canopy_height_m: float = 2.0
    wind: WindConfig = field(default_factory=WindConfig)
    magnetic_field_enu_gauss: tuple[float, float, float] = (0.0, 0.21, -0.42)
    start_enu_m: tuple[float, float] | None = None
    vector_sensors: Literal["physical", "paper"] = "physical"
    sensor_profile: Literal[SENSOR_PROFILES] | None = None
    onboard_state: Literal["estimate", "truth"] = "estimate"
    collision: CollisionConfig = field(default_factory=CollisionConfig)
    autopilot: Literal["px4", "ardupilot"] = "px4"

    def __post_init__(self) -> None:
        if self.sensor_profile is not None and self.sensor_profile not in SENSOR_PROFILES:
            raise ValueError(f"sim.sensor_profile must be one of {', '.join(SENSOR_PROFILES)}")
        if self.vector_sensors not in ("physical", "paper"):
            raise ValueError("sim.vector_sensors must be physical or paper")
        if self.onboard_state not in ("estimate", "truth"):
            raise ValueError("sim.onboard_state must be estimate or truth")
        if self.autopilot not in ("px4", "ardupilot"):
            raise ValueError("sim.autopilot must be px4 or ardupilot")
        m = self.magnetic_field_enu_gauss
        if not all(math.isfinite(x) for x in m) or not math.hypot(*m) > 0:
            raise ValueError("sim.magnetic_field_enu_gauss must be finite and non-zero")
        from .sim_ranges import check_sim_ranges   # physical ranges of every numeric key

        if self.canopy_height_m <= 0:
            raise ValueError("sim.canopy_height_m must be > 0")
        if self.start_enu_m is not None and not all(math.isfinite(x) for x in self.start_enu_m):
            raise ValueError("sim.start_enu_m must be finite")
        if self.rangefinders is not None:
            ids = [r.id for r in self.rangefinders]
            if len(set(ids)) != len(ids):
                raise ValueError("sim.rangefinders ids must be unique")
        check_sim_ranges(self)

    @property
    def rangefinders_or_default(self) -> tuple[RangefinderConfig, ...]:
        return default_rangefinders() if self.rangefinders is None else self.rangefinders


def vehicle_radius_m(sim: SimConfig, arm_m: float) -> float:
    """Radius (m) of the vehicle sphere: ``sim.collision.vehicle_radius_m``,
    else the arm length ``arm_m`` (``vehicle.arm_m``) plus ``DEFAULT_PROP_RADIUS_M``."""
    r = sim.collision.vehicle_radius_m
    return float(r) if r is not None else float(arm_m) + DEFAULT_PROP_RADIUS_M
