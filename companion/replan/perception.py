"""From a DISTANCE_SENSOR reading and the vehicle pose to evidence in ENU.

Geometry (all ENU world / FLU body, m)::

    origin = p + R_enu_flu @ offset_flu                 sensor position
    R_enu_sensor = R_enu_flu @ R_flu_sensor             sensor frame -> world
    axis = R_enu_sensor[:, 0]                            beam direction
    hit = origin + distance * axis                       (a return)

``R_flu_sensor`` comes decoded with the reading (``mavcore.codec``:
orientations 0..7, 24, 25 and MAV_SENSOR_ROTATION_CUSTOM's quaternion).
The return is placed on the beam axis, and a rangefinder reports the
nearest surface anywhere in its field of view, so the true point may be off
the axis by up to ``distance * tan(fov / 2)``: ``fan_hits`` are the four
edge midpoints of the field of view at the measured distance, and half-way
to them for a wide field (the replanner asks the known map about all of them
and, for a wide beam, remembers them all). The beam's
pyramid (its horizontal and vertical fields of view about its axis) is free
of obstacles up to the distance, or up to ``max_m`` for a reading with no
return. A reading below ``min_m`` (NaN without ``no_return``) is no
evidence.

The pose at the reading's time comes from ``PoseHistory``: position
interpolated linearly between the two poses around that time (or
extrapolated from the last two, at most ``MAX_EXTRAPOLATION_S``), attitude
from the nearer pose (one frame, 4 ms, apart: the rotation in between is
below 0.1 deg at the yaw rates flown).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

#: A reading newer than the last pose by more than this (s) waits for no pose: it is dropped.
MAX_EXTRAPOLATION_S = 0.05
#: Poses kept (s of history).
HISTORY_S = 0.5
#: ``propagated_pose`` carries a measurement at most this far (s) in time.
MAX_PROPAGATION_S = 0.25


def flat_rotation(R_enu_flu) -> tuple:
    """A rotation as a row-major 9-tuple of floats, from a (3, 3) array, three rows
    or a row-major 9-sequence."""
    if hasattr(R_enu_flu, "ravel"):
        R_enu_flu = R_enu_flu.ravel().tolist()
    elif len(R_enu_flu) == 3:
        R_enu_flu = [*R_enu_flu[0], *R_enu_flu[1], *R_enu_flu[2]]
    R = tuple(float(x) for x in R_enu_flu)
    if len(R) != 9:
        raise ValueError("R_enu_flu must have 9 elements")
    return R


def propagated_pose(dt_p: float, pos_enu_m, vel_enu_m_s, dt_R: float, R_enu_flu, rate_flu_rad_s):
    """The pose a little later (or earlier) than its measurements: position
    ``pos + vel * dt_p``, attitude ``R @ exp([rate]x * dt_R)`` (body rates, FLU
    rad/s; Rodrigues). Both intervals are clipped to +-``MAX_PROPAGATION_S``.

    Over a lossy link the last position and attitude messages may be several
    frames old when a reading is placed: at 12 deg/s of yaw an attitude 80 ms
    old turns a 5.7 m return 13 cm sideways (off a row's face: a phantom
    obstacle). ``R_enu_flu`` as ``flat_rotation`` takes it. Returns (position
    3-tuple, row-major 9-tuple R).
    """
    tp = min(max(float(dt_p), -MAX_PROPAGATION_S), MAX_PROPAGATION_S)
    p = (pos_enu_m[0] + vel_enu_m_s[0] * tp, pos_enu_m[1] + vel_enu_m_s[1] * tp,
         pos_enu_m[2] + vel_enu_m_s[2] * tp)
    R = flat_rotation(R_enu_flu)
    tr = min(max(float(dt_R), -MAX_PROPAGATION_S), MAX_PROPAGATION_S)
    return p, rotated(R, rate_flu_rad_s[0] * tr, rate_flu_rad_s[1] * tr, rate_flu_rad_s[2] * tr)


def rotated(R: tuple, wx: float, wy: float, wz: float) -> tuple:
    """``R @ exp([w]x)`` (Rodrigues) for the rotation vector w (rad, in R's own frame);
    ``R`` (row-major 9-tuple) itself when w is below 1e-12 rad or not finite."""
    th = math.sqrt(wx * wx + wy * wy + wz * wz)
    if not th > 1e-12 or not math.isfinite(th):
        return R
    kx, ky, kz = wx / th, wy / th, wz / th
    s, c = math.sin(th), math.cos(th)
    v = 1.0 - c
    # exp([k]x th) = I + s [k]x + (1 - c) [k]x^2
    E = (c + v * kx * kx, v * kx * ky - s * kz, v * kx * kz + s * ky,
         v * ky * kx + s * kz, c + v * ky * ky, v * ky * kz - s * kx,
         v * kz * kx - s * ky, v * kz * ky + s * kx, c + v * kz * kz)
    out = []
    for i in range(3):
        a, b, d = R[3 * i], R[3 * i + 1], R[3 * i + 2]
        out.extend((a * E[0] + b * E[3] + d * E[6], a * E[1] + b * E[4] + d * E[7], a * E[2] + b * E[5] + d * E[8]))
    return tuple(out)


@dataclass(frozen=True, slots=True)
class Pose:
    """Vehicle pose at ``t_s``: position ENU (m, 3-tuple), ``R_enu_flu`` row-major 9-tuple."""

    t_s: float
    p: tuple
    R: tuple


class PoseHistory:
    """The last ``HISTORY_S`` seconds of estimated poses (vehicle time), oldest first."""

    def __init__(self, history_s: float = HISTORY_S) -> None:
        self.history_s = float(history_s)
        self._poses: deque[Pose] = deque()
        self._last: Pose | None = None          # the last answer (one frame's readings share a time)

    def add(self, t_s: float, pos_enu_m, R_enu_flu) -> None:
        """Add a pose. One older than the last (datagrams reordered by the link)
        is inserted in time order; one older than the whole history (a restart)
        starts it again.

        ``R_enu_flu``: a (3, 3) array, three rows, or a row-major 9-sequence.
        """
        R = flat_rotation(R_enu_flu)
        pose = Pose(float(t_s), (float(pos_enu_m[0]), float(pos_enu_m[1]), float(pos_enu_m[2])), R)
        q = self._poses
        self._last = None
        if q and pose.t_s < q[-1].t_s:
            if pose.t_s < q[-1].t_s - self.history_s:
                q.clear()
            else:
                i = len(q) - 1
                while i > 0 and q[i - 1].t_s > pose.t_s:
                    i -= 1
                q.insert(i, pose)
                return
        q.append(pose)
        while q[0].t_s < pose.t_s - self.history_s:
            q.popleft()

    def __len__(self) -> int:
        return len(self._poses)

    def at(self, t_s: float) -> Pose | None:
        """Pose at ``t_s`` (module doc); None when ``t_s`` is outside the history
        (older than its first pose, or newer than the last by more than
        ``MAX_EXTRAPOLATION_S``)."""
        last = self._last
        if last is not None and last.t_s == t_s:
            return last
        q = self._poses
        if not q or t_s < q[0].t_s - 1e-9 or t_s > q[-1].t_s + MAX_EXTRAPOLATION_S:
            return None
        if len(q) == 1:
            return q[0]
        # newest first: readings are about the latest frame
        i = len(q) - 1
        while i > 1 and q[i - 1].t_s > t_s:
            i -= 1
        a, b = q[i - 1], q[i]
        span = b.t_s - a.t_s
        f = 1.0 if span <= 0.0 else (t_s - a.t_s) / span
        ap, bp = a.p, b.p
        p = (ap[0] + f * (bp[0] - ap[0]), ap[1] + f * (bp[1] - ap[1]), ap[2] + f * (bp[2] - ap[2]))
        self._last = Pose(float(t_s), p, a.R if f < 0.5 else b.R)
        return self._last


@dataclass(frozen=True, slots=True)
class BeamEvidence:
    """What one reading says (ENU, m).

    Attributes
    ----------
    origin : 3-tuple
        Sensor position.
    axis, h_axis, v_axis : 3-tuples
        The sensor frame in ENU: unit beam direction, and the directions in
        which the horizontal and the vertical fields of view open (sensor y
        and z).
    half_h_rad, half_v_rad : float
        Half the horizontal and vertical fields of view (0 when unset).
    free_m : float
        The beam (the pyramid of its fields of view) is free of obstacles
        from the origin up to this range.
    hit : 3-tuple or None
        The return on the axis at the measured distance; None without a return.
    distance_m : float
        The measured distance (NaN without a return).
    fan_hits : tuple of 3-tuples
        Where the return may also lie: the points at the measured distance
        along the four edge midpoints of the field of view, and half-way to
        them for a field wider than ``WIDE_FOV_RAD`` (empty without a return
        or without a field of view). The replanner asks the known map about
        ``hit`` and these (``KnownMap.explains``).
    """

    origin: tuple
    axis: tuple
    h_axis: tuple
    v_axis: tuple
    half_h_rad: float
    half_v_rad: float
    free_m: float
    hit: tuple | None
    distance_m: float
    fan_hits: tuple = ()

    @property
    def half_max_rad(self) -> float:
        """Half the larger field of view."""
        return max(self.half_h_rad, self.half_v_rad)


def _half(fov: float) -> float:
    return 0.5 * fov if math.isfinite(fov) and 0.0 <= fov < math.pi else 0.0


def beam_evidence(reading, pose: Pose, offset_flu_m=(0.0, 0.0, 0.0)) -> BeamEvidence | None:
    """Evidence of one reading at ``pose`` (module doc).

    Parameters
    ----------
    reading : mavcore.codec.Range
        Decoded DISTANCE_SENSOR (``R_flu_sensor``, ``distance_m``, ``no_return``,
        ``max_m``, ``hfov_rad``, ``vfov_rad``).
    pose : Pose
        Vehicle pose at the reading's time.
    offset_flu_m : 3 floats
        Sensor position relative to the centre of mass, body FLU (m).

    Returns
    -------
    BeamEvidence or None
        None when the reading carries no evidence: unsupported orientation,
        a distance below ``min_m``, or non-finite values.
    """
    S = reading.R_flu_sensor
    if S is None:
        return None
    d = reading.distance_m
    if math.isfinite(d):
        if not d > 0.0 or d < reading.min_m:
            return None                  # below the sensor's range: no evidence
        free = d
    elif reading.no_return and math.isfinite(reading.max_m):
        free = reading.max_m
    else:
        return None
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = pose.R
    ox, oy, oz = offset_flu_m
    px, py, pz = pose.p
    origin = (px + r00 * ox + r01 * oy + r02 * oz,
              py + r10 * ox + r11 * oy + r12 * oz,
              pz + r20 * ox + r21 * oy + r22 * oz)
    cols = []
    for c in range(3):                                    # the sensor's axes, body FLU -> ENU
        bx, by, bz = S[c], S[3 + c], S[6 + c]
        cols.append((r00 * bx + r01 * by + r02 * bz, r10 * bx + r11 * by + r12 * bz,
                     r20 * bx + r21 * by + r22 * bz))
    axis = cols[0]
    n = math.sqrt(axis[0] ** 2 + axis[1] ** 2 + axis[2] ** 2)
    if not (abs(n - 1.0) < 1e-6) or not math.isfinite(origin[0] + origin[1] + origin[2]):
        return None
    hit = None
    fan = ()
    if math.isfinite(d):
        hit = (origin[0] + d * axis[0], origin[1] + d * axis[1], origin[2] + d * axis[2])
        fan = tuple(_fan_points(pose.R, S, origin, d, reading.hfov_rad, reading.vfov_rad))
    return BeamEvidence(origin, axis, cols[1], cols[2], _half(reading.hfov_rad), _half(reading.vfov_rad),
                        float(free), hit, d, fan)


#: Step (rad) of the heading turns of the attitude allowance: at 5 m a 1 deg turn moves a
#: beam's edge 9 cm, less than the 0.1 m within which the known map places a row's face.
ALLOWANCE_STEP_RAD = math.radians(1.0)


def attitude_perturbations(R, tilt_rad: float, heading_rad: float, step_rad: float = ALLOWANCE_STEP_RAD):
    """Attitudes the estimate cannot tell from its own (the replanner's attitude allowance,
    docs/replan.md): ``R`` (row-major 9-tuple body FLU -> ENU) turned about the vertical
    by +-k step up to ``heading_rad`` (and +-heading_rad itself), and about the east and
    the north axes by +-tilt/2 and +-tilt. Row-major 9-tuples, nearest turns first."""
    out = []
    angles = []
    k = 1
    while k * step_rad < heading_rad - 1e-12:
        angles.append(k * step_rad)
        k += 1
    if heading_rad > 0.0:
        angles.append(heading_rad)
    tilts = (0.5 * tilt_rad, tilt_rad) if tilt_rad > 0.0 else ()
    turns = [(2, a) for a in angles] + [(k, a) for a in tilts for k in (0, 1)]
    turns.sort(key=lambda ka: ka[1])
    for k, a in turns:
        for sgn in (1.0, -1.0):
            # exp([a e_k]x) R = R exp([R^T a e_k]x): the world axis e_k in the body frame is row k of R
            b = sgn * a
            out.append(rotated(R, b * R[3 * k], b * R[3 * k + 1], b * R[3 * k + 2]))
    return out


#: A field of view wider than this (rad) is also sampled half-way to its edges.
WIDE_FOV_RAD = math.radians(10.0)


def _fan_points(R, S, origin, d: float, hfov: float, vfov: float):
    """Points at range ``d`` across the field of view (ENU): the edge midpoints,
    and half-way to them for a field wider than ``WIDE_FOV_RAD``."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
    for col, fov in ((1, hfov), (2, vfov)):
        if not (math.isfinite(fov) and 0.0 < fov < math.pi):
            continue
        half = 0.5 * fov
        angles = (half, -half, 0.5 * half, -0.5 * half) if fov > WIDE_FOV_RAD else (half, -half)
        for a in angles:
            # sensor-frame ray (1, tan a, 0) or (1, 0, tan a), to body FLU, then ENU
            t = math.tan(a)
            bx = S[0] + t * S[col]
            by = S[3] + t * S[3 + col]
            bz = S[6] + t * S[6 + col]
            ex = r00 * bx + r01 * by + r02 * bz
            ey = r10 * bx + r11 * by + r12 * bz
            ez = r20 * bx + r21 * by + r22 * bz
            k = d / math.sqrt(ex * ex + ey * ey + ez * ez)
            yield (origin[0] + k * ex, origin[1] + k * ey, origin[2] + k * ez)


def field_sine_range(ev: BeamEvidence) -> tuple[float, float]:
    """(lowest, highest) sine of elevation of the rays in the beam's field of view: the
    z of the unit ray, ``closing.still_plane``'s input.

    The field is the rectangular pyramid of ``_fan_points``: rays ``a + s h + t v``
    (axis, horizontal and vertical axes of the sensor, orthonormal, ENU) with
    ``|s| <= tan(half_h)``, ``|t| <= tan(half_v)``. The z of the unit ray,
    ``f = (a_z + s h_z + t v_z) / sqrt(1 + s^2 + t^2)``, is stationary inside the
    rectangle only where the ray is vertical (``f = -1``: straight down in view),
    and on the edge ``s = s0`` at ``t* = v_z (1 + s0^2) / (a_z + s0 h_z)`` (likewise
    for ``t = t0``), so its minimum is the least of the four corners, the edges'
    stationary points inside them and, when the nadir is in view, -1; the maximum is
    the minimum of the field mirrored in the horizontal plane, negated."""
    S, T = math.tan(ev.half_h_rad), math.tan(ev.half_v_rad)
    lo = _lowest_sine((ev.axis[2], ev.h_axis[2], ev.v_axis[2]), S, T)
    hi = -_lowest_sine((-ev.axis[2], -ev.h_axis[2], -ev.v_axis[2]), S, T)
    return lo, hi


def _lowest_sine(z: tuple, S: float, T: float) -> float:
    az, hz, vz = z

    def f(s: float, t: float) -> float:
        return (az + s * hz + t * vz) / math.sqrt(1.0 + s * s + t * t)

    best = min(f(s, t) for s in (S, -S) for t in (T, -T))
    # the edges s = +-S (stationary in t) and t = +-T (stationary in s)
    for fixed, free, fz, gz, s_fixed in ((S, T, hz, vz, True), (T, S, vz, hz, False)):
        for x0 in (fixed, -fixed):
            c = az + x0 * fz
            if c != 0.0:
                y = gz * (1.0 + x0 * x0) / c
                if -free <= y <= free:
                    best = min(best, f(x0, y) if s_fixed else f(y, x0))
    # the nadir (0, 0, -1) in the sensor frame: (-a_z, -h_z, -v_z), in view when ahead
    # and within both half-angles
    if -az > 0.0 and abs(hz) <= S * -az and abs(vz) <= T * -az:
        best = -1.0
    return best
