"""The onboard controller's collision prevention, as PX4's (``CP_DIST``,
``CP_DELAY``, ``CP_GO_NO_DATA``), fed by OBSTACLE_DISTANCE.

Pure and stateful; timed by the vehicle clock its owner hands it (the time
a message arrived, ``on_sectors``, and the time now, ``set_time``), so data
that aged while another controller flew is not taken for fresh. Horizontal
only, world ENU / body FLU:

- a sector (centre azimuth a_i in body FLU, horizontal distance d_i) allows
  the speed toward it from which the vehicle stops ``CP_DIST`` short of the
  obstacle, braking at ``MPC_ACC_HOR`` = A after a delay tau = ``CP_DELAY``::

      v_i = A (-tau + sqrt(tau^2 + 2 max(d_i - CP_DIST, 0) / A))

  (the largest v with v tau + v^2 / (2 A) <= d_i - CP_DIST);
- the velocity setpoint v_sp (after the position loop and the speed limits)
  keeps its direction and is scaled down until its component toward every
  sector within 90 deg of it is at most that sector's v_i: |v| cos(theta_i)
  <= v_i, theta_i the angle between v_sp and a_i (PX4's
  ``CollisionPrevention::_calculateConstrainedSetpoint`` does the same);
- no data: with ``CP_GO_NO_DATA = 0`` a setpoint whose direction lies in a
  sector marked unknown, or in no sector, or any setpoint when the last
  OBSTACLE_DISTANCE is older than ``max_age_s`` (PX4: 0.5 s), is stopped;
  with 1 it is left alone;
- ``CP_DIST < 0`` switches it off (PX4's default).

While it limits, the horizontal acceleration feed-forward is dropped too
(``limit`` says so): the feed-forward of a trajectory that runs into the
obstacle would otherwise push on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CollisionPreventionConfig:
    """PX4 parameters (SI): ``CP_DIST`` (m, < 0 off), ``CP_DELAY`` (s),
    ``CP_GO_NO_DATA``, ``MPC_ACC_HOR`` (m/s^2), and the age (s of vehicle
    time) after which OBSTACLE_DISTANCE counts as no data."""

    dist_m: float = -1.0
    delay_s: float = 0.4
    go_no_data: bool = False
    accel_m_s2: float = 3.0
    max_age_s: float = 0.5

    @property
    def enabled(self) -> bool:
        return self.dist_m >= 0.0


def allowed_speed_m_s(distance_m, cfg: CollisionPreventionConfig):
    """Speed (m/s) toward an obstacle ``distance_m`` away that stops ``cfg.dist_m``
    short of it (module docstring); numpy-broadcast, inf for an infinite distance."""
    d = np.asarray(distance_m, dtype=float)
    room = np.maximum(d - cfg.dist_m, 0.0)
    a, tau = cfg.accel_m_s2, cfg.delay_s
    with np.errstate(invalid="ignore"):
        v = a * (-tau + np.sqrt(tau * tau + 2.0 * room / a))
    return np.where(np.isinf(d), math.inf, v)


class CollisionPrevention:
    """Holds the last OBSTACLE_DISTANCE and limits velocity setpoints (module docstring)."""

    def __init__(self, cfg: CollisionPreventionConfig = CollisionPreventionConfig()) -> None:
        self.cfg = cfg
        self._msg_us: int | None = None
        self._now_us = 0
        self._sectors = None
        self._obstacles: list[tuple[float, float]] = []   # (azimuth FLU rad, allowed speed m/s)
        self._unknown: list[float] = []                   # azimuths of unknown sectors
        self._covered = None                              # (sector centres, half width)
        self.n_messages = 0
        self.n_limited = 0

    def configure(self, cfg: CollisionPreventionConfig) -> None:
        self.cfg = cfg
        if self._sectors is not None:
            self.on_sectors(self._sectors, keep_age=True)

    @property
    def age_s(self) -> float:
        """Vehicle time (s) since the last OBSTACLE_DISTANCE; inf before the first."""
        return math.inf if self._msg_us is None else (self._now_us - self._msg_us) * 1e-6

    def set_time(self, now_us: int) -> None:
        """The vehicle clock now (us)."""
        self._now_us = int(now_us)

    def on_sectors(self, sectors, now_us: int | None = None, keep_age: bool = False) -> None:
        """A decoded OBSTACLE_DISTANCE (``mavcore.codec.ObstacleSectors``) received at
        ``now_us`` (vehicle clock; default: the time last set): the new picture."""
        self._sectors = sectors
        d = np.asarray(sectors.distance_m, dtype=float)
        az = np.asarray(sectors.azimuth_flu_rad, dtype=float)
        known = np.isfinite(d)
        v = allowed_speed_m_s(np.where(known, d, 0.0), self.cfg)
        self._obstacles = [(float(a), float(s)) for a, s in zip(az[known], v[known])]
        self._unknown = [float(a) for a in az[np.isnan(d)]]
        self._covered = (az, sectors.half_width_rad)
        if not keep_age:
            if now_us is not None:
                self._now_us = int(now_us)
            self._msg_us = self._now_us
            self.n_messages += 1

    def _no_data(self, az: float) -> bool:
        if self._sectors is None or self.age_s > self.cfg.max_age_s:
            return True
        centres, half = self._covered
        off = np.abs((centres - az + math.pi) % (2.0 * math.pi) - math.pi)
        inside = off <= half + 1e-12
        if not inside.any():
            return True
        return bool(np.all(np.isnan(np.asarray(self._sectors.distance_m)[inside])))

    def limit(self, vx: float, vy: float, yaw_enu_rad: float, dt_s: float = 0.0) -> tuple[float, float, bool]:
        """The velocity setpoint (ENU m/s, horizontal) allowed now, and whether it was limited.

        ``yaw_enu_rad``: the vehicle's heading (body x from east, CCW);
        ``dt_s``: the controller's step (unused: the data's age comes from ``set_time``).
        """
        cfg = self.cfg
        speed = math.hypot(vx, vy)
        if not cfg.enabled or speed <= 1e-9:
            return vx, vy, False
        az = math.atan2(vy, vx) - yaw_enu_rad                 # direction of the setpoint, body FLU
        if not cfg.go_no_data and self._no_data(az):
            self.n_limited += 1
            return 0.0, 0.0, True
        if self._sectors is None or self.age_s > cfg.max_age_s:
            return vx, vy, False                               # no data, allowed to go
        vmax = speed
        for a_i, v_i in self._obstacles:
            c = math.cos(az - a_i)
            if c > 1e-9 and v_i < vmax * c:
                vmax = v_i / c
        if vmax >= speed:
            return vx, vy, False
        self.n_limited += 1
        k = vmax / speed
        return vx * k, vy * k, True
