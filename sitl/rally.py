"""Rally points (MAV_MISSION_TYPE_RALLY, NAV_RALLY_POINT 5100) and where
AUTO.RTL goes (pure).

PX4's multicopter return (RTL_TYPE 0, the default) flies "directly to the
closest safe landing point (a rally point or the home position)" and lands
there (https://docs.px4.io/main/en/flight_modes_mc/return.html). Closest is
horizontal distance from where the return starts; world ENU metres.
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

NAV_RALLY_POINT = 5100


class RallyError(ValueError):
    """A rally list with an item that is not a usable rally point."""


def rally_points_from_items(items: Sequence, item_enu: Callable) -> tuple:
    """Stored rally ``MissionItem``s -> tuple of ENU (x, y, z) points."""
    pts = []
    for i, it in enumerate(items):
        if int(it.command) != NAV_RALLY_POINT:
            raise RallyError(f"rally item {i}: command {int(it.command)} is not NAV_RALLY_POINT")
        p = item_enu(it)
        if p is None:
            raise RallyError(f"rally item {i}: no position")
        pts.append(tuple(float(v) for v in p))
    return tuple(pts)


def return_destination(pos_enu_m, home_enu_m, rally_points: Sequence) -> tuple[tuple, bool]:
    """(destination (x, y, z), is a rally point): the closest of home and
    the rally points to ``pos_enu_m``, horizontally; home wins a tie."""
    best = tuple(float(v) for v in home_enu_m)
    best_d = math.hypot(best[0] - pos_enu_m[0], best[1] - pos_enu_m[1])
    rally = False
    for p in rally_points:
        d = math.hypot(p[0] - pos_enu_m[0], p[1] - pos_enu_m[1])
        if d < best_d:
            best, best_d, rally = tuple(p), d, True
    return best, rally
