"""The geofence uploaded with MAV_MISSION_TYPE_FENCE, as geometry (pure).

Items (MAVLink common.xml; PX4 https://docs.px4.io/main/en/flying/geofence.html):

- NAV_FENCE_POLYGON_VERTEX_INCLUSION (5001) / _EXCLUSION (5002): one vertex
  each, param1 = the polygon's vertex count; a polygon is that many
  consecutive items of the same command.
- NAV_FENCE_CIRCLE_INCLUSION (5003) / _EXCLUSION (5004): param1 = radius (m).
- NAV_FENCE_RETURN_POINT (5000): accepted and ignored (fixed-wing).

The vehicle breaches the fence when it is inside any exclusion area, or
when there is at least one inclusion area and it is inside none of them
(PX4's reading of several fences). Horizontal only: the fence altitude
limits (GF_MAX_VER_DIST) are not simulated. World ENU metres throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

FENCE_RETURN_POINT = 5000
POLYGON_INCLUSION = 5001
POLYGON_EXCLUSION = 5002
CIRCLE_INCLUSION = 5003
CIRCLE_EXCLUSION = 5004
FENCE_COMMANDS = frozenset({FENCE_RETURN_POINT, POLYGON_INCLUSION, POLYGON_EXCLUSION,
                            CIRCLE_INCLUSION, CIRCLE_EXCLUSION})


class FenceError(ValueError):
    """A fence list that does not describe closed areas (why in the message)."""


@dataclass(frozen=True)
class Fence:
    """Inclusion and exclusion areas, world ENU (m).

    Attributes
    ----------
    inclusion_polygons, exclusion_polygons : tuple of tuple of (x, y)
    inclusion_circles, exclusion_circles : tuple of (x, y, radius_m)
    """

    inclusion_polygons: tuple = ()
    exclusion_polygons: tuple = ()
    inclusion_circles: tuple = ()
    exclusion_circles: tuple = ()

    @property
    def empty(self) -> bool:
        return not (self.inclusion_polygons or self.exclusion_polygons or self.inclusion_circles
                    or self.exclusion_circles)

    def breached(self, x: float, y: float) -> bool:
        """True if the point (ENU, m) is outside the allowed area."""
        if any(point_in_polygon(x, y, p) for p in self.exclusion_polygons):
            return True
        if any(math.hypot(x - cx, y - cy) < r for cx, cy, r in self.exclusion_circles):
            return True
        if not (self.inclusion_polygons or self.inclusion_circles):
            return False
        return not (any(point_in_polygon(x, y, p) for p in self.inclusion_polygons)
                    or any(math.hypot(x - cx, y - cy) <= r for cx, cy, r in self.inclusion_circles))


def point_in_polygon(x: float, y: float, poly: Sequence) -> bool:
    """Even-odd rule (W. R. Franklin's crossing test) for a closed polygon
    given by its vertices (no repeated first vertex needed)."""
    inside = False
    n = len(poly)
    xj, yj = poly[n - 1]
    for i in range(n):
        xi, yi = poly[i]
        if (yi > y) != (yj > y) and x < (xj - xi) * (y - yi) / (yj - yi) + xi:
            inside = not inside
        xj, yj = xi, yi
    return inside


def fence_from_items(items: Sequence, item_xy: Callable) -> Fence:
    """Stored fence ``MissionItem``s -> ``Fence``; ``item_xy(item)``: the
    item's ENU (x, y, ...) or None. Raises FenceError naming the first bad item."""
    inc_p, exc_p, inc_c, exc_c = [], [], [], []
    i, n = 0, len(items)
    while i < n:
        it = items[i]
        cmd = int(it.command)
        if cmd not in FENCE_COMMANDS:
            raise FenceError(f"fence item {i}: command {cmd} is not a fence item")
        if cmd == FENCE_RETURN_POINT:
            i += 1
            continue
        pos = item_xy(it)
        if pos is None:
            raise FenceError(f"fence item {i}: no position")
        if cmd in (CIRCLE_INCLUSION, CIRCLE_EXCLUSION):
            r = float(it.param1)
            if not (math.isfinite(r) and r > 0):
                raise FenceError(f"fence item {i}: circle radius {r:g}")
            (inc_c if cmd == CIRCLE_INCLUSION else exc_c).append((pos[0], pos[1], r))
            i += 1
            continue
        count = float(it.param1)
        if not (math.isfinite(count) and count == int(count) and count >= 3):
            raise FenceError(f"fence item {i}: polygon vertex count {count:g} (at least 3)")
        count = int(count)
        run = items[i:i + count]
        if len(run) < count or any(int(v.command) != cmd or float(v.param1) != count for v in run):
            raise FenceError(f"fence item {i}: polygon of {count} vertices is not {count} such items")
        verts = []
        for v in run:
            q = item_xy(v)
            if q is None:
                raise FenceError(f"fence item {v.seq}: no position")
            verts.append((float(q[0]), float(q[1])))
        (inc_p if cmd == POLYGON_INCLUSION else exc_p).append(tuple(verts))
        i += count
    return Fence(tuple(inc_p), tuple(exc_p), tuple(inc_c), tuple(exc_c))
