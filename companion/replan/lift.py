"""Route heights over the obstacles the vehicle knows (pure; docs/replan.md "Pacing").

A re-route is planned in 2-D at the plan's height above the terrain. When its
path passes over an obstacle the vehicle knows and can climb (an occupied
voxel of the obstacle map), flying it at that height would break the guard's
clearance, and the guard refuses the whole route: a vehicle that had just
climbed over a low crate and then met a tall post held, because the way back
went over the crate (the independent 3-D check found the route).

``lift`` raises the route over them. Along the path, sampled every
``STEP_M``, the height it must fly at is the plan's height above the terrain,
or, over a voxel's box within ``R = keep + margin`` horizontally (``r``),
the box's top + ``sqrt(R^2 - r^2)``: the sphere of radius R about the
vehicle's centre clears the box's top edge (``required_height``; a voxel too
tall to clear only matters where the route passes within ``keep`` of it). That profile (as a lift above the terrain-following height) is widened
into ramps no steeper than ``slope`` (rise over run: the vertical speed over
the cruise speed), made piecewise linear from above (Douglas-Peucker, each
piece raised by the most the profile stands above it), and its breakpoints
are inserted into the 2-D path as way-points: each run between them then
flies a straight 3-D line. The heights come back as a terrain model
(``LiftedTerrain.height_at``: the DEM plus the lift) for ``waypoints_along``,
which follows it.

A profile that would go above ``ceiling`` (terrain + ``ceiling_agl_m`` less
``WALL_MARGIN_M``) cannot be flown: ``lift`` returns None (no route).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

#: Spacing (m) of the samples of the path's height profile.
STEP_M = 0.1
#: The piecewise-linear profile stands at most this far (m) above the sampled one before it is raised.
SIMPLIFY_M = 0.05
#: The route stays this far (m) below the ceiling (the avoidance's wall margin).
WALL_MARGIN_M = 0.1


class LiftedTerrain:
    """``height_at`` of the terrain a lifted route follows: the DEM plus the lift, the
    lift read on the path (the route's way-points all lie on it), linear between its
    samples."""

    def __init__(self, dem, path_xy: np.ndarray, lift_m: np.ndarray) -> None:
        self._tree = cKDTree(np.asarray(path_xy, float))
        self._lift = np.asarray(lift_m, float)
        self._dem = dem

    def lift_at(self, q: np.ndarray) -> np.ndarray:
        """(M,) the lift (m) at (M, 2) points: linear between the two path samples the point
        projects between (next to its nearest)."""
        P, L = self._tree.data, self._lift
        k = self._tree.query(q)[1]
        best = L[k].copy()
        best_d = np.full(len(q), np.inf)
        for a, b in ((k - 1, k), (k, k + 1)):
            ok = (a >= 0) & (b < len(P))
            a, b = np.clip(a, 0, len(P) - 1), np.clip(b, 0, len(P) - 1)
            d = P[b] - P[a]
            dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-18)
            f = np.clip(np.einsum("ij,ij->i", q - P[a], d) / dd, 0.0, 1.0)
            foot = P[a] + f[:, None] * d
            dist = np.hypot(*(q - foot).T)
            take = ok & (dist < best_d)
            best[take] = (L[a] + f * (L[b] - L[a]))[take]
            best_d[take] = dist[take]
        return best

    def height_at(self, x, y):
        x = np.asarray(x, float)
        q = np.column_stack([x.reshape(-1), np.asarray(y, float).reshape(-1)])
        out = np.asarray(self._dem.height_at(x, y), float).reshape(-1) + self.lift_at(q)
        return out.reshape(x.shape) if x.ndim else float(out[0])


def _dense(path_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(samples (M, 2), arc length (M,)) of the path every ``STEP_M`` at most, its vertices kept."""
    pts, arc = [path_xy[:1]], [np.zeros(1)]
    s0 = 0.0
    for i in range(len(path_xy) - 1):
        a, b = path_xy[i], path_xy[i + 1]
        L = float(np.hypot(*(b - a)))
        k = max(1, int(np.ceil(L / STEP_M)))
        f = np.arange(1, k + 1) / k
        pts.append(a + f[:, None] * (b - a))
        arc.append(s0 + f * L)
        s0 += L
    return np.vstack(pts), np.concatenate(arc)


def required_height(xy: np.ndarray, ground: np.ndarray, agl_m: float, voxels: np.ndarray, voxel_m: float,
                    keep_m: float, margin_m: float, cap_agl_m: float = np.inf) -> np.ndarray:
    """(M,) height (m, ENU z) the route must fly at over each of ``xy`` (M, 2) (module doc):
    ``ground + agl_m``, raised over each voxel whose box lies within ``R = keep_m + margin_m``
    horizontally (``r``, less half the sample spacing ``STEP_M``: a point between two samples
    is that near one of them) to the voxel's top + ``sqrt(R^2 - r^2)``, the height at which
    the sphere of radius R about the vehicle's centre clears the box's top edge. A voxel that
    would need more than ``ground + cap_agl_m`` stands above any height the route can take, so
    flying higher gains nothing beside it: it is left to the 2-D route and the guard where
    the sample lies outside the guard's clearance (its own distance to the box ``>= keep_m``:
    a route starts where the vehicle stopped, just outside it), and makes the point
    unflyable (inf) where it lies inside."""
    z = ground + agl_m
    if not len(voxels):
        return z
    h = 0.5 * voxel_m
    R = keep_m + margin_m
    tree = cKDTree(voxels[:, :2])
    tops = voxels[:, 2] + h
    for j, near in enumerate(tree.query_ball_point(xy, R + h * np.sqrt(2.0) + 0.5 * STEP_M)):
        if not near:
            continue
        d = np.abs(voxels[near, :2] - xy[j])
        r_box = np.hypot(*np.maximum(d - h, 0.0).T)          # to the box, at this sample
        r = np.maximum(r_box - 0.5 * STEP_M, 0.0)             # the nearest a point between samples may be
        inside = r < R
        if not inside.any():
            continue
        top, ri = tops[near][inside], r[inside]
        need = top + np.sqrt(R * R - ri ** 2)
        cap = ground[j] + cap_agl_m
        over = need > cap
        if over.any():
            # the margin is a preference, the clearance is not (as the climb, which flies at the
            # cap when top + clearance + body fits under it): at the cap where the sphere of
            # ``keep_m`` clears the box's edge there
            hard = top + np.sqrt(np.maximum(keep_m * keep_m - ri ** 2, 0.0))
            fits = over & (hard <= cap)
            need = np.where(fits, cap, need)
            over = over & ~fits
        if over.any():
            # too tall to clear: unflyable only where the sample itself is inside the clearance
            # (the route starts where the vehicle stopped, just outside it; the guard checks
            # between samples), else left to the 2-D route and the guard
            if np.any(r_box[inside][over] < keep_m):
                z[j] = np.inf
                continue
            need = np.where(over, -np.inf, need)
        z[j] = max(z[j], float(need.max()))
    return z


def _ramped(arc: np.ndarray, z: np.ndarray, slope: float) -> np.ndarray:
    """The least profile >= z whose slope (rise over run) is at most ``slope``."""
    out = z.copy()
    for i in range(1, len(out)):
        out[i] = max(out[i], out[i - 1] - slope * (arc[i] - arc[i - 1]))
    for i in range(len(out) - 2, -1, -1):
        out[i] = max(out[i], out[i + 1] - slope * (arc[i + 1] - arc[i]))
    return out


def _breakpoints(arc: np.ndarray, z: np.ndarray, lo: int, hi: int, tol: float, out: list) -> None:
    """Douglas-Peucker on (arc, z) between samples lo and hi (appends the kept indices)."""
    if hi <= lo + 1:
        return
    s = arc[lo:hi + 1]
    line = z[lo] + (z[hi] - z[lo]) * (s - s[0]) / max(s[-1] - s[0], 1e-12)
    dev = np.abs(z[lo:hi + 1] - line)
    k = int(np.argmax(dev))
    if dev[k] > tol:
        _breakpoints(arc, z, lo, lo + k, tol, out)
        out.append(lo + k)
        _breakpoints(arc, z, lo + k, hi, tol, out)


@dataclass(frozen=True)
class Over:
    """What a route is lifted over, and how: the known obstacle map's voxel centres (k, 3)
    ENU m and their size, the distance the centre keeps (airframe radius + clearance) and
    the margin beyond it, the steepest ramp (rise over run) and the ceiling above the
    terrain (m)."""

    voxels_enu_m: np.ndarray
    voxel_m: float
    keep_m: float
    margin_m: float
    slope: float
    ceiling_agl_m: float


def lift(path_xy: np.ndarray, dem, agl_m: float, over: Over):
    """(path_xy with the breakpoints inserted, terrain to follow) for a route over the known
    obstacles; (path_xy, dem) unchanged when nothing needs lifting; None when the route
    would have to go above the ceiling (module doc). The lift is the height above the
    terrain-following route (``ground + agl_m``): piecewise linear, so the terrain's own
    shape adds no breakpoints."""
    path = np.asarray(path_xy, float)
    vox = np.asarray(over.voxels_enu_m, float).reshape(-1, 3)
    if len(path) < 2 or not len(vox):
        return path, dem
    xy, arc = _dense(path)
    ground = np.asarray(dem.height_at(xy[:, 0], xy[:, 1]), float)
    base = ground + agl_m
    room = over.ceiling_agl_m - WALL_MARGIN_M - agl_m
    need = required_height(xy, ground, agl_m, vox, over.voxel_m, over.keep_m, over.margin_m, room + agl_m) - base
    if np.all(need <= 1e-9):
        return path, dem
    if not np.all(np.isfinite(need)):
        return None
    e = _ramped(arc, np.maximum(need, 0.0), over.slope)
    if np.any(e > room + 1e-9):
        return None
    L = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])
    vertex_at = np.unique(np.clip(np.searchsorted(arc, L - 1e-9), 0, len(xy) - 1))
    keep = set(int(i) for i in vertex_at)
    for a, b in zip(vertex_at[:-1], vertex_at[1:]):
        found: list = []
        _breakpoints(arc, e, int(a), int(b), SIMPLIFY_M, found)
        keep.update(found)
    idx = np.array(sorted(keep))
    # the piecewise-linear lift through the kept samples, raised to stand over e
    ep = e[idx].copy()
    for j in range(len(idx) - 1):
        a, b = idx[j], idx[j + 1]
        s = arc[a:b + 1]
        line = ep[j] + (ep[j + 1] - ep[j]) * (s - s[0]) / max(s[-1] - s[0], 1e-12)
        under = float(np.max(e[a:b + 1] - line))
        if under > 0.0:
            ep[j] += under
            ep[j + 1] += under
    ep = np.minimum(ep, room)           # e <= room everywhere: the clipped pieces still stand over it
    return xy[idx], LiftedTerrain(dem, xy, np.interp(arc, arc[idx], ep))
