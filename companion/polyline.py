"""Points along a polyline, at most a given step apart (any dimension; pure).

Shared by the planner's DEM coverage check (``planner.check_dem_covers``, in
the plane) and the re-route repair's judgement of a route's straight
segments (``replan.repair``, in 3-D).
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
