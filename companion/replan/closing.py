"""How fast unknown obstacles come toward the vehicle, from successive ranges.

The clearance governor (``companion.replan.replanner``) limits the vehicle's
approach speed to every remembered obstacle point so that it can stop before
the clearance: ``v <= v_stop(room)`` with ``v^2 / (2 a_b) + v t_lag = room``.
That holds for a still obstacle. A worker or a tractor walking toward the
vehicle closes the gap at ``v + w`` (w its own approach speed), so the rule
here bounds the *closing* speed instead: ``v + w <= v_stop(room)``, i.e. the
vehicle's allowed approach is ``v_stop(room) - w``; below zero the vehicle
backs away at up to w, so it never closes on a mover faster than it can stop.

w comes from the rangefinders: a DISTANCE_SENSOR hit placed in the world
(``companion.replan.perception``) moves only with the obstacle (the
vehicle's own motion is already taken out), so for one sensor the approach
speed is ``-(h(t) - h(t0)) . u / (t - t0)`` (u the beam axis, from the
vehicle outward; h(t0) the nearest earlier hit within ``MATCH_M``, among
those ``BASELINE_S`` to twice that old), taken over at least ``BASELINE_S`` (a 1 cm range noise
then reads as 0.03 m/s). Only hits within ``MATCH_M`` of each other are
compared (the same object), and only unknown returns (not a row) are fed, and
those of an obstacle added in flight (a re-route's; ``Replanner._place``, where
they stay explained): the vehicle saw it still, it may walk.
The largest w counts while approaches keep being measured (each at most
``HOLD_S`` after the last); speeds below
``MIN_M_S`` (noise, a beam sliding over a still post as the vehicle yaws)
count as 0, and so does a return that moved mostly across the beam (less
than ``ALIGN_MIN`` of its displacement along the axis): a beam sweeping over
a still surface as the vehicle flies past slides its return across, at up to
the vehicle's speed.

While the vehicle is still (``still=True``: its reference at rest, its measured
speed below ``replanner.STILL_M_S``) and the beam that saw both returns did not
turn (``swept``: the point at the old range along it moved less than
``MIN_M_S`` over the baseline), the beam does not sweep, so a return that
moves at all is something moving: then the whole level displacement counts, in
any direction (a worker crossing the corridor moves its return across the beam,
which the alignment rule would drop as a sweep; a crossing walker read as still
walked into a vehicle that flew on toward it, campaign obstacles-wide scenario 7).
This is how the replanner's *look* tells a still obstacle from a mover
(``replanner``: with ``give_way`` the vehicle stops at an unknown obstacle and
watches before it avoids it). A vehicle at rest still yaws (the pointing law
turns it toward its target): a return on a turning beam slides across the axis
with the beam (7 deg/s moved returns 1.1 m in 1.75 s, read as 0.3-1.0 m/s:
obstacles-wide seed 20261160, flight 27), so a pair from a beam that turned is
judged as in flight, by its motion along the axis.

A return that keeps its place relative to the sensor while the vehicle moves
(its level displacement less the sensor's below ``MIN_M_S`` over the baseline)
is not counted either: that is a beam riding over a surface with the vehicle.
A beam tilted down onto a canopy or an obstacle's top, looking back while the
vehicle flies on, returns from points that follow the vehicle along the beam:
read as a world speed, a mover chasing it at its own speed. The give-way cap
(``give_way_speed_m_s``) would then let the vehicle fly faster than its cruise
to outpace it, which makes the "mover" faster still. A true chaser at exactly
the vehicle's speed is not closing; it is counted as soon as it gains on the
vehicle by ``MIN_M_S``. But a mover already measured coming is not let go
because the vehicle backing away from it now keeps pace with it: a return that
rides with the vehicle where that mover was (``following``: within ``MATCH_M``
and the return's spread of ``mover_at``, while its approach counts) holds the
approach it had, without raising it. A worker walking after a vehicle that
backed away at 1.2-1.7 m/s, 1.1 m behind it, rode with it for a second; the
approach lapsed (``HOLD_S``), the give-way braked, and the worker walked into
it (fresh seed 20261224 along, flight 7). A riding return with no approach
measured before it starts nothing.

Movers are read by beams within ``MOVER_TILT_MAX_DEG`` (60 deg) of level; one tilted more
than ``PLANE_TILT_DEG`` (15 deg) only with its ``field`` given, only against its own earlier
returns, and only by motion along it, even at rest. A beam tilted down onto an obstacle's
top slides its return along that top as the vehicle climbs, descends or pitches: level,
along the beam, toward the vehicle, what a mover coming down the beam does. At 20 deg down,
1 deg of pitch moves a return on a top 0.8 m below by 0.12 m; a 1.5 m post's top read as a
2.1 m/s mover behind a vehicle flying away, and a box's top as 1.5 m/s (45 deg beams;
obstacles-wide seed 20261166, flight 20). The speed then pushed the vehicle through its
corridor's corner wall (0.71 m off the path), and with that fixed, into the guard's speed
rule ahead (the flight ended). That slide is what ``still_plane`` explains (the top's
height fixed through the older return's lowest or highest ray, met by the newer one's at
its measured range), so every pair of a tilted beam is judged by it. Until then only beams
within 15 deg of level read movers, on the premise that a level beam meets a walker
wherever it can reach the vehicle; true for the default suite's low ring (4-14 deg down),
not for a suite whose level ring is 2 deg high and whose next ring looks 20 deg down:
climbing at 2.13 m, a vehicle flew at 0.8 m/s toward a worker walking down the corridor,
whom only the 20 and 45 deg rings saw, and kept 0.124 m (fresh seed 20261221, flight 8).
Across a tilted beam a return also moves as the vehicle pitches (a beam looking sideways
rolls), so a tilted beam counts only motion along it. Steeper than 60 deg, the level part
of the axis is too small to read an approach.

A speed is read only along a continuous track: between the pair's two returns of one
beam, no return of that beam moved level farther than any mover could in the time
between them (``MAX_M_S`` per second, plus ``JUMP_TOL_M`` of noise). A beam that slides
over an edge onto another surface jumps: tilted 45 deg down behind a vehicle flying away,
it left a box's top for a still walker's head 0.7 m nearer between two 20 Hz returns,
read as a 2.0 m/s mover chasing the vehicle (obstacles-wide seed 20261166, flight 20); the
push away from it broke the corridor's corner wall and carried the vehicle 0.71 m off the
path. The two surfaces are two objects, and neither moved. A mover's own returns are
continuous, so it is measured once they span a baseline (``BASELINE_S`` after it came
into the beam).
At rest across beams (a mover passing from beam to beam) no track is required.

A pair one still horizontal surface explains is no motion either (``still_plane``): a level
beam whose field's lower edge grazes an obstacle's top near the vehicle's own height
returns from where that edge meets the top, at the height difference over the sine of the
edge's angle, so the vehicle's pitch slides the return along the beam. A box's top 0.5 m
under a vehicle hovering 4-5 m away read as a mover at 0.4-1.4 m/s each time the vehicle
pitched: stop, look, "no motion", avoid, rejoin, stop again, 40 times in 230 s (mix
20261210 flight 14). The older return fixes the height where its lowest (or highest) ray
met the surface; the newer one's lowest (highest) ray meets that height at a predicted
range; within ``MIN_M_S`` per second of the measured one, it is that plane. A mover coming
down the beam changes the range where the plane would not (the two agree only if the
vehicle's height and pitch happen to follow the mover's approach, pair after pair).

In flight the earlier hit is the same beam's: two beams see two
different points of one still object, and a pair across them is no motion.
Returns of two beams on one post within ``MATCH_M`` of each other read 1.6-1.9
m/s while the vehicle climbed beside it (obstacles-wide seed 20261152, flight 0),
and a level beam paired with the low ring's beam 9 deg below it read 2.2 m/s
(seed 20261160, flight 27). At rest it is any beam's: a crossing walker passes
from beam to beam, and a fixed beam's own earlier return, where it has one, is
the nearest.

Movers move level: only the level parts count (the axis' level direction,
the return's level displacement), and only beams within ``MOVER_TILT_MAX_DEG``
of level are used (above; the down rangefinder's return also jumps as the
vehicle passes over a crate).

Pure: times are the vehicle clock (s), points world ENU (m); no I/O.
"""

