"""The nearest surface inside a rangefinder's field of view, solved exactly.

A rangefinder returns the distance to the nearest surface point in its field
of view: the minimum of ``|x - o|`` over the points x of the solid that lie in
the sensor's pyramid K (apex o; sensor frame: beam along x, |y| <= tan(h/2) x,
|z| <= tan(v/2) x, h and v the full horizontal and vertical fields of view).
For a convex solid S that minimum is attained at the projection of the apex
onto the convex set ``S ∩ K``, found here by Dykstra's alternating projection
algorithm (Boyle & Dykstra 1986; Bauschke & Combettes, *Convex Analysis and
Monotone Operator Theory*, 2nd ed., Thm. 30.7): projecting onto S (vertical
cylinder or yawed box: a clamp) and onto K (a polyhedral cone: the nearest of
its faces, edges and apex) in turn. Every iterate's direction lies in K; a
ray cast along it gives a surface point that really is in view, so the
result never under-reads, and it converges to the exact minimum from above.

Flat ground is a half-space ``z <= z_g``: the nearest in-view point is at
``h / |P_K(-e_z)|`` (h the height above it), because the largest ``-u_z`` over
unit directions u of a convex cone is the length of the projection of
``-e_z`` onto it (Moreau's decomposition).

Pure: plain floats in and out (the SITL's hot path), no I/O.
"""

from __future__ import annotations

import math

from mavcore.pyramid import project_pyramid

_INF = math.inf
TOL_M = 1e-3             # the search stops when its bounds are this close (m)
_STEP_M = 1e-6           # ... or when an iterate moves less than this (m)
_MAX_ITERS = 24          # ... or after this many (the best ray so far is returned)
_STALE_ITERS = 6         # ... or when the best ray has not improved by TOL_M for this many


