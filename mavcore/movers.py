"""Moving obstacles on scripted paths (``sim.movers``): where each one is at a
time of the vehicle clock, and its solid there.

Pure: a ``MoverConfig`` and a time (s since the SITL's boot) in, positions
(world ENU, m) and ``mavcore.geometry`` solids out. The SITL renders and
collides with these solids (``sitl.world``, ``sitl.collision``) and the
companion's report measures its true clearance to the same ones.

Kinematics
----------
The path is a polyline ``p_0 .. p_n`` of cumulative arc length ``s_k`` and
total length ``L``. Before ``start_s`` the mover stands at ``p_0``. After it,
the distance travelled is ``d = speed (t - start_s)``; without ``loop`` the
arc position is ``s = min(d, L)`` (it stops at the end), with ``loop`` it is
the triangle wave ``s = L - |L - (d mod 2L)|`` (back and forth). The heading
is that of the segment under ``s``, reversed on the way back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .geometry import Box, Cylinder, Solid
from .mission.sim import (TRACTOR_HEIGHT_M, TRACTOR_LENGTH_M, TRACTOR_WIDTH_M, WALKER_HEIGHT_M,
                          WALKER_RADIUS_M, MoverConfig)


@dataclass(frozen=True, slots=True)
class MoverPose:
    """Where a mover is: centre (ENU x, y, m), heading (rad, ENU from east,
    counter-clockwise) and velocity (ENU, m/s)."""

    x_m: float
    y_m: float
    heading_rad: float
    vx_m_s: float
    vy_m_s: float


def path_length_m(cfg: MoverConfig) -> float:
    """Total length (m) of the mover's polyline."""
    return sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(cfg.path, cfg.path[1:]))


def mover_pose(cfg: MoverConfig, t_s: float) -> MoverPose:
    """The mover's pose at vehicle time ``t_s`` (s); see the module notes."""
    path = cfg.path
    total = path_length_m(cfg)
    d = cfg.speed_m_s * max(0.0, float(t_s) - cfg.start_s)
    back = False
    if cfg.loop:
        d = math.fmod(d, 2.0 * total)
        if d > total:
            d, back = 2.0 * total - d, True
        moving = t_s > cfg.start_s
    else:
        moving = cfg.start_s < t_s and d < total
        d = min(d, total)
    s = 0.0
    for a, b in zip(path, path[1:]):
        seg = math.hypot(b[0] - a[0], b[1] - a[1])
        if d <= s + seg or b is path[-1]:
            f = min(1.0, max(0.0, (d - s) / seg))
            ux, uy = (b[0] - a[0]) / seg, (b[1] - a[1]) / seg
            if back:
                ux, uy = -ux, -uy
            v = cfg.speed_m_s if moving else 0.0
            return MoverPose(a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), math.atan2(uy, ux),
                             v * ux, v * uy)
        s += seg
    raise AssertionError("unreachable: the last segment always returns")


def mover_solid(cfg: MoverConfig, pose: MoverPose, base_z_m: float) -> Solid:
    """The mover's solid at ``pose`` standing at ``base_z_m`` (terrain under its centre):
    a walker a vertical cylinder, a tractor a box long along its heading."""
    if cfg.type == "walker":
        return Cylinder(pose.x_m, pose.y_m, base_z_m, base_z_m + WALKER_HEIGHT_M, WALKER_RADIUS_M)
    return Box(pose.x_m, pose.y_m, base_z_m, base_z_m + TRACTOR_HEIGHT_M, 0.5 * TRACTOR_LENGTH_M,
               0.5 * TRACTOR_WIDTH_M, pose.heading_rad)


def movers_nearest(movers: tuple[MoverConfig, ...], t_s: float, height, px: float, py: float,
                   pz: float) -> tuple[float, int | None]:
    """(signed distance m, index in ``movers``) of the nearest mover at time ``t_s``
    to the point (ENU); (inf, None) without movers. ``height(x, y)``: terrain (m)."""
    best, k = math.inf, None
    for i, cfg in enumerate(movers):
        pose = mover_pose(cfg, t_s)
        d = mover_solid(cfg, pose, float(height(pose.x_m, pose.y_m))).signed_distance_m(px, py, pz)
        if d < best:
            best, k = d, i
    return best, k