from __future__ import annotations

import math

#: Shortest time (s) between the two hits of one sensor that give a speed.
BASELINE_S = 0.3
#: Two hits farther apart (m) are not the same object.
MATCH_M = 1.0
#: An approach speed is remembered this long (s) after it was last measured.
HOLD_S = 1.0
#: Approach speeds (m/s) below this are taken as a still obstacle.
MIN_M_S = 0.3
#: Approach speeds above this (m/s) are not a walker or a tractor: a wrong match.
MAX_M_S = 6.0
#: The return must have moved at least this fraction of its displacement along the beam.
ALIGN_MIN = 0.8
#: Beams tilted more than this (deg) from level do not read movers (module notes).
MOVER_TILT_MAX_DEG = 60.0
#: ... as the level part of the unit axis: |u_xy| below this is too steep.
MIN_LEVEL = math.cos(math.radians(MOVER_TILT_MAX_DEG))
#: Beams tilted more than this (deg) read movers only along their own track, in flight's
#: rule, with ``still_plane`` judging every pair (module notes).
PLANE_TILT_DEG = 15.0
PLANE_LEVEL = math.cos(math.radians(PLANE_TILT_DEG))
#: A hit older than this (s) is not compared.
_STALE_S = 1.5
#: Level noise (m) allowed on top of ``MAX_M_S`` between two returns of one beam on one track.
JUMP_TOL_M = 0.1


