"""The rows as a compass: the heading error of the estimated pose, from the returns the known map explains.

Why
---
A rangefinder return is placed in the world with the estimated attitude. A
compass-grade heading is off by a degree or two (a magnetometer's hard-iron
residual and the field of the motor currents: ``sitl.profiles``, profile
``icm42688p-bmm150-zedf9p``, gives 1-2 deg), and a return 5-6 m away then
lands 0.1-0.2 m beside where it came from. A beam that grazes a row's face
at its field's edge puts its return that far into the corridor: an unknown
obstacle that is not there (a *phantom*), at the clearance of the path. Re-
flown with the true pose, every such return of a realistic-profile flight is
explained by the known map (BENCHMARKS.md, "realistic-profile phantoms").

The rows are long, fixed and known: they measure the heading error. For a
return at distance d the known map explains it only for some rotations of
the beam about the vertical through the sensor, an interval containing the
true error; the intervals of many returns overlap at the true error.

How
---
Candidate offsets ``eps_k = k * STEP_RAD``, ``|eps_k| <= SPAN_RAD``. At most
every ``PERIOD_S`` of vehicle time, one return at least ``MIN_RANGE_M`` away
on a beam within ``MAX_TILT_RAD`` of the horizontal and not pitched down below
its own vertical field (nearer or steeper returns hold little of the heading) is rotated by each offset and asked of
the known map (``explain(evidence) -> bool``, the replanner's own test). A
return explained at some offsets but not at all is *informative*; its
explanation vector ``e_k`` (0/1) is added to scores that fade with the time
constant ``TAU_S`` (the error drifts as the motor currents change), as is 1
to the evidence weight. A return no offset explains (an unknown obstacle) or
that every offset explains (the ground, a row face met head on) says
nothing about the heading and is left out.

The offsets whose score is within ``TIE_RETURNS`` of the best explain the
returns equally well: they form the interval the returns pin the error
down to (about a degree wide in a corridor). The estimate is the middle of
that run of offsets (of several runs, the one nearest 0), once the evidence
weight reaches ``MIN_EVIDENCE``; but while that run holds 0 (the heading as
estimated explains the returns as well as any turn) it is 0. Before that,
and wherever the heading is right, nothing changes: flights on exact or
paper-model sensors are the same, bit for bit.

Safety: the estimate only rotates the evidence by the error the rows
measured; a return is then explained at that one rotation, never at a band
of them, so what it can hide is what a correct heading would hide. An
obstacle's returns, unexplained at every offset, do not vote; but one beside
a row is explained at the turns that bring it onto the row, so a return on an
obstacle the vehicle already remembers (``remembered``) does not vote either
(a walker and a box beside rows set the estimate 4 deg the wrong way).

Pure: floats and the ``explain`` callable in, no I/O, vehicle time.
"""

from __future__ import annotations

import math

from .perception import BeamEvidence

#: Offset grid: step and half-span (rad).
STEP_RAD = math.radians(0.25)
SPAN_RAD = math.radians(4.0)
#: Every this many offsets (1 deg) are tested first, then those between two that answer
#: differently: an interval of explaining turns is about 2 tolerance / range wide, 2.3 deg for
#: the default 0.2 m (``replan.known_tolerance_m``) at 10 m, so none falls between two tests.
COARSE = 4
#: Vehicle time (s) between two evaluated returns.
PERIOD_S = 0.1
#: Returns nearer than this (m) are not evaluated (0.25 deg at 2 m is 9 mm).
MIN_RANGE_M = 2.0
#: Beams steeper than this from the horizontal (rad) are not evaluated.
MAX_TILT_RAD = math.radians(30.0)
#: ... and not pitched down below its own vertical field (its upper edge at most this far
#: under the horizon; a narrow beam within this of level): the rows' faces pin the heading
#: down at the horizon, a beam pitched down meets the ground and the rows' feet, and such
#: returns voted for a wrong heading (a ring pitched 6 deg down, sloped field, realistic
#: profile: 2.1 deg off for 40 s). Level beams count while the vehicle leans, as before.
MIN_HALF_V_RAD = math.radians(2.0)
#: Fading time constant of the scores (s).
TAU_S = 10.0
#: Evidence weight (informative returns, faded) before an estimate is made.
MIN_EVIDENCE = 10.0
#: Offsets whose score is within this many returns of the best explain the returns as well.
TIE_RETURNS = 1.0


def rotate_evidence(ev, eps_rad: float):
    """``ev`` (``perception.BeamEvidence``) with its beam turned by ``eps_rad`` (counter-clockwise
    seen from above) about the vertical through the sensor: directions and points alike."""
    c, s = math.cos(eps_rad), math.sin(eps_rad)
    ox, oy, oz = ev.origin

    def vec(v):
        return (c * v[0] - s * v[1], s * v[0] + c * v[1], v[2])

    def pt(q):
        x, y = q[0] - ox, q[1] - oy
        return (ox + c * x - s * y, oy + s * x + c * y, q[2])

    return BeamEvidence(ev.origin, vec(ev.axis), vec(ev.h_axis), vec(ev.v_axis), ev.half_h_rad, ev.half_v_rad,
                        ev.free_m, None if ev.hit is None else pt(ev.hit), ev.distance_m,
                        tuple(pt(q) for q in ev.fan_hits))


