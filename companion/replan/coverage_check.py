"""Before flight: do the rangefinders see where the vehicle is going, far enough to stop?

Pure (arrays in, a named result out). Along the trajectory, sampled at
``SAMPLE_HZ``, with ENU world / FLU body:

- the body frame is the pointing law's (``companion.control.geometric``,
  eqs. 21-22) taken level: b3 = e_z, b2 = the horizontal part of
  s = (S_p - x_d)/|S_p - x_d| normalised, b1 = b2 x b3. The roll and pitch
  that acceleration adds (atan(a / g): 3 deg at 0.5 m/s^2) are left out:
  obstacles stand on the ground, and a beam tilted by that much still
  crosses them within its range;
- the direction of travel is horizontal, as in PX4's collision prevention:
  d = R^T v_h / |v_h| (body FLU, v_h the horizontal part of v; climbs and
  descents along a slope do not take it out of a level beam); the stopping
  distance takes the whole speed |v|;
- a beam (one rangefinder: mounting rotation sensor -> FLU, full fields of
  view h and v, ``max_m``, reading period) sees d when, in the sensor frame
  (beam along x), ``d_x > 0``, ``|d_y| <= tan(h/2) d_x`` and
  ``|d_z| <= tan(v/2) d_x``;
- stopping in front of what it sees needs (PX4's collision prevention,
  CP_DIST/CP_DELAY)::

      range >= v^2 / (2 a) + v tau + c

  with a the braking acceleration (``replan.accel_m_s2``), tau the sensing
  and control delay (one reading period, ``1 / rate_hz``, plus
  ``CONTROL_DELAY_S``) and c the clearance from the beam's origin to the
  obstacle when stopped (``replan.clearance_m`` plus the body radius:
  clearance is measured from the airframe surface). Solved for v, the speed
  a beam of range R allows is ``a (-tau + sqrt(tau^2 + 2 (R - c) / a))``
  (0 if R <= c); the allowed speed of a sample is the best over the beams
  that see its direction, 0 if none does (a direction without a sensor is
  blocked, as CP_GO_NO_DATA = 0).

A sample is covered when its planned speed is at most the allowed speed;
horizontal speeds below ``MIN_SPEED_M_S`` (hovering, turning on the spot,
climbing or descending on the spot) are not checked. Between two samples
the speed can exceed both ends': given the exact largest speed of each
interval between samples (``companion.trajectory.extrema``, from the
trajectory's polynomial pieces), an interval is covered when that speed is
at most the smaller allowed speed of its ends, and otherwise its two
samples are uncovered. Consecutive uncovered samples form a gap: "blind"
when no beam sees the direction at some sample of it, "short" when beams
see it but not far enough for the planned speed. ``time_scale`` is the
factor by which slowing the whole trajectory uniformly (t -> k t: speeds /
k, accelerations / k^2) covers every short gap: the largest ratio of the
(exact interval) speed to the allowed speed, so the slowed speed is under
the allowed one on every interval; a blind gap cannot be flown at any
speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Samples per second of the trajectory.
SAMPLE_HZ = 10.0
#: Speeds below this (m/s) are not checked (the vehicle is hovering or turning).
MIN_SPEED_M_S = 0.05
#: Control part of the delay (s): the companion's replanning step, the
#: MAVLink setpoint and the controller's response, on top of one reading period.
CONTROL_DELAY_S = 0.1
#: Samples at most (a day at SAMPLE_HZ is 864 000: bounded memory).
MAX_SAMPLES = 1_000_000
#: Samples whose terrain profile and low-obstacle speeds are computed at a time.
TERRAIN_CHUNK = 4096
#: Tolerance (on tangents) of the field-of-view test.
_FOV_EPS = 1e-9


@dataclass(frozen=True)
class Beam:
    """A rangefinder as the check sees it.

    Attributes
    ----------
    sensor_id : int
        DISTANCE_SENSOR id.
    rotation_flu : (3, 3) array
        Sensor frame (beam along x) -> body FLU.
    tan_half_h, tan_half_v : float
        Tangents of the half fields of view.
    max_m : float
        Range (m).
    period_s : float
        Time between readings (s).
    """

    sensor_id: int
    rotation_flu: np.ndarray
    tan_half_h: float
    tan_half_v: float
    max_m: float
    period_s: float


@dataclass(frozen=True)
class CoverageGap:
    """An interval of the plan where the direction of travel is not covered.

    ``kind``: "blind" (no beam sees the direction) or "short" (beams see it,
    not far enough to stop from the planned speed). ``p_enu_m``: the
    position where it starts (ENU m); speeds in m/s (the largest planned,
    the smallest allowed within the gap). ``low_obstacles``: the gap comes
    from obstacles lower than the vehicle's centre (``intruder_cover``).
    """

    t_start_s: float
    t_end_s: float
    p_enu_m: tuple[float, float, float]
    kind: str
    planned_speed_m_s: float
    allowed_speed_m_s: float
    low_obstacles: bool = False

    def to_dict(self) -> dict:
        return {"t_start_s": self.t_start_s, "t_end_s": self.t_end_s, "p_enu_m": list(self.p_enu_m),
                "kind": self.kind, "planned_speed_m_s": self.planned_speed_m_s,
                "allowed_speed_m_s": self.allowed_speed_m_s, "low_obstacles": self.low_obstacles}

    def describe(self) -> str:
        x, y, z = self.p_enu_m
        where = ("below the vehicle's centre along the direction of travel (obstacles lower than the "
                 "vehicle)" if self.low_obstacles else "along the direction of travel")
        what = (f"no rangefinder sees {where} in time" if self.kind == "blind" else
                f"the rangefinders {where} allow {self.allowed_speed_m_s:.2f} m/s, "
                f"the plan flies {self.planned_speed_m_s:.2f} m/s")
        return (f"sensor gap from t = {self.t_start_s:.1f} s to {self.t_end_s:.1f} s of the plan, "
                f"starting at ENU ({x:.2f}, {y:.2f}, {z:.2f}) m: {what}")


@dataclass(frozen=True)
class SensorCoverage:
    """Result of ``check_coverage``.

    Attributes
    ----------
    t_s, speed_m_s, allowed_speed_m_s : (n,) arrays
        Sample times (s), planned speeds and allowed speeds (m/s; inf where
        the speed is below ``MIN_SPEED_M_S``).
    sensor_id : (n,) int array
        The beam that allows the most speed at each sample (-1: none sees
        the direction, or not checked).
    gaps : tuple of CoverageGap
    time_scale : float
        Uniform slow-down (>= 1) that covers every short gap; inf with a
        blind gap.
    """

    t_s: np.ndarray
    speed_m_s: np.ndarray
    allowed_speed_m_s: np.ndarray
    sensor_id: np.ndarray
    gaps: tuple[CoverageGap, ...]
    time_scale: float

    @property
    def blind(self) -> bool:
        return any(g.kind == "blind" for g in self.gaps)


def allowed_speed(range_m, accel_m_s2: float, delay_s, clearance_m):
    """Largest v (m/s) with ``v^2 / (2 a) + v tau + c <= range`` (0 if range <= c);
    numpy-broadcast over ``range_m``, ``delay_s`` and ``clearance_m``."""
    r = np.asarray(range_m, dtype=float) - clearance_m
    tau = np.asarray(delay_s, dtype=float)
    a = float(accel_m_s2)
    v = a * (-tau + np.sqrt(tau * tau + 2.0 * np.maximum(r, 0.0) / a))
    return np.where(r > 0.0, v, 0.0)


def stopping_distance_m(speed_m_s, accel_m_s2: float, delay_s: float, clearance_m: float):
    """``v^2 / (2 a) + v tau + c`` (m): the range a beam needs at speed v."""
    v = np.asarray(speed_m_s, dtype=float)
    return v * v / (2.0 * accel_m_s2) + v * delay_s + clearance_m


def level_body_axes(p_enu_m: np.ndarray, target_enu_m) -> np.ndarray:
    """(n, 3, 3) body FLU -> ENU rotations of the pointing law, level (module docstring).

    Where the target is straight above or below (no horizontal direction),
    the previous sample's heading is kept (east at the first).
    """
    p = np.asarray(p_enu_m, dtype=float).reshape(-1, 3)
    s = np.asarray(target_enu_m, dtype=float).reshape(1, 3) - p
    s[:, 2] = 0.0
    n = np.hypot(s[:, 0], s[:, 1])
    ok = n > 1e-9
    b2 = np.zeros_like(s)
    b2[ok] = s[ok] / n[ok, None]
    last = np.array([0.0, 1.0, 0.0])
    for i in np.flatnonzero(~ok):     # rare: carry the heading over
        b2[i] = b2[i - 1] if i > 0 else last
    b3 = np.broadcast_to(np.array([0.0, 0.0, 1.0]), b2.shape)
    b1 = np.cross(b2, b3)
    return np.stack([b1, b2, b3], axis=2)


def check_coverage(t_s, p_enu_m, v_enu_m_s, target_enu_m, beams: tuple[Beam, ...], accel_m_s2: float,
                   clearance_m: float, interval_max_speed_m_s=None, terrain=None,
                   ground_band_m: float = 0.0) -> SensorCoverage:
    """Where the direction of travel is covered, and at what speed.

    Parameters
    ----------
    t_s : (n,) array
        Sample times (s), increasing.
    p_enu_m, v_enu_m_s : (n, 3) arrays
        Planned position (m) and velocity (m/s), ENU.
    target_enu_m : (3,) array
        Pointing target S_p (eq. 21).
    beams : tuple of Beam
    accel_m_s2 : float
        Braking acceleration (m/s^2), > 0.
    clearance_m : float
        Distance (m) from the beam's origin to the obstacle when stopped.
    interval_max_speed_m_s : (n - 1,) array, optional
        The largest speed (m/s) on each [t_i, t_{i+1}]
        (``companion.trajectory.extrema.max_speed_on_intervals``). Given,
        an interval is held to the smaller allowed speed of its two ends
        (the directions between two samples are those of the samples), so
        ``time_scale`` bounds the speed everywhere, not only at the samples.
    terrain : ``terrain_profile``'s ``(h, (s, drop))``, or ``f(i0, i1)`` giving it for samples i0:i1, optional
        The terrain under and ahead of each sample (taken ``TERRAIN_CHUNK`` samples at a
        time: a callable keeps a long plan's profile, n x 80 points, out of memory). Given, obstacles lower
        than the centre must be seen in time too
        (``companion.replan.intruder_cover``; ``clearance_m`` is then the
        clearance sphere's radius): a sample's allowed speed is the smaller
        of the two, and a gap they limit says "low obstacles".
    ground_band_m : float
        A return within this distance of the nearest ground in a beam's view
        is taken for the ground in flight (the known map's tolerance,
        ``replan.known_tolerance_m``): that band is hidden (``low_allowed_speed``).

    Returns
    -------
    SensorCoverage
    """
    t = np.asarray(t_s, dtype=float).reshape(-1)
    v = np.asarray(v_enu_m_s, dtype=float).reshape(-1, 3)
    p = np.asarray(p_enu_m, dtype=float).reshape(-1, 3)
    speed = np.linalg.norm(v, axis=1)
    vh = v.copy()
    vh[:, 2] = 0.0
    speed_h = np.linalg.norm(vh, axis=1)
    moving = speed_h >= MIN_SPEED_M_S
    R = level_body_axes(p, target_enu_m)                       # body -> ENU
    d = np.einsum("nji,nj->ni", R, vh) / np.maximum(speed_h, 1e-12)[:, None]   # R^T v_h / |v_h|
    allowed = np.zeros(t.shape)
    best = np.full(t.shape, -1, dtype=int)
    for beam in beams:
        ds = d @ beam.rotation_flu                              # sensor frame: R_s^T d
        x = ds[:, 0]
        seen = (x > 0.0) & (np.abs(ds[:, 1]) <= (beam.tan_half_h + _FOV_EPS) * x) \
            & (np.abs(ds[:, 2]) <= (beam.tan_half_v + _FOV_EPS) * x)
        vb = float(allowed_speed(beam.max_m, accel_m_s2, beam.period_s + CONTROL_DELAY_S, clearance_m))
        better = seen & (vb > allowed)
        allowed[better] = vb
        best[better] = beam.sensor_id
    low_limited = np.zeros(t.shape, dtype=bool)
    if terrain is not None:
        from .intruder_cover import low_allowed_speed

        if not callable(terrain):
            h_all, (s_all, drop_all) = terrain

            def terrain(i0: int, i1: int):
                return h_all[i0:i1], (s_all, drop_all[i0:i1])
        low = np.empty(t.shape)
        for k in range(0, t.size, TERRAIN_CHUNK):        # each sample on its own: bounded memory
            h_k, prof_k = terrain(k, k + TERRAIN_CHUNK)
            h_k = np.asarray(h_k, dtype=float).reshape(-1)
            low[k:k + TERRAIN_CHUNK] = low_allowed_speed(d[k:k + TERRAIN_CHUNK], h_k, beams, accel_m_s2, clearance_m,
                                                         CONTROL_DELAY_S, prof_k, ground_band_m)
        low_limited = moving & (low < allowed)
        allowed = np.minimum(allowed, low)
    allowed = np.where(moving, allowed, np.inf)
    uncovered = moving & (speed > allowed * (1.0 + 1e-9))
    peak = speed.copy()                          # the largest speed at or next to a sample
    ratio = np.where(uncovered, math.inf, 0.0)  # a blind sample: no speed is allowed
    ok = uncovered & (allowed > 0.0)
    ratio[ok] = speed[ok] / allowed[ok]
    if interval_max_speed_m_s is not None and t.size > 1:
        vmax = np.asarray(interval_max_speed_m_s, dtype=float).reshape(-1)
        a_int = np.minimum(allowed[:-1], allowed[1:])
        over = vmax > a_int * (1.0 + 1e-9)
        r_int = np.where(over, math.inf, 0.0)
        ok = over & (a_int > 0.0)
        r_int[ok] = vmax[ok] / a_int[ok]
        for side in (slice(None, -1), slice(1, None)):
            uncovered[side] |= over
            peak[side] = np.maximum(peak[side], np.where(over, vmax, 0.0))
            ratio[side] = np.maximum(ratio[side], r_int)
    gaps = []
    idx = np.flatnonzero(uncovered)
    if idx.size:
        splits = np.flatnonzero(np.diff(idx) > 1) + 1
        for run in np.split(idx, splits):
            i0, i1 = int(run[0]), int(run[-1])
            blind = bool(np.any(best[run] < 0) or np.any(allowed[run] <= 0.0))
            gaps.append(CoverageGap(float(t[i0]), float(t[i1]), tuple(float(c) for c in p[i0]),
                                    "blind" if blind else "short", float(peak[run].max()),
                                    float(np.min(np.where(np.isfinite(allowed[run]), allowed[run], np.inf))),
                                    bool(np.any(low_limited[run]))))
    if any(g.kind == "blind" for g in gaps):
        scale = math.inf
    elif gaps:
        scale = float(np.max(ratio))
    else:
        scale = 1.0
    return SensorCoverage(t, speed, allowed, best, tuple(gaps), max(1.0, scale))


def sample_times(t0: float, tf: float) -> np.ndarray:
    """Times (s) at ``SAMPLE_HZ`` from t0 to tf, both included, at most ``MAX_SAMPLES``."""
    n = int(min(MAX_SAMPLES, max(2, math.ceil((tf - t0) * SAMPLE_HZ) + 1)))
    return np.linspace(t0, tf, n)


# MAV_SENSOR_ORIENTATION -> Z-Y-X Euler angles (deg) of the mounting about the
# body FLU axes (the enum's yaw turns toward the right: negative about FLU z;
# PITCH_90 looks up, PITCH_270 down).
_ENUM_EULER_FLU_DEG = {**{k: (0.0, 0.0, -45.0 * k) for k in range(8)},
                       24: (0.0, -90.0, 0.0), 25: (0.0, 90.0, 0.0)}


def beam_from_config(cfg) -> Beam:
    """A ``Beam`` from a ``mavcore.mission.sim.RangefinderConfig``."""
    from mavcore import frames

    if cfg.orientation in _ENUM_EULER_FLU_DEG:
        R = frames.euler_zyx2rotmat(*np.radians(_ENUM_EULER_FLU_DEG[cfg.orientation]))
    elif cfg.quaternion_flu_wxyz is not None:
        R = frames.quat_wxyz2rotmat(cfg.quaternion_flu_wxyz)
    else:
        R = frames.euler_zyx2rotmat(*np.radians(cfg.rotation_flu_deg))
    return Beam(int(cfg.id), np.asarray(R, dtype=float), math.tan(math.radians(0.5 * cfg.hfov_deg)),
                math.tan(math.radians(0.5 * cfg.vfov_deg)), float(cfg.max_m), 1.0 / float(cfg.rate_hz))


def terrain_profile(p_enu_m, v_enu_m_s, dem, reach_m: float, step_m: float = 0.25):
    """The terrain ahead of each sample: ``(h, (s, drop))`` with ``h`` (n,) the centres'
    heights above the terrain under them, ``s`` (m,) the distances ahead (m) and
    ``drop`` (n, m) the centres' heights above the terrain that far along the
    horizontal velocity (-inf beyond the DEM: nothing to hit). Each sample on its own:
    ``check_coverage`` asks for ``TERRAIN_CHUNK`` of them at a time (bounded memory)."""
    p = np.asarray(p_enu_m, dtype=float).reshape(-1, 3)
    v = np.asarray(v_enu_m_s, dtype=float).reshape(-1, 3)
    vh = np.hypot(v[:, 0], v[:, 1])
    u = np.where(vh[:, None] > 1e-9, v[:, :2] / np.maximum(vh, 1e-12)[:, None], 0.0)
    s = np.arange(step_m, reach_m + 0.5 * step_m, step_m)
    x = p[:, 0:1] + s[None, :] * u[:, 0:1]
    y = p[:, 1:2] + s[None, :] * u[:, 1:2]
    under = p[:, 2] - dem.height_at(p[:, 0], p[:, 1])
    return under, (s, p[:, 2:3] - dem.height_or(x, y, np.inf))


def mission_coverage(mission, trajectory, body_radius_m: float, dem=None) -> SensorCoverage:
    """``check_coverage`` of a trajectory (``companion.trajectory.Trajectory``
    with its pointing target) with the mission's rangefinders
    (``sim.rangefinders``, else the default suite), braking at
    ``replan.accel_m_s2`` and stopping ``replan.clearance_m + body_radius_m``
    from what they see, obstacles lower than the centre included over the
    terrain of ``dem`` (the mission's, read here when not given)."""
    from mavcore.mission.sim import default_rangefinders
    from ..trajectory.extrema import max_speed_on_intervals

    sim = mission.sim
    cfgs = default_rangefinders() if sim is None else sim.rangefinders_or_default
    beams = tuple(beam_from_config(c) for c in cfgs)
    t = sample_times(float(trajectory.t0), float(trajectory.tf))
    d = trajectory.derivatives(t)                 # sample(t)'s p and v (the pointing is not needed)
    p, v = d[:, 0, :], d[:, 1, :]
    target = trajectory.target_enu_m if trajectory.target_enu_m is not None else p[0] + np.array([0.0, 1.0, 0.0])
    rp = mission.replan
    vmax = max_speed_on_intervals(trajectory, t, v)
    if dem is None:
        from mavcore.maps.field import load_mission_dem

        dem = load_mission_dem(mission)
    reach = max(b.max_m for b in beams)

    def terrain(i0: int, i1: int):
        return terrain_profile(p[i0:i1], v[i0:i1], dem, reach)

    return check_coverage(t, p, v, target, beams, rp.accel_m_s2, rp.clearance_m + body_radius_m, vmax, terrain,
                          rp.known_tolerance_m)
