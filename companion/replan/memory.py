"""Short-lived local memory of unknown obstacle points (ENU, m).

One point per voxel (``voxel_m``): a new return in an occupied voxel
refreshes its time and keeps the point first seen there, so an obstacle
seen again and again does not grow the memory, and the point does not
creep with the sensor (a horizontal beam climbing a face would otherwise
drag the voxel's point up to the top, where the first beam over the top
clears it). Points are forgotten when

- not seen again for ``lifetime_s`` (decay, vehicle time; a shorter
  lifetime may be given per point: the replanner gives the candidate
  positions of a wide beam's return 1 s);
- farther than ``radius_m`` from the vehicle;
- inside a beam that is now free (clearing): a later reading's field of
  view holds the point short of its own return (by ``clear_margin_m``), so
  the obstacle moved, was a false return, or was one of the candidate
  positions of a wide beam's return that another beam shows to be free.
  A measured point (one kept the full lifetime) is cleared only by the
  inner part of the field of view (``CLEAR_FOV_FRACTION`` of each
  half-angle): a sensor does not see a small object at the edge of a wide
  field of view for sure (a real ToF reports the dominant return, the SITL
  the nearest of a few rays), and clearing the whole pyramid erased a
  0.33 m post's points seen a moment before by a beam that passed it at
  the edge (randomized SITL flight 43: passed at 0.39 m). A short-lived
  candidate is cleared by the whole pyramid;
- the capacity is reached (the oldest point goes first).

So a side sensor that stops seeing an obstacle beside the vehicle (its beam
now passes behind the obstacle) does not clear it: only time or a beam
through the point does. Memory is bounded by the capacity, whatever the
flight length.
"""

from __future__ import annotations

import math

import numpy as np

#: Clearing uses this fraction of each half field of view about the axis.
CLEAR_FOV_FRACTION = 0.5

#: Default capacity (points).
CAPACITY = 1024


class ObstacleMemory:
    """A bounded point set with decay and clearing (module doc).

    Parameters
    ----------
    voxel_m : float
        Voxel edge (m).
    lifetime_s : float
        Decay time (s).
    radius_m : float
        Forget points farther than this from the vehicle (m).
    clear_margin_m : float
        A beam clears points closer than its return minus this margin (m).
    capacity : int
    """

    def __init__(self, voxel_m: float, lifetime_s: float, radius_m: float,
                 clear_margin_m: float, capacity: int = CAPACITY) -> None:
        self.voxel_m = float(voxel_m)
        self.lifetime_s = float(lifetime_s)
        self.radius_m = float(radius_m)
        self.clear_margin_m = float(clear_margin_m)
        self.capacity = int(capacity)
        self._pts = np.zeros((self.capacity, 3))
        self._t = np.full(self.capacity, -math.inf)
        self._life = np.full(self.capacity, self.lifetime_s)
        self._key = [None] * self.capacity
        self._slots: dict[tuple, int] = {}
        self._free = list(range(self.capacity - 1, -1, -1))
        self._cache: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self._slots)

    def add(self, t_s: float, point, lifetime_s: float | None = None) -> None:
        """Remember a return at ``point`` (ENU m) seen at ``t_s``, for ``lifetime_s``
        (default the memory's) unless seen again; a voxel keeps the longest
        lifetime it was given."""
        life = self.lifetime_s if lifetime_s is None else float(lifetime_s)
        x, y, z = float(point[0]), float(point[1]), float(point[2])
        v = self.voxel_m
        key = (math.floor(x / v), math.floor(y / v), math.floor(z / v))
        i = self._slots.get(key)
        if i is None:
            if not self._free:
                self._drop(int(np.argmin(np.where(np.isfinite(self._t), self._t, math.inf))))
            i = self._free.pop()
            self._slots[key] = i
            self._key[i] = key
            self._pts[i] = (x, y, z)
            self._life[i] = life
            self._cache = None
        else:
            self._life[i] = max(self._life[i], life)
        self._t[i] = t_s

    def _drop(self, i: int) -> None:
        key = self._key[i]
        if key is not None:
            del self._slots[key]
            self._key[i] = None
            self._t[i] = -math.inf
            self._free.append(i)
            self._cache = None

    def _active(self) -> np.ndarray:
        return np.fromiter(self._slots.values(), dtype=np.intp, count=len(self._slots))

    def points(self) -> np.ndarray:
        """(k, 3) the remembered points (a cached array; do not modify)."""
        if self._cache is None:
            self._cache = self._pts[self._active()] if self._slots else np.zeros((0, 3))
        return self._cache

    def times(self) -> np.ndarray:
        """(k,) last-seen times of ``points()``, same order."""
        return self._t[self._active()] if self._slots else np.zeros(0)

    def clear_beam(self, ev) -> int:
        """Forget the points inside a free beam (``perception.BeamEvidence``): in its
        pyramid (half the fields of view about the axis; for a measured point,
        ``CLEAR_FOV_FRACTION`` of them; plus half a voxel) and
        short of ``free_m - clear_margin_m``; returns how many were forgotten."""
        if not self._slots:
            return 0
        reach = ev.free_m - self.clear_margin_m
        if reach <= 0.0:
            return 0
        idx = self._active()
        rel = self._pts[idx] - np.asarray(ev.origin, dtype=float)
        along = rel @ np.asarray(ev.axis, dtype=float)
        r = 0.5 * self.voxel_m
        inside = (along > 0.0) & (along < reach)
        f = np.where(self._life[idx] < self.lifetime_s, 1.0, CLEAR_FOV_FRACTION)
        inside &= np.abs(rel @ np.asarray(ev.h_axis, dtype=float)) <= along * np.tan(f * ev.half_h_rad) + r
        inside &= np.abs(rel @ np.asarray(ev.v_axis, dtype=float)) <= along * np.tan(f * ev.half_v_rad) + r
        gone = idx[inside]
        for i in gone.tolist():
            self._drop(i)
        return len(gone)

    def expire(self, t_s: float, center_enu_m) -> int:
        """Forget points older than the lifetime or farther than the radius; returns how many."""
        if not self._slots:
            return 0
        idx = self._active()
        rel = self._pts[idx] - np.asarray(center_enu_m, dtype=float)
        old = (self._t[idx] < t_s - self._life[idx]) | (np.einsum("ki,ki->k", rel, rel) > self.radius_m ** 2)
        gone = idx[old]
        for i in gone.tolist():
            self._drop(i)
        return len(gone)

    def forget(self, mask_fn) -> int:
        """Forget the points for which ``mask_fn(points) -> (k,) bool`` is True."""
        if not self._slots:
            return 0
        idx = self._active()
        gone = idx[np.asarray(mask_fn(self._pts[idx]), dtype=bool)]
        for i in gone.tolist():
            self._drop(i)
        return len(gone)