class HeadingBias:
    """The heading error the known map measures (module doc); ``estimate_rad`` is added to the
    estimated heading of every beam."""

    def __init__(self, step_rad: float = STEP_RAD, span_rad: float = SPAN_RAD, period_s: float = PERIOD_S,
                 tau_s: float = TAU_S, min_evidence: float = MIN_EVIDENCE) -> None:
        n = int(round(span_rad / step_rad))
        self.offsets = tuple(k * step_rad for k in range(-n, n + 1))
        self.period_s = float(period_s)
        self.tau_s = float(tau_s)
        self.min_evidence = float(min_evidence)
        self.scores = [0.0] * len(self.offsets)
        self.weight = 0.0
        self.estimate_rad = 0.0
        self.n_evaluated = self.n_informative = 0
        self._t_last = -math.inf
        self._t_fade = None

    def wants(self, t_s: float, ev) -> bool:
        """Whether the return of ``ev`` at vehicle time ``t_s`` is evaluated (the period, range and tilt)."""
        if t_s - self._t_last < self.period_s - 1e-9 or ev.hit is None or not ev.distance_m >= MIN_RANGE_M:
            return False
        return abs(ev.axis[2]) <= math.sin(MAX_TILT_RAD) and ev.axis[2] >= -math.sin(ev.half_v_rad + MIN_HALF_V_RAD)

    def observe(self, t_s: float, ev, explain, on_terrain=None, remembered=None) -> None:
        """Evaluate the return of ``ev`` (``wants`` first) with ``explain(evidence) -> bool``.
        ``on_terrain(evidence) -> bool``: a point of the return lies on the terrain. Such a
        return is explained at every turn (a turn about the vertical moves it along the
        ground), so it says nothing about the heading and does not spend the period: with a
        ring pitched down, ground returns would otherwise take the turns of the row returns.
        ``remembered(evidence) -> bool``: the return lies on an obstacle the vehicle remembers;
        such a return does not vote either (module doc, Safety), and spends the period."""
        if not self.wants(t_s, ev):
            return
        if on_terrain is not None and on_terrain(ev):
            return
        if remembered is not None and remembered(ev):
            # on an obstacle the vehicle remembers: that obstacle's return, which a turn
            # can bring onto a row (module doc, Safety). It spends the period: the map
            # query (40-140 us) then runs at most once per period, not for every return
            self._t_last = t_s
            return
        self._t_last = t_s
        self.n_evaluated += 1
        e = self._explained_at(ev, explain)
        k = sum(e)
        if k == 0.0 or k == len(e):
            return
        self.n_informative += 1
        self._fade(t_s)
        self.scores = [s + x for s, x in zip(self.scores, e)]
        self.weight += 1.0
        self._estimate()

    def _explained_at(self, ev, explain) -> list:
        """1.0 / 0.0 per offset: every ``COARSE``-th offset is tested, and those between two
        whose answers differ (an interval of explaining turns is wider than the coarse step:
        the known map's tolerance over the sensors' range)."""
        offs = self.offsets
        n = len(offs)
        e = [None] * n

        def at(i):
            if e[i] is None:
                a = offs[i]
                e[i] = 1.0 if explain(rotate_evidence(ev, a) if a else ev) else 0.0
            return e[i]

        coarse = list(range(0, n, COARSE))
        if coarse[-1] != n - 1:
            coarse.append(n - 1)
        for i, j in zip(coarse, coarse[1:]):
            if at(i) == at(j):
                e[i + 1:j] = [e[i]] * (j - i - 1)
            else:
                for k in range(i + 1, j):
                    at(k)
        return e

    def _fade(self, t_s: float) -> None:
        if self._t_fade is not None and t_s > self._t_fade:
            f = math.exp(-(t_s - self._t_fade) / self.tau_s)
            self.scores = [s * f for s in self.scores]
            self.weight *= f
        self._t_fade = t_s

    def _estimate(self) -> None:
        if self.weight < self.min_evidence:
            return
        top = max(self.scores)
        good = [sc >= top - TIE_RETURNS for sc in self.scores]
        runs, start = [], None
        for i, g in enumerate(good + [False]):
            if g and start is None:
                start = i
            elif not g and start is not None:
                runs.append((start, i - 1))
                start = None
        mid = len(self.offsets) // 2              # the offset 0
        a, b = min(runs, key=lambda r: 0 if r[0] <= mid <= r[1] else min(abs(r[0] - mid), abs(r[1] - mid)))
        # the estimator's own heading stands while it explains the returns as well as any
        self.estimate_rad = 0.0 if a <= mid <= b else 0.5 * (self.offsets[a] + self.offsets[b])