class ClosingSpeed:
    """The largest approach speed (m/s) of an unknown obstacle toward the vehicle."""

    def __init__(self) -> None:
        self._hist: dict[int, list[tuple]] = {}
        self._w = 0.0
        self._t_w = -math.inf
        self._at: tuple[float, float, float] | None = None

    def on_hit(self, t_s: float, sensor_id: int, hit_enu_m, axis_enu, still: bool = False,
               origin_enu_m=None, field=None, spread_m: float = 0.0) -> None:
        """An unknown return of ``sensor_id`` at vehicle time ``t_s``: the hit point
        (ENU, m) and the beam's unit axis (ENU, from the sensor outward); ``still``: the
        vehicle is still, so any motion of the return is the obstacle's; ``origin_enu_m``:
        the sensor's position (a return riding with it is no approach; None: not judged);
        ``field``: (sensor height m, measured range m, lowest and highest sine of
        elevation in its field of view; ``perception.field_sine_range``), for
        ``still_plane`` (None: not judged); ``spread_m``: how far (m) across the beam the
        return may lie from ``hit_enu_m`` (the field of view at the measured range), kept
        with the mover's place (``mover_at``) (module notes)."""
        hit = (float(hit_enu_m[0]), float(hit_enu_m[1]), float(hit_enu_m[2]))
        uh = math.hypot(float(axis_enu[0]), float(axis_enu[1]))
        if uh < MIN_LEVEL:
            return                   # looking down: hardly any level part (module notes)
        tilted = uh < PLANE_LEVEL
        if tilted and field is None:
            return                   # a tilted beam's top is judged by ``still_plane`` only
        # one history for the level beams: at rest a mover passes from beam to beam; a
        # tilted beam's own (its returns slide over tops; module notes)
        h = self._hist.setdefault(-1 - int(sensor_id) if tilted else 0, [])
        still = still and not tilted
        u = (float(axis_enu[0]) / uh, float(axis_enu[1]) / uh, 0.0)      # level: movers move level
        o = None if origin_enu_m is None else (float(origin_enu_m[0]), float(origin_enu_m[1]))
        while h and t_s - h[0][0] > _STALE_S:
            h.pop(0)
        # the nearest hit (within MATCH_M: the same object) of those BASELINE_S to
        # 2 BASELINE_S old; the nearest, not the newest: a post beside a walker
        best, t0 = MATCH_M, None
        for tk, pk, uk, ok, sk, ek in reversed(h):
            age = t_s - tk
            if age < BASELINE_S:
                continue
            if age > 2.0 * BASELINE_S:
                break
            if not still and sk != sensor_id:
                continue             # in flight, one beam's own returns (module notes)
            dk = math.dist(hit, pk)
            if dk <= best:
                best, t0, p0, u0, o0, s0, e0 = dk, tk, pk, uk, ok, sk, ek
        if t0 is not None and s0 == sensor_id and not continuous(h, sensor_id, t0, t_s, hit):
            t0 = None                # a jump between two surfaces, no motion (module notes)
        if t0 is not None:
            d = (hit[0] - p0[0], hit[1] - p0[1], 0.0)
            along = d[0] * u[0] + d[1] * u[1]
            moved = math.hypot(d[0], d[1])
            if still and not (s0 == sensor_id and swept(p0, u0, o0, u, o, t_s - t0)):
                # no sweep: the return moved because the obstacle did, whichever way
                w, aligned = moved / (t_s - t0), True
            else:
                # a mover coming down the beam moves its return along the axis; a beam sweeping
                # over a still surface (the vehicle flying past a box) slides it across
                w, aligned = -along / (t_s - t0), -along >= ALIGN_MIN * moved
            counts = MIN_M_S <= w <= MAX_M_S and aligned and \
                not (s0 == sensor_id and still_plane(e0, field, t_s - t0))
            if counts and not riding(d, o, o0, t_s - t0):
                # the largest speed while the mover keeps coming (conservative), fresh again
                if w >= self._w or t_s - self._t_w > HOLD_S:
                    self._w = w
                self._t_w = t_s
                self._at = (hit[0], hit[1], float(spread_m))
            elif counts and self.following(t_s, hit):
                # riding with the vehicle, where the mover being given way to was: it keeps
                # pace with the vehicle backing away from it (module notes). Its approach is
                # held, not raised: a speed read from a return that rides with the vehicle
                # grows with the vehicle's own
                self._t_w = t_s
                self._at = (hit[0], hit[1], float(spread_m))
        h.append((t_s, hit, u, o, sensor_id, field))

    def following(self, t_s: float, hit) -> bool:
        """An approach counts at ``t_s`` and ``hit`` (ENU m) lies where it was measured
        (within ``MATCH_M`` and its return's spread of ``mover_at``)."""
        at = self.mover_at(t_s)
        return at is not None and math.hypot(hit[0] - at[0], hit[1] - at[1]) <= MATCH_M + at[2]

    def approach_m_s(self, t_s: float | None) -> float:
        """The approach speed (m/s, >= 0) that the governor allows for at time ``t_s``
        (None: before the first step, 0)."""
        return self._w if t_s is not None and t_s - self._t_w <= HOLD_S else 0.0

    def mover_at(self, t_s: float | None) -> tuple[float, float, float] | None:
        """Where the mover was last measured coming closer, while ``approach_m_s`` counts it:
        (east m, north m, spread m), the return of the last approach measured and how far
        across its beam it may lie; None when no approach counts at ``t_s``."""
        return self._at if self.approach_m_s(t_s) > 0.0 else None


