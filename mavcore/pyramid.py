"""A rangefinder's field of view as a cone: the pyramid K = {|y| <= a x, |z| <= b x}
in the sensor frame (beam along x; a, b the tangents of the half fields of view).

Shared by the SITL's exact nearest-surface search (``sitl.fov``) and the
companion's pre-flight coverage check (``companion.replan.intruder_cover``).
Pure: plain floats in and out.
"""

from __future__ import annotations


def project_pyramid(x: float, y: float, z: float, a: float, b: float) -> tuple[float, float, float]:
    """Projection of (x, y, z) (sensor frame) onto K = {|y| <= a x, |z| <= b x}.

    a, b >= 0 are the tangents of the half fields of view. The projection onto
    a polyhedral cone is the projection onto the span of one of its faces: the
    point itself, a face plane, an edge ray or the apex; the nearest feasible
    candidate is the projection.
    """
    if abs(y) <= a * x and abs(z) <= b * x:
        return x, y, z
    best = (0.0, 0.0, 0.0)
    bd = x * x + y * y + z * z
    eps = 1e-12
    # face planes y = s a x (normal (s a, -1, 0)) and z = s b x (normal (s b, 0, -1))
    for s in (1.0, -1.0):
        n2 = a * a + 1.0
        k = (s * a * x - y) / n2
        px, py, pz = x - k * s * a, y + k, z
        if px >= 0.0 and abs(pz) <= b * px + eps and abs(py) <= a * px + eps:
            d = (px - x) ** 2 + (py - y) ** 2
            if d < bd:
                best, bd = (px, py, pz), d
        n2 = b * b + 1.0
        k = (s * b * x - z) / n2
        px, py, pz = x - k * s * b, y, z + k
        if px >= 0.0 and abs(py) <= a * px + eps and abs(pz) <= b * px + eps:
            d = (px - x) ** 2 + (pz - z) ** 2
            if d < bd:
                best, bd = (px, py, pz), d
    # edge rays (1, +-a, +-b)
    n2 = 1.0 + a * a + b * b
    for sa in (1.0, -1.0):
        for sb in (1.0, -1.0):
            t = (x + sa * a * y + sb * b * z) / n2
            if t > 0.0:
                px, py, pz = t, sa * a * t, sb * b * t
                d = (px - x) ** 2 + (py - y) ** 2 + (pz - z) ** 2
                if d < bd:
                    best, bd = (px, py, pz), d
    return best
