"""Joining the main segments into one continuous boustrophedon path.

Order (documented heuristic): start at the first segment (smallest line
offset, then smallest ``t``) flown in the beam direction; then repeatedly
fly next the unvisited segment with the end point nearest (straight-line
distance) to the current position, entering it by that end. On a beam of
full lines this is the classic boustrophedon: lines in offset order with
alternating direction. Where a line is cut into several segments (an
obstacle in a corridor) the greedy rule continues with the nearest piece,
usually the rest of the same line behind the obstacle, so the detour stays
local; lines of different lengths need no special case. Each connection is
an auxiliary path from :func:`gridpath.aux_path`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .freespace import FreeSpace
from .gridpath import aux_paths


@dataclass(frozen=True, eq=False)
class Route:
    """A continuous coverage route in the grid frame G (m).

    Attributes
    ----------
    vertices_g : (N, 2)
        Polyline through the turning points (collinear and repeated points removed).
    main_g : (k, 2, 2)
        Main segments in flight order, each (start, end).
    aux_g : list of (m, 2)
        Auxiliary connections in flight order (end of main i to start of main i+1).
    """

    vertices_g: np.ndarray
    main_g: np.ndarray
    aux_g: list


def flight_order(starts: np.ndarray, ends: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Greedy nearest-end order (module doc): (k,) segment indices and (k,) reversed flags."""
    k = len(starts)
    first = int(np.argmin(line))   # segments come in (line, t) order: first line, smallest t
    order, rev = [first], [False]
    todo = np.ones(k, dtype=bool)
    todo[first] = False
    cur = ends[first]
    for _ in range(k - 1):
        ds = np.where(todo, np.hypot(*(starts - cur).T), np.inf)
        de = np.where(todo, np.hypot(*(ends - cur).T), np.inf)
        i_s, i_e = int(np.argmin(ds)), int(np.argmin(de))
        if ds[i_s] <= de[i_e]:
            nxt, r = i_s, False
        else:
            nxt, r = i_e, True
        order.append(nxt)
        rev.append(r)
        todo[nxt] = False
        cur = starts[nxt] if r else ends[nxt]
    return np.array(order), np.array(rev)


def _drop_collinear(p: np.ndarray, tol_m: float) -> np.ndarray:
    """Remove repeated points and vertices that do not turn (within tol_m)."""
    keep = [p[0]]
    for q in p[1:]:
        if np.hypot(*(q - keep[-1])) > tol_m:
            keep.append(q)
    p = np.array(keep)
    if len(p) < 3:
        return p
    out = [p[0]]
    for i in range(1, len(p) - 1):
        a, b, c = out[-1], p[i], p[i + 1]
        ab, bc = b - a, c - b
        cross = ab[0] * bc[1] - ab[1] * bc[0]
        # turning point unless b lies on segment a-c (within tol) and heads the same way
        if abs(cross) / max(np.hypot(*(c - a)), 1e-12) > tol_m or np.dot(ab, bc) < 0:
            out.append(b)
    out.append(p[-1])
    return np.array(out)


def join_segments(free: FreeSpace, starts: np.ndarray, ends: np.ndarray, line: np.ndarray,
                  source: str = "<map>") -> Route:
    """Order the main segments (G, m) and connect them into one :class:`Route`."""
    order, rev = flight_order(starts, ends, line)
    a = np.where(rev[:, None], ends[order], starts[order])
    b = np.where(rev[:, None], starts[order], ends[order])
    pts = [a[0], b[0]]
    aux = aux_paths(free, b[:-1], a[1:], source)
    for i, conn in enumerate(aux, start=1):
        pts.extend(conn[1:])
        pts.append(b[i])
    verts = _drop_collinear(np.array(pts), 1e-6)
    return Route(vertices_g=verts, main_g=np.stack([a, b], axis=1), aux_g=aux)