def continuous(history, sensor_id: int, t0_s: float, t_s: float, hit) -> bool:
    """The returns of ``sensor_id`` in ``history`` from ``t0_s`` on, then ``hit`` at ``t_s``,
    form one track: each moved level from the one before at most ``MAX_M_S`` times the
    time between them plus ``JUMP_TOL_M`` (module notes)."""
    later = (t_s, hit)
    for tk, pk, _uk, _ok, sk, _ek in reversed(history):      # newest first: stop at t0_s
        if tk < t0_s:
            break
        if sk != sensor_id:
            continue
        if not _step_ok((tk, pk), later):
            return False
        later = (tk, pk)
    return True


def still_plane(field0, field1, dt_s: float) -> bool:
    """Two returns of one beam (``ClosingSpeed.on_hit``'s ``field`` of each) are what one
    still horizontal surface gives: the surface at the height where the older return's
    lowest (or highest) ray met it, met by the newer one's lowest (highest) ray at its
    measured range within ``MIN_M_S`` per second. A level beam whose field's lower edge
    grazes an obstacle's top near the vehicle's own height moves its return along the beam
    as the vehicle pitches (the range to the top through the lower edge is the height
    difference over the sine of its angle): a box's top read as a mover coming at 1.4 m/s,
    40 times in one flight (mix 20261210 flight 14). A mover walking down a beam whose
    geometry stays changes the range where the plane would not. False when either is None."""
    if field0 is None or field1 is None:
        return False
    oz0, d0, lo0, hi0 = field0
    oz1, d1, lo1, hi1 = field1
    for s0, s1 in ((lo0, lo1), (hi0, hi1)):
        if s0 * s1 <= 0.0 or abs(s1) < 1e-6:
            continue                 # not the same side of level: no such plane
        pred = (oz0 + d0 * s0 - oz1) / s1
        if pred > 0.0 and abs(pred - d1) < MIN_M_S * dt_s:
            return True
    return False


