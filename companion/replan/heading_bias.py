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
on a beam within ``MAX_TILT_RAD`` of the horizontal whose vertical field
holds the horizon (nearer or steeper returns hold little of the heading) is rotated by each offset and asked of
the known map (``explain(evidence) -> bool``, the replanner's own test). A
return explained at some offsets but not at all is *informative*; its
explanation vector ``e_k`` (0/1) is added to scores that fade with the time
constant ``TAU_S`` (the error drifts as the motor currents change and
follows the heading), as is 1 to the evidence weight. A return no offset
explains (an unknown obstacle) or that every offset explains (the ground, a row face met head on) says
nothing about the heading and is left out.

The offsets whose score is within ``TIE_RETURNS`` of the best explain the
returns equally well: they form the interval the returns pin the error
down to (about a degree wide in a corridor). The estimate is the middle of
that run of offsets (of several runs, the one nearest 0) while the evidence
weight is at least ``MIN_EVIDENCE`` (0 below it: no fresh evidence, no
turn); but while that run holds 0 (the heading as
estimated explains the returns as well as any turn) it is 0. Before that,
and wherever the heading is right, nothing changes: flights on exact or
paper-model sensors are the same, bit for bit.

Safety: the estimate only rotates the evidence by the error the rows
measured; a return is then explained at that one rotation, never at a band
of them, so what it can hide is what a correct heading would hide. An
obstacle's returns, unexplained at every offset, do not vote.

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
#: ... and whose vertical field of view holds the horizon (or within this of it, for a narrow
#: one): the rows' faces pin the heading down at the horizon, a beam pitched down meets the
#: ground and the rows' feet, and such returns voted for a wrong heading (a ring pitched 6 deg
#: down, sloped field, realistic profile: 2.1 deg off for 40 s).
MIN_HALF_V_RAD = math.radians(2.0)
#: Heading sectors (rad): the votes of a return go to the sector of the vehicle's heading, and
#: the estimate for a heading reads its sector and the two beside it (45 deg). The realistic
#: profile's error follows the heading (the hard-iron residual turns with the body): 2-3 deg
#: of change over a 45 deg turn, which the pointing law makes in a few seconds. One pool for
#: all headings (fading in 10 s) lagged a turn and stood 1.5-2.2 deg off the error for 20 s
#: (tilted-hexagon, realistic profile, seed 1); fading in 2.5 s instead lost the evidence
#: between corridors and left 3.5 deg uncorrected (flat-rectangle, seed 3).
SECTOR_RAD = math.radians(15.0)
#: Fading time constant of a sector's scores (s): the part of the error that does not follow
#: the heading (the motor currents' field) drifts slowly; a corridor flown the other way
#: comes back to a sector within a minute.
TAU_S = 20.0
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
    """The heading error the known map measures (module doc), per sector of the vehicle's
    heading: ``at(t_s, heading_rad)`` is added to the estimated heading of every beam;
    ``estimate_rad`` is the last estimate made (of the sectors the last vote went to)."""

    def __init__(self, step_rad: float = STEP_RAD, span_rad: float = SPAN_RAD, period_s: float = PERIOD_S,
                 tau_s: float = TAU_S, min_evidence: float = MIN_EVIDENCE, sector_rad: float = SECTOR_RAD) -> None:
        n = int(round(span_rad / step_rad))
        self.offsets = tuple(k * step_rad for k in range(-n, n + 1))
        self.period_s = float(period_s)
        self.tau_s = float(tau_s)
        self.min_evidence = float(min_evidence)
        self.n_sectors = max(1, int(round(2.0 * math.pi / sector_rad)))
        self._sectors: dict[int, list] = {}       # sector -> [scores, weight, time of the scores]
        self._cache: dict[int, tuple] = {}        # sector -> (time, estimate)
        self.estimate_rad = 0.0
        self.weight = 0.0                          # evidence of the last estimate made (faded)
        self.n_evaluated = self.n_informative = 0
        self._t_last = -math.inf

    def sector(self, heading_rad) -> int:
        """The heading sector of ``heading_rad`` (0 when None: one sector for all)."""
        if heading_rad is None:
            return 0
        return int(math.floor((heading_rad % (2.0 * math.pi)) / (2.0 * math.pi) * self.n_sectors)) % self.n_sectors

    def wants(self, t_s: float, ev) -> bool:
        """Whether the return of ``ev`` at vehicle time ``t_s`` is evaluated (the period, range and tilt)."""
        if t_s - self._t_last < self.period_s - 1e-9 or ev.hit is None or not ev.distance_m >= MIN_RANGE_M:
            return False
        return abs(ev.axis[2]) <= math.sin(min(MAX_TILT_RAD, max(ev.half_v_rad, MIN_HALF_V_RAD)))

    def observe(self, t_s: float, ev, explain, on_terrain=None, heading_rad=None) -> None:
        """Evaluate the return of ``ev`` (``wants`` first) with ``explain(evidence) -> bool``;
        ``heading_rad``: the vehicle's estimated heading (its sector gets the vote; None: one
        sector). ``on_terrain(evidence) -> bool``: a point of the return lies on the terrain.
        Such a return is explained at every turn (a turn about the vertical moves it along the
        ground), so it says nothing about the heading and does not spend the period: with a
        ring pitched down, ground returns would otherwise take the turns of the row returns."""
        if not self.wants(t_s, ev):
            return
        if on_terrain is not None and on_terrain(ev):
            return
        self._t_last = t_s
        self.n_evaluated += 1
        e = self._explained_at(ev, explain)
        k = sum(e)
        if k == 0.0 or k == len(e):
            return
        self.n_informative += 1
        b = self.sector(heading_rad)
        sec = self._sectors.get(b)
        if sec is None:
            sec = self._sectors[b] = [[0.0] * len(self.offsets), 0.0, t_s]
        f = math.exp(-(t_s - sec[2]) / self.tau_s) if t_s > sec[2] else 1.0
        sec[0] = [sc * f + x for sc, x in zip(sec[0], e)]
        sec[1] = sec[1] * f + 1.0
        sec[2] = t_s
        for d in (-1, 0, 1):
            self._cache.pop((b + d) % self.n_sectors, None)
        self.estimate_rad = self.at(t_s, heading_rad)

    def at(self, t_s: float, heading_rad=None) -> float:
        """The estimate (rad) for the vehicle's heading ``heading_rad`` at ``t_s``: from the
        votes of its sector and the two beside it, faded to ``t_s`` (recomputed at most every
        ``period_s``)."""
        b = self.sector(heading_rad)
        hit = self._cache.get(b)
        if hit is not None and t_s - hit[0] < self.period_s:
            return hit[1]
        scores = [0.0] * len(self.offsets)
        weight = 0.0
        for d in ((-1, 0, 1) if self.n_sectors >= 3 else (0,)):
            sec = self._sectors.get((b + d) % self.n_sectors)
            if sec is None:
                continue
            f = math.exp(-(t_s - sec[2]) / self.tau_s) if t_s > sec[2] else 1.0
            scores = [x + f * y for x, y in zip(scores, sec[0])]
            weight += f * sec[1]
        self.weight = weight
        est = self._estimate(scores, weight)
        self._cache[b] = (t_s, est)
        return est

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

    def _estimate(self, scores: list, weight: float) -> float:
        if weight < self.min_evidence:
            return 0.0                    # too little fresh evidence: the estimator's own heading
        top = max(scores)
        good = [sc >= top - TIE_RETURNS for sc in scores]
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
        return 0.0 if a <= mid <= b else 0.5 * (self.offsets[a] + self.offsets[b])
