"""Sensor models of the SITL: IMU, magnetometer, position/velocity and
rangefinders. Body frame FLU, world ENU; the MAVLink codec converts to FRD/NED.

The error figures come from ``sitl.profiles.resolve_sensor_model`` (the
mission's ``sim.noise`` over ``sim.sensor_profile`` over the paper's
defaults). Per sample, with R body FLU -> world ENU, a the true
acceleration (world), W the true body rate, m_E the Earth field (world),
g e3 = (0, 0, g), n_* independent standard normal 3-vectors:

``sim.vector_sensors: physical`` (default)

- accelerometer (specific force: +g along body z at rest, zero in free fall)::

      s   = R^T (a + g e3)
      a_m = s + b_a + sqrt(rel^2 |s|^2 + sa^2) n_a

  ``rel = sqrt(vector_variance)``: the paper's noise on the *direction*
  (variance 5e-4 per component of s/|s|); ``sa = accel density * sqrt(rate)``;
- magnetometer::

      m_m = R^T m_E + h + k_T T + sqrt(rel^2 |m_E|^2 + sm^2) n_m

  h the hard-iron field, k_T the motor-current field per newton of total
  rotor thrust T (both body FLU), ``sm = mag_noise_std_gauss``;

``sim.vector_sensors: paper`` (the paper's sensor model, Section 3.4: two
unfiltered unit vectors of known, constant inertial directions)

- accelerometer fields: ``g (R^T e3 + rel n_a)``: the direction of the
  gravity reaction, constant inertial direction +e3 (ENU up), as an ideal
  inclinometer gives it; NOT the specific force (it does not change with
  the acceleration). A consumer takes r1 = e3;
- magnetometer fields: ``|m_E| (R^T m_E/|m_E| + rel n_m)``; r2 = m_E/|m_E|;
- biases, densities and the magnetic disturbance do not apply to these two;

both modes

- gyroscope: ``W_m = W + b_W + sg n_W``, ``sg^2 = gyro_variance + density^2 * rate``;
- biases ``b = b_const + b_turn_on + b_walk``: the turn-on part is drawn
  once per run (std ``*_turn_on_std``), the walk moves by
  ``walk * sqrt(dt) * n`` after every sample (dt = 1 / sensor rate), so
  its variance grows as ``walk^2 t``. No draw is made for a zero std, so
  the no-profile default draws exactly as before profiles existed;
- position / velocity: ``sitl.gnss.GnssReceiver`` (white noise, rate and
  latency; exact and every frame by default, the paper's mocap-like case);
- rangefinders: the distance to the nearest surface inside the field of
  view (the pyramid of ``hfov_deg`` x ``vfov_deg`` about the beam), from the
  sensor's mounting position (``position_flu_m``, body FLU): obstacles and
  flat ground exactly over the whole field (``sitl.fov``), rows and uneven
  ground with a fan of rays (centre and the four edge midpoints of the
  field of view) cast into ``World``; plus white noise
  ``range_std_m``; ``None`` when nothing is within ``max_m``, clamped up to
  ``min_m`` below it. The mounting rotation (sensor frame: beam along x,
  horizontal field of view across y, vertical across z -> body FLU) comes
  from the MAV_SENSOR_ORIENTATION or, for CUSTOM (100), from the mission's
  ``rotation_flu_deg`` / ``quaternion_flu_wxyz``. With
  ``range_dropout_probability`` p > 0 each due reading is lost with
  probability p (one uniform draw per due reading; none when p = 0).

Every random draw comes from the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mavcore import frames
from mavcore.mission.sim import SENSOR_ROTATION_CUSTOM, RangefinderConfig, SimConfig

from .gnss import GnssReceiver
from .fov import Pyramid, nearest_in_view
from .profiles import SensorModel, resolve_sensor_model
from .world import World

# MAV_SENSOR_ORIENTATION -> Z-Y-X Euler angles (roll, pitch, yaw; deg) of the
# mounting about the body **FLU** axes. The enum's rotations are about FRD
# axes (YAW_90 turns forward toward the right, PITCH_270 points down, as PX4
# reads them); about FLU axes pitch and yaw change sign.
_DOWN, _UP = 25, 24
_ENUM_EULER_FLU_DEG = {**{k: (0.0, 0.0, -45.0 * k) for k in range(8)},
                       _UP: (0.0, -90.0, 0.0), _DOWN: (0.0, 90.0, 0.0)}


def _clean(x: float) -> float:
    return 0.0 if abs(x) < 1e-15 else x


def _rot9(R) -> tuple:
    return tuple(_clean(float(x)) for x in np.asarray(R, dtype=float).reshape(9))


def mount_rotation_flu(cfg: RangefinderConfig) -> tuple:
    """Rotation sensor frame -> body FLU (row-major 9-tuple) of a rangefinder.

    The sensor frame has the beam along x, the horizontal field of view
    across y and the vertical one across z. MAV_SENSOR_ORIENTATION values use
    the enum's angles; CUSTOM (100) the mission's ``rotation_flu_deg``
    (Z-Y-X Euler, FLU) or ``quaternion_flu_wxyz`` (normalised).
    """
    if cfg.orientation == SENSOR_ROTATION_CUSTOM:
        if cfg.quaternion_flu_wxyz is not None:
            return _rot9(frames.quat_wxyz2rotmat(cfg.quaternion_flu_wxyz))
        roll, pitch, yaw = (math.radians(a) for a in cfg.rotation_flu_deg)
    elif cfg.orientation in _ENUM_EULER_FLU_DEG:
        roll, pitch, yaw = (math.radians(a) for a in _ENUM_EULER_FLU_DEG[cfg.orientation])
    else:
        raise ValueError(f"unsupported rangefinder orientation {cfg.orientation}")
    return _rot9(frames.euler_zyx2rotmat(roll, pitch, yaw))


def orientation_direction_flu(orientation: int) -> tuple[float, float, float]:
    """Body FLU unit vector of a MAV_SENSOR_ORIENTATION (0..7, 24, 25)."""
    if orientation not in _ENUM_EULER_FLU_DEG:
        raise ValueError(f"unsupported rangefinder orientation {orientation}")
    R = mount_rotation_flu(RangefinderConfig(id=0, orientation=orientation))
    return (R[0], R[3], R[6])


def fan_directions_flu(cfg: RangefinderConfig) -> tuple[tuple[float, float, float], ...]:
    """Body FLU unit rays of a rangefinder: the axis, then the edge midpoints
    of its field of view (horizontal: across the sensor's y, vertical:
    across its z; a zero field of view adds no rays)."""
    R = mount_rotation_flu(cfg)
    th, tv = math.tan(0.5 * math.radians(cfg.hfov_deg)), math.tan(0.5 * math.radians(cfg.vfov_deg))
    local = [(1.0, 0.0, 0.0)]
    for sgn in (1.0, -1.0):
        if th > 0.0:
            local.append((1.0, sgn * th, 0.0))
    for sgn in (1.0, -1.0):
        if tv > 0.0:
            local.append((1.0, 0.0, sgn * tv))
    rays = []
    for a, b, c in local:
        n = math.sqrt(a * a + b * b + c * c)
        a, b, c = a / n, b / n, c / n
        rays.append(tuple(_clean(R[3 * i] * a + R[3 * i + 1] * b + R[3 * i + 2] * c) for i in range(3)))
    return tuple(rays)


@dataclass(frozen=True)
class RangeReading:
    """One DISTANCE_SENSOR reading.

    Attributes
    ----------
    sensor_id : int
    orientation : int
        MAV_SENSOR_ORIENTATION.
    distance_m : float or None
        Measured distance (m); None: no return within ``max_m``.
    min_m, max_m : float
        Range limits (m).
    hfov_rad, vfov_rad : float
        Full fields of view (rad).
    mount_rotation_flu : tuple (9,)
        Rotation sensor frame -> body FLU, row-major (``mount_rotation_flu``).
    noise_std_m : float
        Standard deviation of the range noise (m).
    """

    sensor_id: int
    orientation: int
    distance_m: float | None
    min_m: float
    max_m: float
    hfov_rad: float
    vfov_rad: float
    mount_rotation_flu: tuple = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    noise_std_m: float = 0.0


@dataclass(frozen=True)
class ImuSample:
    """Accelerometer (specific force, m/s^2), gyro (rad/s), magnetometer (gauss), body FLU (3,)."""

    accel_flu_m_s2: np.ndarray
    gyro_flu_rad_s: np.ndarray
    mag_flu_gauss: np.ndarray


class Rangefinder:
    """A body-fixed rangefinder with its schedule."""

    def __init__(self, cfg: RangefinderConfig, first_due_us: int) -> None:
        self.cfg = cfg
        self.mount_rotation_flu = mount_rotation_flu(cfg)
        self.rays = fan_directions_flu(cfg)
        self.position_flu_m = tuple(float(x) for x in cfg.position_flu_m)
        self._offset = any(self.position_flu_m)
        self.period_us = max(1, int(round(1e6 / cfg.rate_hz)))
        self.next_due_us = int(first_due_us)
        self.hfov_rad = math.radians(cfg.hfov_deg)
        self.vfov_rad = math.radians(cfg.vfov_deg)
        self._tan_h = math.tan(0.5 * self.hfov_rad)
        self._tan_v = math.tan(0.5 * self.vfov_rad)
        self._wide = self._tan_h > 0.0 or self._tan_v > 0.0

    def true_distance(self, world: World, p, R) -> float:
        """Distance (m, inf if none within max) from the sensor mounted on a
        body at p (3-tuple, ENU) with R (row-major 9-tuple, body FLU -> ENU)
        to the nearest surface in its field of view.

        The fan of rays (``fan_directions_flu``) samples everything (terrain,
        rows, obstacles); obstacles and flat ground are then solved exactly
        over the whole field of view (``sitl.fov``), and the ray toward the
        nearest obstacle point is cast through the whole world once more, so
        that a row or the ground in front of it is not seen through.
        """
        ox, oy, oz = p
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
        if self._offset:
            bx, by, bz = self.position_flu_m
            ox += r00 * bx + r01 * by + r02 * bz
            oy += r10 * bx + r11 * by + r12 * bz
            oz += r20 * bx + r21 * by + r22 * bz
        lim = self.cfg.max_m
        best = math.inf
        # one origin for the whole fan: its ground height and the obstacles within reach, once
        ground = world.terrain.height(ox, oy)
        near = world.near_obstacles(ox, oy, oz, lim)
        for bx, by, bz in self.rays:
            dx = r00 * bx + r01 * by + r02 * bz
            dy = r10 * bx + r11 * by + r12 * bz
            dz = r20 * bx + r21 * by + r22 * bz
            t = world.raycast(ox, oy, oz, dx, dy, dz, lim, ground, near)
            if t < best:
                best = t
                lim = t
        if not self._wide:
            return best
        return self._in_view(world, (ox, oy, oz), R, best, near)

    def _in_view(self, world: World, o, R, best: float, near=None) -> float:
        """``best`` lowered to the nearest obstacle point in the field of view. ``near``:
        the obstacles within the sensor's reach (``World.near_obstacles``; default all:
        the broad phase below drops the others anyway)."""
        m0, m1, m2, m3, m4, m5, m6, m7, m8 = self.mount_rotation_flu
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = R
        M = (r0 * m0 + r1 * m3 + r2 * m6, r0 * m1 + r1 * m4 + r2 * m7, r0 * m2 + r1 * m5 + r2 * m8,
             r3 * m0 + r4 * m3 + r5 * m6, r3 * m1 + r4 * m4 + r5 * m7, r3 * m2 + r4 * m5 + r5 * m8,
             r6 * m0 + r7 * m3 + r8 * m6, r6 * m1 + r7 * m4 + r8 * m7, r6 * m2 + r7 * m5 + r8 * m8)
        fov = Pyramid(o, M, self._tan_h, self._tan_v, self.cfg.max_m)
        # flat ground: nothing of it is nearer than the sensor's height above it
        if world.terrain.flat and o[2] - world.terrain.z < min(best, self.cfg.max_m):
            t = fov.ground_distance(world.terrain.z)
            if t < best:
                best = t
        ox, oy, oz = o
        edges = None
        for ob in (world.obstacles_now if near is None else near):
            # broad phase: the bounding sphere must reach into the field of view within range
            cx, cy, cz = ob.x - ox, ob.y - oy, ob.zc - oz
            if math.sqrt(cx * cx + cy * cy + cz * cz) - ob.bound_r >= min(best, self.cfg.max_m):
                continue
            if fov.distance_to(ob.x, ob.y, ob.zc) > ob.bound_r:
                continue
            # ... and no vertical plane through the sensor, tangent to the solid, may separate them
            span = ob.azimuth_span(ox, oy)
            if span is not None:
                if edges is None:
                    edges = fov.edges()
                if _separated(edges, span[0], span[1]):
                    continue
            t, u = nearest_in_view(fov, ob.project, ob.raycast, best)
            if t < best:
                if u is not None:     # a row or the ground in front of it hides it
                    t = min(t, world.raycast(ox, oy, oz, u[0], u[1], u[2], t))
                best = t
        return best


def _separated(edges, az: float, half: float) -> bool:
    """True if every edge direction of the field of view (ENU unit vectors)
    lies strictly beyond one of the two vertical planes at azimuths
    ``az +- half`` that enclose a solid: then the solid is out of view."""
    for side in (1.0, -1.0):
        a = az + side * half
        # normal of the plane, pointing away from the solid
        nx, ny = -side * math.sin(a), side * math.cos(a)
        if all(nx * e[0] + ny * e[1] > 1e-12 for e in edges):
            return True
    return False


class SensorSuite:
    """All sensors of the vehicle (pure: state in, readings out).

    Parameters
    ----------
    sim : SimConfig
        Noise, profile, vector mode, Earth field and rangefinder set.
    world : World
    rng : numpy.random.Generator
    sensor_hz : int
        Sensor frame rate (Hz): converts noise densities and bias walks to
        per-sample values.
    """

    def __init__(self, sim: SimConfig, world: World, rng: np.random.Generator, sensor_hz: int = 250) -> None:
        self.sim = sim
        self.world = world
        self.rng = rng
        md = self.model = resolve_sensor_model(sim, sensor_hz)
        self.mag_earth = np.array(sim.magnetic_field_enu_gauss, dtype=float)
        self._mag = tuple(float(x) for x in self.mag_earth)
        self._mag_norm = float(np.linalg.norm(self.mag_earth))
        self.paper = md.vector_sensors == "paper"
        self.acc_rel_std = md.accel_rel_std
        self.acc_abs_std = md.accel_std_m_s2
        self.mag_std = md.accel_rel_std * self._mag_norm      # relative part, gauss
        self.mag_abs_std = md.mag_std_gauss
        self.gyro_std = md.gyro_std_rad_s
        self._hard_iron = md.mag_hard_iron_gauss
        self._mag_thrust = md.mag_thrust_gauss_per_n
        # Biases: constant + turn-on draw (only when its std is non-zero).
        gb = list(md.gyro_bias_rad_s)
        ab = list(md.accel_bias_m_s2)
        if md.gyro_bias_turn_on_std_rad_s > 0:
            gb = [b + md.gyro_bias_turn_on_std_rad_s * n for b, n in zip(gb, rng.standard_normal(3).tolist())]
        if md.accel_bias_turn_on_std_m_s2 > 0:
            ab = [b + md.accel_bias_turn_on_std_m_s2 * n for b, n in zip(ab, rng.standard_normal(3).tolist())]
        self._gyro_bias = tuple(gb)
        self._accel_bias = tuple(ab)
        dt = 1.0 / sensor_hz
        self._gyro_walk = md.gyro_bias_walk_rad_s_rts * math.sqrt(dt)
        self._accel_walk = md.accel_bias_walk_m_s2_rts * math.sqrt(dt)
        self.gnss = GnssReceiver(md.gnss_period_us, md.gnss_latency_us, md.position_std_xy_m,
                                 md.position_std_z_m, md.velocity_std_m_s, rng)
        self.range_std = md.range_std_m
        self.range_dropout = md.range_dropout_probability
        cfgs = sim.rangefinders_or_default
        # Stagger the first readings over one period so the ray casting of
        # several sensors does not land on the same frame.
        self.rangefinders = tuple(
            Rangefinder(c, int(round(1e6 / c.rate_hz)) * k // max(1, len(cfgs))) for k, c in enumerate(cfgs))

    @property
    def gyro_bias_rad_s(self) -> np.ndarray:
        """(3,) current gyro bias (body FLU, rad/s): constant + turn-on + walk."""
        return np.array(self._gyro_bias)

    @property
    def accel_bias_m_s2(self) -> np.ndarray:
        """(3,) current accelerometer bias (body FLU, m/s^2)."""
        return np.array(self._accel_bias)

    def imu(self, R: np.ndarray, acc_enu_m_s2, omega_flu_rad_s, gravity_m_s2: float,
            thrust_n: float = 0.0) -> ImuSample:
        """IMU and magnetometer sample.

        Parameters
        ----------
        R : (3, 3) body FLU -> world ENU
        acc_enu_m_s2 : (3,) true acceleration (world)
        omega_flu_rad_s : (3,) true body rate
        gravity_m_s2 : g
        thrust_n : total rotor thrust (N), for the motor-current field
        """
        R9 = tuple(float(x) for x in np.asarray(R, dtype=float).reshape(9))
        return self.imu_floats(R9, tuple(float(x) for x in acc_enu_m_s2),
                               tuple(float(x) for x in omega_flu_rad_s), gravity_m_s2, thrust_n)

    def imu_floats(self, R, acc, w, gravity_m_s2: float, thrust_n: float = 0.0) -> ImuSample:
        """``imu`` on plain floats (R row-major 9-tuple, acc and w 3-tuples)."""
        a, g, m = self.imu_tuples(R, acc, w, gravity_m_s2, thrust_n)
        return ImuSample(np.array(a), np.array(g), np.array(m))

    def imu_tuples(self, R, acc, w, gravity_m_s2: float, thrust_n: float = 0.0):
        """``imu_floats`` as three float 3-tuples (accel, gyro, mag): the hot path."""
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
        mx, my, mz = self._mag
        bx = r00 * mx + r10 * my + r20 * mz          # R^T m_earth
        by = r01 * mx + r11 * my + r21 * mz
        bz = r02 * mx + r12 * my + r22 * mz
        n0, n1, n2, n3, n4, n5, n6, n7, n8 = self.rng.standard_normal(9).tolist()
        bg = self._gyro_bias
        kg = self.gyro_std
        gyro = (w[0] + bg[0] + kg * n3, w[1] + bg[1] + kg * n4, w[2] + bg[2] + kg * n5)
        if self.paper:
            g, k = gravity_m_s2, self.acc_rel_std
            gm = self._mag_norm
            accel = (g * (r20 + k * n0), g * (r21 + k * n1), g * (r22 + k * n2))   # g (R^T e3 + n)
            mag = (bx + gm * k * n6, by + gm * k * n7, bz + gm * k * n8)          # |m| (R^T m_hat + n)
        else:
            ax, ay, az = acc[0], acc[1], acc[2] + gravity_m_s2
            sx = r00 * ax + r10 * ay + r20 * az          # R^T (a + g e3)
            sy = r01 * ax + r11 * ay + r21 * az
            sz = r02 * ax + r12 * ay + r22 * az
            ka = self.acc_rel_std * math.sqrt(sx * sx + sy * sy + sz * sz)
            if self.acc_abs_std > 0:
                ka = math.sqrt(ka * ka + self.acc_abs_std ** 2)
            km = self.mag_std
            if self.mag_abs_std > 0:
                km = math.sqrt(km * km + self.mag_abs_std ** 2)
            ba = self._accel_bias
            accel = (sx + ba[0] + ka * n0, sy + ba[1] + ka * n1, sz + ba[2] + ka * n2)
            hx, hy, hz = self._hard_iron
            tx, ty, tz = self._mag_thrust
            T = thrust_n
            mag = (bx + hx + tx * T + km * n6, by + hy + ty * T + km * n7, bz + hz + tz * T + km * n8)
        if self._gyro_walk > 0:
            k = self._gyro_walk
            d0, d1, d2 = self.rng.standard_normal(3).tolist()
            self._gyro_bias = (bg[0] + k * d0, bg[1] + k * d1, bg[2] + k * d2)
        if self._accel_walk > 0:
            k = self._accel_walk
            ba = self._accel_bias
            d0, d1, d2 = self.rng.standard_normal(3).tolist()
            self._accel_bias = (ba[0] + k * d0, ba[1] + k * d1, ba[2] + k * d2)
        return accel, gyro, mag

    def position(self, pos_enu_m, vel_enu_m_s) -> tuple[np.ndarray, np.ndarray]:
        """One noisy (position ENU m, velocity ENU m/s) sample (3,) each, now
        (no schedule or latency: ``gnss.step`` applies those)."""
        s = self.gnss.measure(0, tuple(float(x) for x in pos_enu_m), tuple(float(x) for x in vel_enu_m_s))
        return np.array(s.pos_enu_m), np.array(s.vel_enu_m_s)

    def ranges(self, time_us: int, p, R) -> tuple[RangeReading, ...]:
        """Readings of the rangefinders due at ``time_us`` (p 3-tuple, R row-major 9-tuple)."""
        out = []
        for rf in self.rangefinders:
            if time_us < rf.next_due_us:
                continue
            while rf.next_due_us <= time_us:
                rf.next_due_us += rf.period_us
            # a dropout: the reading is lost (one draw per due reading, only when enabled)
            if self.range_dropout > 0 and self.rng.random() < self.range_dropout:
                continue
            out.append(self.range_reading(rf, p, R))
        return tuple(out)

    def range_reading(self, rf: Rangefinder, p, R) -> RangeReading:
        cfg = rf.cfg
        d = rf.true_distance(self.world, p, R)
        if self.range_std > 0:
            d = d + self.range_std * float(self.rng.standard_normal())
        if not d <= cfg.max_m:
            dist = None
        else:
            dist = max(d, cfg.min_m)
        return RangeReading(cfg.id, cfg.orientation, dist, cfg.min_m, cfg.max_m, rf.hfov_rad, rf.vfov_rad,
                            rf.mount_rotation_flu, float(self.range_std))
