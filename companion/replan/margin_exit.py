"""The way out of a clearance the vehicle stopped inside (pure; docs/replan.md "Candidates
that start inside").

The obstacle map can grow round a vehicle at rest: a climb stops over a post
whose top reads high (a wide beam smears it), and by the map the vehicle is
then inside the post's clearance (obstacles-wide seed 20261127, flight 16:
0.22 m inside, 0.92 m from the post by the truth). Every re-route from there
closed on the post on its first metres, the guard's margin rule refused each
one, and the vehicle held although a route existed.

``margin_exit`` finds the shortest straight leg out: along each of ``N_DIRS``
level directions, straight up and down, and the direction in which the
nearest surface recedes fastest, points every ``STEP_M`` up to ``MAX_M``;
the leg ends at the first point that keeps every clearance plus ``margin_m``,
and is taken only if the guard's margin rule holds along it (never closer to
any surface than it has been until out, never within the airframe radius) and
it stays between the floor and the ceiling. The re-route is then planned from
its end, flown after it (``reroute3d``'s leg in front of the 2-D re-route).
"""

from __future__ import annotations

import math

import numpy as np

#: Level directions tried.
N_DIRS = 16
#: Spacing (m) of the points along a leg.
STEP_M = 0.05
#: Longest leg (m).
MAX_M = 3.0


def _directions(guard, p: np.ndarray) -> np.ndarray:
    ang = 2.0 * math.pi * np.arange(N_DIRS) / N_DIRS
    dirs = [np.column_stack([np.cos(ang), np.sin(ang), np.zeros(N_DIRS)]), np.array([[0.0, 0.0, 1.0],
                                                                                      [0.0, 0.0, -1.0]])]
    d = guard.distances(p[None, :])
    kind = min(d, key=lambda k: float(d[k][0]) - guard.required_m(k))
    n = guard.normal(kind, p)
    if float(np.linalg.norm(n)) > 0.0:
        dirs.append(n[None, :])
    return np.vstack(dirs)


def margin_exit(guard, p_enu_m, floor_z: float, ceiling_z: float, margin_m: float) -> np.ndarray | None:
    """(2, 3) the leg [p, exit] (ENU m) out of every clearance (module doc); None when
    ``p`` already keeps them all plus ``margin_m``, or no leg gets out."""
    p = np.asarray(p_enu_m, dtype=float).reshape(3)
    d0 = guard.distances(p[None, :])
    if all(float(d0[k][0]) >= guard.required_m(k) + margin_m for k in d0):
        return None
    s = STEP_M * np.arange(1, int(MAX_M / STEP_M) + 1)
    best = None
    for u in _directions(guard, p):
        pts = p + s[:, None] * u
        inside_band = (pts[:, 2] >= floor_z) & (pts[:, 2] <= ceiling_z)
        d = guard.distances(np.vstack([p, pts]))
        out = np.ones(len(pts), dtype=bool)
        for kind, dk in d.items():
            out &= dk[1:] >= guard.required_m(kind) + margin_m
        if not out.any():
            continue
        k = int(np.argmax(out))
        if not inside_band[:k + 1].all():
            continue
        if not guard.check_path(np.vstack([p, pts[:k + 1]]), margin_m).ok:
            continue
        if best is None or s[k] < best[0]:
            best = (float(s[k]), pts[k])
    return None if best is None else np.vstack([p, best[1]])
