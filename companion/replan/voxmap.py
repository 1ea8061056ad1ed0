"""A persistent 3-D map of unknown obstacles from DISTANCE_SENSOR evidence (ENU, m).

Voxels of edge ``voxel_m`` (the cell of a point is ``floor(p / voxel_m)``)
carry a hit/miss log-odds ``l`` (Thrun et al., *Probabilistic Robotics*,
eq. 9.7; OctoMap's clamped update):

- a return unexplained by the known map adds ``L_HIT`` to its voxel (a
  candidate position across a wide field of view ``L_CANDIDATE``: one beam
  through it removes it), clamped to ``L_MAX``;
- a beam removes ``L_MISS`` from every stored voxel in the part of it that it
  surely saw free, short of its return by ``clear_margin_m``: the voxels its
  axis traverses (an exact segment-box test, the traversal of Amanatides &
  Woo restricted to the stored voxels) and, for a wide beam, the voxels
  whose point (the first return seen in it) lies in the inner cone
  (``CLEAR_FOV_FRACTION`` of each half-angle, widened by half a voxel: a
  small object at the edge of a wide field is not surely seen). A voxel only
  ever hit as a candidate (never on an axis) is cleared by the whole cone
  widened likewise: it was a guess, and any beam whose
  field holds it short of its return says the guess was wrong. A voxel whose
  log-odds reaches 0 is deleted.

Nothing else clears a voxel hit on a beam's axis (*confirmed*): not time,
not a re-route, not the vehicle flying away. A voxel is *occupied* while
stored (l > 0). The one exception is a wide beam's edge *candidate* (where
the return may also lie, ``perception.BeamEvidence.fan_hits``): it is a
hypothesis, not a measurement of that voxel, and beams that see the obstacle
itself never clear it (they return at its range), so an unconfirmed
candidate lapses ``CANDIDATE_LIFETIME_S`` (vehicle time) after its last
sighting (``expire_candidates``); an axis hit in its voxel confirms it for
good.

Memory bound: only voxels that returned a hit are stored, and every hit is
a surface within the sensors' maximum range of the flown path, so the
number of voxels is at most the number of voxels within ``max_range`` of
the area flown, below the ceiling: ``(A_flown + 2 r L + pi r^2) H / v^3``
for a path of length L sweeping area A, range r, height H. Flying the same
area again re-hits the same voxels (a dict keyed by voxel index) and adds
nothing; the flight's duration does not enter. A hard cap ``MAX_VOXELS``
(refusing new voxels, counted in ``dropped``) guards against a sensor
that floods the map.

``distance(points)`` is the query for the guard (``companion.safety``): the
Euclidean distance from each point to the nearest occupied voxel's surface
(its box), through a k-d tree of the voxel centres; never above the true
distance, at most half a voxel diagonal below it (``exact=True``: exact).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

#: Log-odds added by a return on the axis.
L_HIT = 1.0
#: Log-odds added by a candidate position of a wide beam's return (edge of its field of view).
L_CANDIDATE = 0.5
#: Log-odds removed by a beam through the voxel.
L_MISS = 1.0
#: Upper clamp: a voxel hit many times needs this many misses (in L_MISS) to clear.
L_MAX = 3.0
#: A wide beam clears the inner cone: this fraction of each half field of view.
CLEAR_FOV_FRACTION = 0.5
#: An unconfirmed candidate lapses this long (s, vehicle time) after its last sighting.
CANDIDATE_LIFETIME_S = 1.0
#: Hard cap on stored voxels (a flooding sensor; the bound of the module doc is far below).
MAX_VOXELS = 200_000
#: Nearest voxel centres examined per query point (``distance``).
K_NEAR = 8
#: With ``exact=True``, further stages for the points the previous did not settle.
_K_EXACT = (64, 1 << 62)
#: Side (m) of the horizontal squares whose points' boxes ``clear_beam`` tests a beam against.
GROUP_M = 1.0
#: ``distance`` of at most this many (point, voxel) pairs is brute force (``_distance_small``):
#: the k-d tree's query costs ~50 us whatever its size, the guard's per-frame two points
#: against a few hundred voxels ~10-40 us this way.
SMALL_PAIRS = 512
#: ... and so is a query of at most this many points while the tree is not built (the map
#: changed since the last query that built it): building costs ~0.13 us a voxel (130 us for
#: a thousand), brute force ~0.023 us a pair, so up to ~5 points brute force is cheaper
#: whatever the map's size (a few points against 3000 voxels: 117 us against 700 us).
FEW_POINTS = 4


class ObstacleMap:
    """Sparse log-odds voxel map of unknown obstacles (module doc).

    Parameters
    ----------
    voxel_m : float
        Voxel edge (m).
    clear_margin_m : float
        A beam clears voxels closer than its return minus this margin (m).
    max_voxels : int
        Hard cap on stored voxels.
    """

    def __init__(self, voxel_m: float, clear_margin_m: float = 0.15, max_voxels: int = MAX_VOXELS) -> None:
        if not (math.isfinite(voxel_m) and voxel_m > 0.0):
            raise ValueError(f"voxel_m must be > 0, got {voxel_m}")
        self.voxel_m = float(voxel_m)
        self.clear_margin_m = float(clear_margin_m)
        self.max_voxels = int(max_voxels)
        self._l: dict[tuple[int, int, int], float] = {}
        #: the first return seen in each voxel (the voxel's point: it does not creep with the
        #: sensor, a beam climbing a face would otherwise drag it up to the top)
        self._first: dict[tuple[int, int, int], tuple[float, float, float]] = {}
        self._confirmed: set[tuple[int, int, int]] = set()
        self._cand_until: dict[tuple[int, int, int], float] = {}
        self.dropped = 0
        self.version = 0
        self._cache_v = -1
        self._centres = np.zeros((0, 3))
        self._points = np.zeros((0, 3))
        self._keys = np.zeros((0, 3), dtype=np.int64)
        self._tree: cKDTree | None = None
        self._conf = np.zeros(0, dtype=bool)
        #: clear_beam's broad phase: per GROUP_M square (x, y index), the box [x0, y0, z0, x1, y1, z1]
        #: of the points ever stored in it (grown by ``add``, never shrunk: a cover of the
        #: points, however many were deleted since; bounded by the area flown, as the voxels)
        self._groups: dict[tuple[int, int], list[float]] = {}

    # --- contents ----------------------------------------------------------------------

    def __len__(self) -> int:
        return len(self._l)

    def key_of(self, point) -> tuple[int, int, int]:
        """Voxel index of an ENU point (m)."""
        v = self.voxel_m
        return (math.floor(point[0] / v), math.floor(point[1] / v), math.floor(point[2] / v))

    def log_odds(self, point) -> float:
        """Log-odds of the voxel holding ``point`` (0: never hit, or cleared)."""
        return self._l.get(self.key_of(point), 0.0)

    def _refresh(self) -> None:
        if self._cache_v == self.version:
            return
        if self._l:
            self._keys = np.array(list(self._l.keys()), dtype=np.int64).reshape(-1, 3)
            self._centres = (self._keys + 0.5) * self.voxel_m
            self._points = np.array([self._first[k] for k in self._l], dtype=float).reshape(-1, 3)
            self._tree = None          # built on the first query that needs it (``distance``)
            self._conf = np.fromiter((k in self._confirmed for k in self._l), dtype=bool, count=len(self._l))
            self._box = (*self._points.min(axis=0).tolist(), *self._points.max(axis=0).tolist())
        else:
            self._conf = np.zeros(0, dtype=bool)
            self._keys = np.zeros((0, 3), dtype=np.int64)
            self._centres = np.zeros((0, 3))
            self._points = np.zeros((0, 3))
            self._tree = None
        self._cache_v = self.version

    def points(self) -> np.ndarray:
        """(k, 3) the occupied voxels' points (ENU m; the first return seen in each, inside
        it; a cached array, do not modify)."""
        self._refresh()
        return self._points

    def points_lower_bound(self, p) -> float:
        """A lower bound (m) on the distance from the ENU point ``p`` to every point of
        ``points()`` (inf when the map is empty): its distance to their bounding box, less
        a nanometre. Each coordinate difference to a point is at least the one to the box
        (rounding is monotone), so the bound holds for distances computed in any order."""
        self._refresh()
        if not self._l:
            return math.inf
        x0, y0, z0, x1, y1, z1 = self._box
        x, y, z = float(p[0]), float(p[1]), float(p[2])
        ex = x0 - x if x < x0 else (x - x1 if x > x1 else 0.0)
        ey = y0 - y if y < y0 else (y - y1 if y > y1 else 0.0)
        ez = z0 - z if z < z0 else (z - z1 if z > z1 else 0.0)
        return math.sqrt(ex * ex + ey * ey + ez * ez) - 1e-9

    def keys(self) -> np.ndarray:
        """(k, 3) int voxel indices of the occupied voxels, in the order of ``points``."""
        self._refresh()
        return self._keys

    def confirmed(self) -> np.ndarray:
        """(k,) bool, in the order of ``points``: hit on a beam's axis (not only as a
        wide beam's edge candidate)."""
        self._refresh()
        return self._conf

    # --- evidence ----------------------------------------------------------------------

    def add(self, point, weight: float = L_HIT, t_s: float = 0.0) -> None:
        """A return at ``point`` (ENU m): ``weight`` log-odds (``L_HIT`` on the axis,
        ``L_CANDIDATE`` for a field-of-view edge candidate, seen at vehicle time ``t_s``)."""
        key = self.key_of(point)
        old = self._l.get(key)
        if old is None:
            if len(self._l) >= self.max_voxels:
                self.dropped += 1
                return
            self.version += 1
            q = self._first[key] = (float(point[0]), float(point[1]), float(point[2]))
            g = (math.floor(q[0] / GROUP_M), math.floor(q[1] / GROUP_M))
            b = self._groups.get(g)
            if b is None:
                self._groups[g] = [*q, *q]
            else:
                for i in range(3):
                    if q[i] < b[i]:
                        b[i] = q[i]
                    if q[i] > b[3 + i]:
                        b[3 + i] = q[i]
        self._l[key] = min(L_MAX, (old or 0.0) + float(weight))
        if weight >= L_HIT:
            if key not in self._confirmed:
                self._confirmed.add(key)
                self._cand_until.pop(key, None)
                self.version += 1
        elif key not in self._confirmed:
            self._cand_until[key] = max(self._cand_until.get(key, -math.inf), float(t_s) + CANDIDATE_LIFETIME_S)

    def clear_beam(self, ev) -> int:
        """A miss for every stored voxel in the surely free part of a beam
        (``perception.BeamEvidence``; module doc); returns how many voxels were
        deleted."""
        if not self._l:
            return 0
        reach = ev.free_m - self.clear_margin_m
        if reach <= 0.0:
            return 0
        # most beams pass far from every voxel: a scalar test of the beam's bounding box
        # (its axis, widened by the cone at its reach and a voxel) against the boxes of
        # the points in each GROUP_M square (kept by ``add``: no refresh of the arrays,
        # which the map's changes would otherwise rebuild for every beam), then against
        # the box of all the points
        w = reach * math.tan(max(ev.half_h_rad, ev.half_v_rad)) + 2.0 * self.voxel_m
        lo, hi = [], []
        for i in range(3):
            a, b = ev.origin[i], ev.origin[i] + reach * ev.axis[i]
            lo.append(min(a, b) - w)
            hi.append(max(a, b) + w)
        x0, y0, z0 = lo
        x1, y1, z1 = hi
        for g in self._groups.values():
            if not (x0 > g[3] or x1 < g[0] or y0 > g[4] or y1 < g[1] or z0 > g[5] or z1 < g[2]):
                break
        else:
            return 0
        self._refresh()
        box = self._box
        for i in range(3):
            if lo[i] > box[3 + i] or hi[i] < box[i]:
                return 0
        o = np.asarray(ev.origin, dtype=float)
        h = 0.5 * self.voxel_m
        hit = _segment_hits_boxes(o, np.asarray(ev.axis, dtype=float), reach, self._centres, h)
        if ev.half_h_rad > 0.0 or ev.half_v_rad > 0.0:
            # the voxel's point in the cone (a candidate: the whole cone; a confirmed
            # voxel: the inner one), widened by half a voxel (a fan beam's zero field
            # is a sheet through the voxel)
            rel = (self._points - o) @ np.array([ev.axis, ev.h_axis, ev.v_axis], dtype=float).T
            along = rel[:, 0]
            f = np.where(self._conf, CLEAR_FOV_FRACTION, 1.0)[:, None]
            width = along[:, None] * np.tan(f * np.array([ev.half_h_rad, ev.half_v_rad])) + h
            hit |= (along > 0.0) & (along < reach) & np.all(np.abs(rel[:, 1:]) <= width, axis=1)
        idx = np.flatnonzero(hit)
        gone = 0
        for i in idx.tolist():
            key = tuple(int(c) for c in self._keys[i])
            left = self._l[key] - L_MISS
            if left <= 1e-12:
                del self._l[key]
                del self._first[key]
                self._confirmed.discard(key)
                self._cand_until.pop(key, None)
                gone += 1
            else:
                self._l[key] = left
        if gone:
            self.version += 1
        return gone

    def expire_candidates(self, t_s: float) -> int:
        """Delete the unconfirmed candidates not seen since ``t_s - CANDIDATE_LIFETIME_S``
        (module doc); returns how many. Confirmed voxels are never touched."""
        if not self._cand_until:
            return 0
        gone = [k for k, until in self._cand_until.items() if until < t_s]
        for k in gone:
            del self._cand_until[k]
            self._l.pop(k, None)
            self._first.pop(k, None)
        if gone:
            self.version += 1
        return len(gone)

    # --- queries -----------------------------------------------------------------------

    def distance(self, points: np.ndarray, exact: bool = False) -> np.ndarray:
        """(M,) distance (m) from each ENU point ((M, 3)) to the surface of the nearest
        occupied voxel (0 inside one; inf when the map is empty).

        A voxel beyond the k = ``K_NEAR`` nearest centres is at least ``c_k - s``
        away (c_k the k-th centre distance, s half the voxel diagonal), so the
        answer is ``min(minimum over the k nearest boxes, c_k - s)``: never more
        than the true distance (safe for a guard), and at most s below it (only
        beside a surface wider than the k voxels, e.g. a wall). ``exact=True``
        does the points where the bound decided again with more centres, up to
        all of them (slower; the tests' reference)."""
        P = np.asarray(points, dtype=float).reshape(-1, 3)
        self._refresh()
        n = len(self._centres)
        if n == 0 or len(P) == 0:
            return np.full(len(P), math.inf)
        h = 0.5 * self.voxel_m
        s = math.sqrt(3.0) * h
        if not exact and (n * len(P) <= SMALL_PAIRS or (self._tree is None and len(P) <= FEW_POINTS)):
            return _distance_small(P, self._centres, h, s)
        out = np.full(len(P), math.inf)
        todo = np.arange(len(P))
        for k in (K_NEAR, *_K_EXACT) if exact else (K_NEAR,):
            k = min(k, n)
            if self._tree is None:
                self._tree = cKDTree(self._centres)
            dc, ii = self._tree.query(P[todo], k=k)
            dc, ii = dc.reshape(len(todo), k), ii.reshape(len(todo), k)
            b = _box_distance(P[todo][:, None, :], self._centres[ii], h).min(axis=1)
            if k == n:
                out[todo] = b
                return out
            # voxels beyond the k nearest centres are at least c_k - s away (s: half the diagonal)
            lower = dc[:, -1] - s
            sure = lower >= b
            out[todo] = np.minimum(b, lower)
            todo = todo[~sure]
            if len(todo) == 0:
                return out
        return out