def _step_ok(a, b) -> bool:
    (ta, pa), (tb, pb) = a, b
    return math.hypot(pb[0] - pa[0], pb[1] - pa[1]) <= MAX_M_S * (tb - ta) + JUMP_TOL_M


def swept(hit0, u0, origin0, u, origin, dt_s: float) -> bool:
    """One beam (level axes ``u0`` then ``u``, origins ``origin0`` then ``origin``) moved over
    ``dt_s`` so that a still return at its old place ``hit0`` would have slid at least
    ``MIN_M_S``: the point at the old level range along the beam moved that far (the vehicle
    yawing at rest turns its beams: module notes). False when either origin is unknown."""
    if origin is None or origin0 is None:
        return False
    r0 = math.hypot(hit0[0] - origin0[0], hit0[1] - origin0[1])
    dx = origin[0] + r0 * u[0] - (origin0[0] + r0 * u0[0])
    dy = origin[1] + r0 * u[1] - (origin0[1] + r0 * u0[1])
    return math.hypot(dx, dy) >= MIN_M_S * dt_s


def riding(d_hit, origin, origin0, dt_s: float) -> bool:
    """The return moved with the sensor: the sensor moved at least ``MIN_M_S`` and the
    return's level displacement ``d_hit`` less the sensor's stays below ``MIN_M_S`` over
    ``dt_s`` (module notes). False when either origin is unknown."""
    if origin is None or origin0 is None:
        return False
    ox, oy = origin[0] - origin0[0], origin[1] - origin0[1]
    lim = MIN_M_S * dt_s
    if math.hypot(ox, oy) < lim:
        return False
    return math.hypot(d_hit[0] - ox, d_hit[1] - oy) < lim


def allowed_approach_m_s(stop_speed_m_s, approach_m_s: float):
    """The vehicle's allowed approach speed (m/s; negative: back away) toward a
    point it could stop for from ``stop_speed_m_s`` when still, with the point
    itself coming at ``approach_m_s``: the closing speed stays within the
    stopping speed (module notes)."""
    return stop_speed_m_s - approach_m_s


#: A vehicle backing away from a mover outpaces it by this much (m/s).
OUTPACE_M_S = 0.5


def give_way_speed_m_s(cruise_m_s: float, approach_m_s: float) -> float:
    """Horizontal speed cap (m/s) of the avoidance: the cruise speed, or more when a
    mover comes at ``approach_m_s``: backing away must outpace it by ``OUTPACE_M_S``
    (a vehicle held to a 1 m/s cruise cannot escape a worker walking at 1.5 m/s)."""
    return max(cruise_m_s, approach_m_s + OUTPACE_M_S) if approach_m_s > 0.0 else cruise_m_s


def give_way_range_m(influence_m: float, trigger_m: float, approach_m_s: float) -> float:
    """Range (m) within which the governor acts on remembered points: the APF's
    influence range, or, while a mover comes closer, the whole trigger range (the
    braking distance of the closing speed): a mover first seen beyond the
    influence range must slow the vehicle from there."""
    return max(influence_m, trigger_m) if approach_m_s > 0.0 else influence_m
