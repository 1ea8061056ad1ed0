"""Where to land when the guard refuses the spot under the vehicle (issue 15; pure, no I/O;
docs/replan.md "Landing where the guard accepts it").

The rule: a landing the guard refuses is moved, not given up. From a hover at ``start``
the candidates are, shortest path first:

- spots at the hover's height on rings round it, ``RING_STEP_M`` apart out to
  ``MAX_RING_M``, ``N_ANGLES`` on each (angle 0 east, counter-clockwise), reached by one
  straight level segment at the climb speed (the move starts beside what refused the
  landing, often inside a clearance);
- home (the launch point, whose column was checked before take-off and is checked again
  here): straight up to the transit height (when it is above the hover), across, and the
  landing from there.

A candidate is taken when ``Guard.check_landing`` passes its column at rest and
``Guard.check_segments`` passes its path flown as rest-to-rest segments (the terrain from
the first segment on: the vehicle is in the air). The path may start inside a clearance
(that is why the landing was refused) as long as it does not close in (the guard's
margin rule). The first candidate that passes is the move; none: None (the flight core
then holds, as before). Search cost is bounded: at most ``N_ANGLES * MAX_RING_M /
RING_STEP_M + 1`` candidates, each one column and one path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..trajectory.reference import climb_duration_s, segments_sample

#: Ring spacing (m): the lattice step of the 3-D route search.
RING_STEP_M = 0.25
#: Candidates the flight core tries per sensor frame: the search never stalls the frame
#: loop (about 1-2 ms of CPU a candidate on the mix's fields; a whole search of 150
#: candidates took 0.31 s of CPU in one frame before it was spread).
CANDIDATES_PER_FRAME = 2
#: Farthest ring (m): beyond it the move goes home.
MAX_RING_M = 3.0
#: Spots on each ring.
N_ANGLES = 16
#: Shortest duration (s) of a level move (``climb_duration_s``'s floor for the take-off's transfer).
MIN_LEVEL_S = 1.0


@dataclass(frozen=True)
class Divert:
    """A checked move to a landing spot: ``segments`` ``[(p0, p1, duration_s), ...]`` flown
    rest to rest (ENU), ``spot`` the landing's start (the last segment's end), ``path_m``
    its length, ``kind`` ``ring`` or ``home``, ``tried`` candidates looked at."""

    segments: tuple
    spot: tuple
    path_m: float
    kind: str
    tried: int

    @property
    def duration_s(self) -> float:
        return float(sum(s[2] for s in self.segments))

    def sample(self, t_s: float) -> tuple:
        """(p, v, a, jerk, snap) of the move ``t_s`` after its start (``smooth_segment``
        of the segment under way; the spot, at rest, after the end)."""
        return segments_sample(self.segments, float(t_s))

    def to_dict(self) -> dict:
        return {"spot_enu_m": [float(c) for c in self.spot], "path_m": float(self.path_m), "kind": self.kind,
                "duration_s": self.duration_s, "candidates_tried": self.tried}


def _level(p0, p1, speed_m_s: float) -> tuple:
    return (p0, p1, climb_duration_s(math.dist(p0, p1), speed_m_s, MIN_LEVEL_S))


def candidates(start, home, transit_z_m: float | None, climb_speed_m_s: float, transfer_speed_m_s: float):
    """The candidate moves ``(path_m, kind, segments)`` in the order they are tried:
    path length, then ring angle (module doc)."""
    x, y, z = (float(c) for c in start)
    out = []
    n_rings = int(round(MAX_RING_M / RING_STEP_M))
    for i in range(1, n_rings + 1):
        r = i * RING_STEP_M
        for k in range(N_ANGLES):
            a = 2.0 * math.pi * k / N_ANGLES
            q = (x + r * math.cos(a), y + r * math.sin(a), z)
            out.append((r, "ring", (_level((x, y, z), q, climb_speed_m_s),)))
    if home is not None:
        hx, hy = float(home[0]), float(home[1])
        zt = max(z, transit_z_m if transit_z_m is not None else -math.inf)
        segs, path = [], 0.0
        cur = (x, y, z)
        if zt - z > 1e-6:
            top = (x, y, zt)
            segs.append((cur, top, climb_duration_s(zt - z, climb_speed_m_s)))
            path += zt - z
            cur = top
        over = (hx, hy, zt)
        if math.dist(cur, over) > 1e-6:
            segs.append(_level(cur, over, transfer_speed_m_s))
            path += math.dist(cur, over)
        if segs:
            out.append((path, "home", tuple(segs)))
    out.sort(key=lambda c: c[0])           # stable: equal lengths keep the ring order
    return out


def search(guard, start, home=None, transit_z_m: float | None = None, climb_speed_m_s: float = 0.5,
           transfer_speed_m_s: float = 1.0, per_step: int = 1):
    """(generator) ``find_landing`` a few candidates at a time: yields the number tried
    after every ``per_step`` refused ones (the flight core spreads the search over its
    frames, ``CANDIDATES_PER_FRAME``); returns the ``Divert``, or None."""
    tried = 0
    for path, kind, segs in candidates(start, home, transit_z_m, climb_speed_m_s, transfer_speed_m_s):
        tried += 1
        spot = segs[-1][1]
        if (guard.check_landing(spot, (0.0, 0.0, 0.0)).ok
                and guard.check_segments(list(segs), terrain_from=0).ok):
            return Divert(tuple(segs), tuple(float(c) for c in spot), float(path), kind, tried)
        if tried % per_step == 0:
            yield tried
    return None


def find_landing(guard, start, home=None, transit_z_m: float | None = None, climb_speed_m_s: float = 0.5,
                 transfer_speed_m_s: float = 1.0) -> Divert | None:
    """The first candidate (``candidates``) whose landing column and path the guard
    passes, as a ``Divert``; None when none does (``search`` all at once)."""
    steps = search(guard, start, home, transit_z_m, climb_speed_m_s, transfer_speed_m_s)
    while True:
        try:
            next(steps)
        except StopIteration as done:
            return done.value