def _distance_small(P: np.ndarray, c: np.ndarray, h: float, s: float) -> np.ndarray:
    """``ObstacleMap.distance`` (not exact) by brute force over all n voxels, the same
    numbers: every voxel beyond the k nearest centres is at least c_k - s from the point,
    so the minimum over all boxes and c_k - s is the minimum over the k nearest boxes and
    c_k - s; c_k is the k-th smallest centre distance, summed in the k-d tree's order
    (x, y, z) and rooted as it does."""
    d = P[:, None, :] - c[None, :, :]
    q = np.maximum(np.abs(d) - h, 0.0)
    q *= q
    b = np.sqrt(q[..., 0] + q[..., 1] + q[..., 2]).min(axis=1)
    if len(c) <= K_NEAR:
        return b
    d *= d
    c2 = d[..., 0] + d[..., 1] + d[..., 2]
    ck = np.sqrt(np.partition(c2, K_NEAR - 1, axis=1)[:, K_NEAR - 1])
    return np.minimum(b, ck - s)


def _box_distance(p: np.ndarray, c: np.ndarray, h: float) -> np.ndarray:
    """Distance from points p to the axis-aligned boxes of half-edge h centred at c (broadcast)."""
    q = np.maximum(np.abs(p - c) - h, 0.0)
    return np.sqrt(np.sum(q * q, axis=-1))


def _segment_hits_boxes(o: np.ndarray, u: np.ndarray, length: float, c: np.ndarray, h: float) -> np.ndarray:
    """(k,) the segment o + s u, 0 <= s <= length, passes through the box of
    half-edge h centred at each c (slab test)."""
    # a zero component: the slab's parameters are +-huge (the sign of the offset), so the
    # slab admits the whole segment exactly when the origin lies inside it
    inv = 1.0 / np.where(np.abs(u) < 1e-12, 1e-300, u)
    t0 = (c - h - o) * inv
    t1 = (c + h - o) * inv
    lo = np.maximum(np.minimum(t0, t1).max(axis=1), 0.0)
    hi = np.minimum(np.maximum(t0, t1).min(axis=1), float(length))
    return lo <= hi
