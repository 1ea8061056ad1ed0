"""Polylines in any dimension (pure): points along one at most a given step apart, and
the distances of points to its segments.

``densify`` is shared by the planner's DEM coverage check (``planner.check_dem_covers``,
in the plane) and the re-route repair's judgement of a route's straight segments
(``replan.repair``, in 3-D); ``segment_distances`` by the corridor coverage check
(``coverage.corridors``, in the plane) and the pacing's path check (``replan.pace``, in
3-D).
"""

from __future__ import annotations

import numpy as np


def densify(points: np.ndarray, step_m: float) -> np.ndarray:
    """The polyline's vertices plus points at most ``step_m`` apart along every
    segment, in order, (M, D) from (K, D) vertices (each vertex once)."""
    p = np.asarray(points, dtype=float)
    seg = np.diff(p, axis=0)
    n = np.maximum(1, np.ceil(np.linalg.norm(seg, axis=1) / step_m).astype(np.intp))
    idx = np.repeat(np.arange(len(seg)), n)
    frac = np.arange(idx.size) - np.repeat(np.cumsum(n) - n, n)
    pts = p[idx] + seg[idx] * (frac / n[idx])[:, None]
    return np.vstack([pts, p[-1:]])


def segment_distances(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(nq, ns) distances from points ``q`` (nq, D) to the segments ``a``-``b`` (ns, D) each."""
    ab = b - a
    L2 = np.maximum((ab * ab).sum(axis=1), 1e-18)
    s = ((q[:, None, :] - a[None]) * ab[None]).sum(axis=2) / L2[None]
    s = np.clip(s, 0.0, 1.0)
    closest = a[None] + s[..., None] * ab[None]
    return np.hypot.reduce(q[:, None, :] - closest, axis=2)


def pair_segment_distances(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n,) distance of each point q[i] to the segment a[i]-b[i]: ``segment_distances``'s
    formula, operation for operation (the same numbers), on pairs instead of all pairs."""
    ab = b - a
    L2 = np.maximum((ab * ab).sum(axis=1), 1e-18)
    s = np.clip(((q - a) * ab).sum(axis=1) / L2, 0.0, 1.0)
    return np.hypot.reduce(q - (a + s[:, None] * ab), axis=1)
