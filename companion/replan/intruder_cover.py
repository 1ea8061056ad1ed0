"""Before flight: are low obstacles seen in time? (the lower half of the clearance sphere)

``coverage_check`` asks whether a beam looks along the direction of travel.
That covers an obstacle at least as high as the vehicle's centre, not a lower
one. Obstacles stand on the ground, and one whose top is ``delta`` below the
centre (0 <= delta < keep, keep = clearance + airframe radius) still enters
the clearance sphere when the vehicle passes within ``sqrt(keep^2 - delta^2)``
of it horizontally. A level beam 10 deg tall sees such a top only from
``delta / tan 5 deg`` on: 10.8 m for delta = keep, beyond a 6 m range. So a
post lower than the vehicle is never seen, and the vehicle brushes over it.

Geometry, in the level body frame of a sample (``coverage_check``), for the
horizontal direction of travel d (unit) and a beam (pyramid K = {|y| <= a x,
|z| <= b x} in its sensor frame, R: sensor -> body FLU):

- the pyramid's trace on the vertical half-plane of d: the directions
  ``d - t e_z`` (t: tangent of the depression below the horizon) in K form an
  interval ``[t_lo, t_hi]`` (five inequalities linear in t: x > 0,
  |y| <= a x, |z| <= b x);
- an obstacle at horizontal distance D whose top is delta below the centre
  holds the vertical segment of depression tangents ``[delta / D, h / D]``
  (h: the centre's height above the ground). The beam sees it when
  ``delta / D <= t_hi`` and ``h / D >= t_lo``, its nearest point in view at the
  depth ``max(delta, D t_lo)``;
- the beam returns the nearest surface anywhere in its view, so the ground
  hides what is farther than the ground's nearest point in view,
  ``h / |P_K(-e_z)|`` away on flat ground (Moreau's decomposition:
  ``sitl.fov``'s flat-ground rule); the terrain ahead along d (the DEM's
  profile) hides it too where it rises into the trace nearer than that. Terrain
  rising beside the direction of travel, inside a beam's width, is not modelled;
- stopping in time (``coverage_check``): seen at
  ``D >= v^2 / (2 a) + v tau + sqrt(keep^2 - delta^2)``.

For delta on a grid ``0 = delta_0 < ... < delta_K = min(keep, h)``, a beam allows
over ``[delta_k, delta_k+1]`` the speed ``allowed_speed(D_far(delta_k+1), a,
tau, sqrt(keep^2 - delta_k^2))``, D_far(delta) being the farthest D at which
the segment is in view, within range and nearer than the ground (0 when the
window ``[delta / t_hi, D_far]`` is empty). That is conservative over each
interval: the window closes as delta grows and the distance needed shrinks.
A sample's allowed speed is the least, over the intervals, of the best beam's.

Pure: arrays in, arrays out.
"""

from __future__ import annotations

import math

import numpy as np

from mavcore.pyramid import project_pyramid

from .coverage_check import allowed_speed

#: Intervals of the depth grid (0 .. keep).
DEPTH_STEPS = 8


