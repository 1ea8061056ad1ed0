"""The SITL's moving obstacles (``sim.movers``): their solids at the current
vehicle time for the rangefinders, and the swept contact of the vehicle
sphere with them for the crash check.

Pure state machine: ``set_time`` moves every mover to its pose at a time of
the vehicle clock (``mavcore.movers.mover_pose``); nothing reads a wall
clock. ``current`` holds ``sitl.world.Obstacle`` objects (the exact
field-of-view pass of ``sitl.fov`` and the ray casts use them as they use the
static obstacles).

Swept contact
-------------
Over one sensor frame the vehicle's centre moves ``p0 -> p1`` and a mover
``m0 -> m1`` (a straight step: its speed is constant within a path segment,
and a 4 ms frame at 1.5 m/s moves it 6 mm). In the mover's frame the vehicle
moves along the chord ``p0 - (m0 - m1) -> p1`` against the solid at ``m1``
(exact for a translation; a turn of the path at a corner within one frame
is neglected). Contact is found along that chord by conservative advancement
on the solid's signed distance (1-Lipschitz), as ``sitl.collision`` does.
"""

from __future__ import annotations

import math

from mavcore.mission.sim import (MoverConfig, ObstacleConfig, TRACTOR_HEIGHT_M, TRACTOR_LENGTH_M, TRACTOR_WIDTH_M,
                                 WALKER_HEIGHT_M, WALKER_RADIUS_M)
from mavcore.movers import MoverPose, mover_pose, mover_solid

_CONTACT_EPS_M = 1e-6
_MAX_ITERS = 200


def obstacle_config_at(cfg: MoverConfig, pose: MoverPose) -> ObstacleConfig:
    """The mover at ``pose`` as a static obstacle (``sim.obstacles`` form)."""
    if cfg.type == "walker":
        return ObstacleConfig("cylinder", pose.x_m, pose.y_m, WALKER_HEIGHT_M, radius=WALKER_RADIUS_M)
    return ObstacleConfig("box", pose.x_m, pose.y_m, TRACTOR_HEIGHT_M, size_x=TRACTOR_LENGTH_M,
                          size_y=TRACTOR_WIDTH_M, yaw_deg=math.degrees(pose.heading_rad))


class MovingObstacles:
    """The movers of one world, posed at the last ``set_time``.

    Parameters
    ----------
    movers : tuple of MoverConfig
        ``sim.movers``.
    terrain : sitl.world.Terrain
        Movers stand on it under their centre.
    obstacle_cls : type
        ``sitl.world.Obstacle`` (passed in: no import cycle).
    """

    def __init__(self, movers: tuple[MoverConfig, ...], terrain, obstacle_cls) -> None:
        self.movers = tuple(movers)
        self.terrain = terrain
        self._cls = obstacle_cls
        self.time_s = math.nan
        self.current: tuple = ()
        self.set_time(0.0)

    def set_time(self, t_s: float) -> None:
        """Pose every mover at vehicle time ``t_s`` (s since boot)."""
        if t_s == self.time_s:
            return
        self.time_s = t_s
        self.current = tuple(self._cls(obstacle_config_at(c, mover_pose(c, t_s)), self.terrain)
                             for c in self.movers)

    def solid_at(self, k: int, t_s: float):
        """The solid (``mavcore.geometry``) of mover ``k`` at time ``t_s``."""
        cfg = self.movers[k]
        pose = mover_pose(cfg, t_s)
        return pose, mover_solid(cfg, pose, self.terrain.height(pose.x_m, pose.y_m))

    def sweep(self, p0, p1, t0_s: float, t1_s: float, radius_m: float):
        """First contact over a frame: (fraction of the chord, mover index) or None.

        The vehicle centre moves ``p0 -> p1`` (ENU, m) while the vehicle clock
        runs ``t0_s -> t1_s``; the sphere of ``radius_m`` against every mover
        (module notes, relative motion)."""
        best = None
        for k in range(len(self.movers)):
            pose0, _ = self.solid_at(k, t0_s)
            pose1, solid = self.solid_at(k, t1_s)
            sx = p0[0] - (pose0.x_m - pose1.x_m)
            sy = p0[1] - (pose0.y_m - pose1.y_m)
            sz = p0[2]
            dx, dy, dz = p1[0] - sx, p1[1] - sy, p1[2] - sz
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
            if solid.signed_distance_m(p1[0], p1[1], p1[2]) - length > radius_m:
                continue                      # 1-Lipschitz: nothing of the chord is that near
            ux, uy, uz = (dx / length, dy / length, dz / length) if length > 0.0 else (0.0, 0.0, 0.0)
            t = 0.0
            for _ in range(_MAX_ITERS):
                gap = solid.signed_distance_m(sx + ux * t, sy + uy * t, sz + uz * t) - radius_m
                if gap <= _CONTACT_EPS_M:
                    frac = t / length if length > 0.0 else 0.0
                    if best is None or frac < best[0]:
                        best = (frac, k)
                    break
                t += gap
                if t > length:
                    break
        return best