class Pyramid:
    """A rangefinder's field of view placed in the world: apex o (ENU) and
    the sensor axes (columns of M, sensor frame -> world ENU)."""

    __slots__ = ("o", "M", "a", "b", "max_m")

    def __init__(self, o, M, a: float, b: float, max_m: float) -> None:
        self.o = o          # (3,) tuple
        self.M = M          # row-major 9-tuple
        self.a, self.b = a, b
        self.max_m = max_m

    def to_sensor(self, px, py, pz):
        m = self.M
        ex, ey, ez = px - self.o[0], py - self.o[1], pz - self.o[2]
        return (m[0] * ex + m[3] * ey + m[6] * ez,
                m[1] * ex + m[4] * ey + m[7] * ez,
                m[2] * ex + m[5] * ey + m[8] * ez)

    def project(self, px, py, pz):
        """Projection (world ENU) of a world point onto the pyramid."""
        sx, sy, sz = project_pyramid(*self.to_sensor(px, py, pz), self.a, self.b)
        m = self.M
        return (self.o[0] + m[0] * sx + m[1] * sy + m[2] * sz,
                self.o[1] + m[3] * sx + m[4] * sy + m[5] * sz,
                self.o[2] + m[6] * sx + m[7] * sy + m[8] * sz)

    def edges(self) -> tuple[tuple[float, float, float], ...]:
        """The four edge directions (ENU, not normalised) of the pyramid."""
        m, a, b = self.M, self.a, self.b
        out = []
        for sa in (1.0, -1.0):
            for sb in (1.0, -1.0):
                y, z = sa * a, sb * b
                out.append((m[0] + m[1] * y + m[2] * z, m[3] + m[4] * y + m[5] * z, m[6] + m[7] * y + m[8] * z))
        return tuple(out)

    def distance_to(self, px, py, pz) -> float:
        """Distance (m) from a world point to the pyramid (0 inside)."""
        qx, qy, qz = self.project(px, py, pz)
        return math.sqrt((qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2)

    def ground_distance(self, z_ground: float) -> float:
        """Nearest in-view distance (m, inf beyond max_m) to the flat ground
        ``z <= z_ground`` (the half-space; 0 at or below it)."""
        h = self.o[2] - z_ground
        if h <= 0.0:
            return 0.0
        m = self.M
        # -e_z in the sensor frame: minus the third row of M
        gx, gy, gz = project_pyramid(-m[6], -m[7], -m[8], self.a, self.b)
        g = math.sqrt(gx * gx + gy * gy + gz * gz)
        if g <= 0.0:
            return _INF
        t = h / g
        return t if t <= self.max_m else _INF


def nearest_in_view(fov: Pyramid, project_solid, raycast_solid,
                    limit_m: float | None = None) -> tuple[float, tuple[float, float, float] | None]:
    """Nearest distance (m) from the apex to a convex solid inside the field of view.

    Parameters
    ----------
    fov : Pyramid
    project_solid : callable (x, y, z) -> (x, y, z)
        Euclidean projection onto the solid (world ENU).
    raycast_solid : callable (ox, oy, oz, dx, dy, dz, max_m) -> float
        Entry distance along a unit ray (inf if none within max_m).
    limit_m : float, optional
        Only a distance below this matters (default ``fov.max_m``): the
        search stops as soon as its lower bound reaches it.

    Returns
    -------
    (distance_m, direction) : float, unit 3-tuple (ENU) or None
        ``math.inf`` and None when the solid has no point in view below the
        limit. The distance is the ray-cast entry along ``direction`` (a
        direction in view): the smallest over Dykstra's iterates, within
        ``tol_m`` of the exact minimum (its lower bound, below).

    Notes
    -----
    Lower bound: for any point x and s = P_S(x) != x, the solid lies in the
    half-space ``<n, z - s> <= 0`` (n = (x - s)/|x - s|), whose nearest
    in-view point is at ``h / |P_K(-n)|`` (h = <n, o - s> > 0, the apex's
    height above that plane; Moreau, as for the ground). The best of these
    bounds proves that a solid is out of view or out of range in one step
    and ends the search when it meets the ray-cast upper bound.
    """
    ox, oy, oz = fov.o
    lim = fov.max_m if limit_m is None else min(limit_m, fov.max_m)
    best, best_u = _INF, None
    lower = 0.0
    stale = 0
    x = (ox, oy, oz)
    px = py = pz = 0.0      # Dykstra's corrections for S and K
    qx = qy = qz = 0.0
    for _ in range(_MAX_ITERS):
        s = project_solid(x[0], x[1], x[2])
        nx, ny, nz = x[0] - s[0], x[1] - s[1], x[2] - s[2]
        nn = math.sqrt(nx * nx + ny * ny + nz * nz)
        if nn > 0.0:
            nx, ny, nz = nx / nn, ny / nn, nz / nn
            h = nx * (ox - s[0]) + ny * (oy - s[1]) + nz * (oz - s[2])
            if h > 0.0:
                gx, gy, gz = fov.to_sensor(ox - nx, oy - ny, oz - nz)
                gx, gy, gz = project_pyramid(gx, gy, gz, fov.a, fov.b)
                g = math.sqrt(gx * gx + gy * gy + gz * gz)
                bound = h / g if g > 0.0 else _INF
                if bound > lower:
                    lower = bound
                    if lower >= lim or lower >= best:
                        break
        elif x[0] == ox and x[1] == oy and x[2] == oz:
            return 0.0, None            # the apex is inside the solid
        y = project_solid(x[0] + px, x[1] + py, x[2] + pz)
        px, py, pz = x[0] + px - y[0], x[1] + py - y[1], x[2] + pz - y[2]
        xn = fov.project(y[0] + qx, y[1] + qy, y[2] + qz)
        qx, qy, qz = y[0] + qx - xn[0], y[1] + qy - xn[1], y[2] + qz - xn[2]
        dx, dy, dz = xn[0] - ox, xn[1] - oy, xn[2] - oz
        n = math.sqrt(dx * dx + dy * dy + dz * dz)
        if n > 0.0:
            u = (dx / n, dy / n, dz / n)
            t = raycast_solid(ox, oy, oz, u[0], u[1], u[2], lim)
            if t < best - TOL_M:
                stale = 0
            else:
                stale += 1
            if t < best:
                best, best_u, lim = t, u, t
        if best - lower <= TOL_M or (best < _INF and stale >= _STALE_ITERS):
            break
        step = (xn[0] - x[0]) ** 2 + (xn[1] - x[1]) ** 2 + (xn[2] - x[2]) ** 2
        x = xn
        if step < _STEP_M * _STEP_M:
            break
    return best, best_u