def depression_interval(u_s: np.ndarray, z_s, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    """(t_lo, t_hi), (n,) each: tangents of the depressions at which the vertical
    half-plane of the horizontal directions ``u_s`` ((n, 3), sensor frame) lies in
    the pyramid; ``z_s``: the body's up axis in the sensor frame. Empty: t_lo > t_hi."""
    ux, uy, uz = u_s[:, 0], u_s[:, 1], u_s[:, 2]
    zx, zy, zz = (float(c) for c in z_s)
    # p + q t >= 0 for each face (x > 0 taken as x >= 0)
    rows = ((ux, -zx), (a * ux - uy, zy - a * zx), (a * ux + uy, -zy - a * zx),
            (b * ux - uz, zz - b * zx), (b * ux + uz, -zz - b * zx))
    lo = np.full(ux.shape, -np.inf)
    hi = np.full(ux.shape, np.inf)
    for p, q in rows:
        p = np.broadcast_to(p, ux.shape)
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = -p / q
        if q > 0.0:
            lo = np.maximum(lo, bound)
        elif q < 0.0:
            hi = np.minimum(hi, bound)
        else:
            hi = np.where(p >= 0.0, hi, -np.inf)
    return lo, hi


def ground_tangent(z_s, a: float, b: float) -> float:
    """|P_K(-e_z)|: the largest downward component of a unit direction in view
    (0: the beam never looks down)."""
    gx, gy, gz = project_pyramid(-float(z_s[0]), -float(z_s[1]), -float(z_s[2]), a, b)
    return math.sqrt(gx * gx + gy * gy + gz * gz)


def far_distance(delta, t_lo: np.ndarray, t_hi: np.ndarray, h: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """Farthest horizontal distance (m) at which an obstacle whose top is ``delta``
    (m, scalar or per sample) below the centre is in view, nearer than ``reach``
    (slant: the range, or the ground); 0 where never (module doc)."""
    delta = np.asarray(delta, dtype=float)
    pos = t_lo > 0.0
    tl = np.where(pos, t_lo, 1.0)
    d_flat = np.sqrt(np.maximum(reach * reach - delta * delta, 0.0))     # nearest point at depth delta
    d_tilt = reach / np.sqrt(1.0 + tl * tl)                              # ... at depth D t_lo
    deep = pos & (d_tilt * tl > delta)
    far = np.where(deep, d_tilt, np.where(pos, np.minimum(d_flat, delta / tl), d_flat))
    far = np.where(pos, np.minimum(far, h / tl), far)                    # the segment's foot in view
    up = t_hi > 0.0
    start = np.where(up, delta / np.where(up, t_hi, 1.0), np.inf)       # its top enters the view
    ok = (t_lo <= t_hi) & (start <= far) & (reach > delta)
    return np.where(ok, far, 0.0)


def ground_hit(t_lo: np.ndarray, t_hi: np.ndarray, tg: np.ndarray, slant: np.ndarray) -> np.ndarray:
    """(n,) slant distance (m) to the nearest terrain point of the profile in the
    pyramid's trace (inf: none), from the profile's depression tangents ``tg = drop / s``
    and slant distances ``slant = hypot(s, drop)`` ((n, m) each: ``drop[i, j]`` is the
    centre's height above the terrain ``s[j]`` ahead; computed once for every beam)."""
    inside = (tg >= t_lo[:, None]) & (tg <= t_hi[:, None])
    return np.where(inside, slant, np.inf).min(axis=1)


def low_allowed_speed(d_body: np.ndarray, h_m: np.ndarray, beams, accel_m_s2: float, keep_m: float,
                      control_delay_s: float, profile=None, ground_band_m: float = 0.0) -> np.ndarray:
    """(n,) speeds (m/s) at which every obstacle lower than the centre along the
    horizontal body directions ``d_body`` ((n, 3), unit) is seen in time;
    ``h_m``: the centre's height above the ground under it (module doc);
    ``beams``: ``coverage_check.Beam`` s; ``profile``: optional ``(s_m, drop_m)``,
    the terrain ahead (``ground_hit``): where it rises into a beam's view
    nearer than the flat ground would, it hides what is beyond; ``ground_band_m``:
    a return within this distance of the nearest ground in view is taken for the
    ground (the replanner's rule, ``KnownMap.ground_in_view_m`` and the known map's
    tolerance), so what lies in that band is hidden too. inf where nothing lower
    than the centre fits (h <= 0)."""
    h = np.asarray(h_m, dtype=float)
    n = h.shape[0]
    top = np.minimum(keep_m, np.maximum(h, 0.0))
    out = np.full(n, np.inf)
    per_beam = []
    if profile is not None:
        s_m, drop_m = profile
        tg = drop_m / s_m[None, :]                      # ground_hit's inputs, once for every beam
        slant = np.hypot(s_m[None, :], drop_m)
    for beam in beams:
        R = beam.rotation_flu
        u_s = d_body @ R
        z_s = R[2, :]                                   # R^T e_z
        t_lo, t_hi = depression_interval(u_s, z_s, beam.tan_half_h, beam.tan_half_v)
        # only the samples whose trace is not empty: elsewhere ``far_distance`` is 0, the
        # beam allows 0 m/s there, and no maximum below keeps a 0 (the same numbers)
        r = np.flatnonzero(t_lo <= t_hi)
        if not len(r):
            continue
        t_lo, t_hi, h_r = t_lo[r], t_hi[r], h[r]
        g = ground_tangent(z_s, beam.tan_half_h, beam.tan_half_v)
        with np.errstate(divide="ignore"):
            ground = np.where(g > 0.0, np.maximum(np.maximum(h_r, 0.0) / max(g, 1e-300) - ground_band_m, 0.0),
                              np.inf)
        reach = np.minimum(beam.max_m, ground)
        if profile is not None:
            reach = np.minimum(reach, ground_hit(t_lo, t_hi, tg[r], slant[r]))
        per_beam.append((r, t_lo, t_hi, h_r, reach, beam.period_s + control_delay_s))
    for k in range(DEPTH_STEPS):
        d0, d1 = top * k / DEPTH_STEPS, top * (k + 1) / DEPTH_STEPS
        need_c = np.sqrt(np.maximum(keep_m * keep_m - d0 * d0, 0.0))
        best = np.zeros(n)
        for r, t_lo, t_hi, h_r, reach, tau in per_beam:
            far = far_distance(d1[r], t_lo, t_hi, h_r, reach)
            best[r] = np.maximum(best[r], allowed_speed(far, accel_m_s2, tau, need_c[r]))
        out = np.where(top > 0.0, np.minimum(out, best), out)
    return out
