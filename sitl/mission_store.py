"""From the stored MISSION_INT lists to what the flight stack flies (pure).

The transport (``sitl.server``) stores three lists with
``mavcore.services.mission.MissionServer``; this module checks a fence or rally list at
the end of its upload (``validator``), turns the stored lists into the
flight stack's ``MissionExecutor``, ``Fence`` and rally points
(``flight_objects``), and says what MISSION_CURRENT reports
(``mission_state``), and where a DO_REPOSITION goes
(``reposition_target``). Geodetic positions go through ``mavcore.codec``
(``mission_item_enu``), the SITL's one way in from WGS-84.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

from pymavlink.dialects.v20 import common as mavlink

from mavcore import codec
from mavcore.autopilot import MissionRules

from .fence import Fence, FenceError, fence_from_items
from .mission_exec import MissionExecutor, nav_items
from .rally import RallyError, rally_points_from_items


@dataclass(frozen=True)
class FlightObjects:
    """The stored lists as the flight stack uses them (None / (): none)."""

    mission: MissionExecutor | None
    fence: Fence | None
    rally_points: tuple


def item_enu_function(origin: codec.GeoOrigin, home_enu_m):
    """``item -> ENU (x, y, z) or None`` for this origin and home."""
    return partial(codec.mission_item_enu, origin, home_enu_m)


def validator(origin: codec.GeoOrigin, home_enu_m):
    """``validate(mission_type, items)`` for ``MissionServer``: a fence or
    rally list that is not usable is refused with MAV_MISSION_ERROR."""
    to_enu = item_enu_function(origin, home_enu_m)

    def validate(mission_type: int, items) -> tuple[int, str] | None:
        try:
            if mission_type == mavlink.MAV_MISSION_TYPE_FENCE:
                fence_from_items(items, to_enu)
            elif mission_type == mavlink.MAV_MISSION_TYPE_RALLY:
                rally_points_from_items(items, to_enu)
        except (FenceError, RallyError) as e:
            return mavlink.MAV_MISSION_ERROR, str(e)
        return None

    return validate


def flight_objects(stored: dict, origin: codec.GeoOrigin, home_enu_m, params,
                   rules: MissionRules = MissionRules()) -> FlightObjects:
    """``MissionServer.stored`` -> the executor (flying by the personality's
    ``rules``), the fence and the rally points."""
    to_enu = item_enu_function(origin, home_enu_m)
    items = stored[mavlink.MAV_MISSION_TYPE_MISSION]
    mission = MissionExecutor(nav_items(items, to_enu), params, home_enu_m, rules) if items else None
    fence_items = stored[mavlink.MAV_MISSION_TYPE_FENCE]
    fence = fence_from_items(fence_items, to_enu) if fence_items else None
    rally = rally_points_from_items(stored[mavlink.MAV_MISSION_TYPE_RALLY], to_enu)
    return FlightObjects(mission, None if fence is None or fence.empty else fence, rally)


def mission_state(mission: MissionExecutor | None, flying_it: bool) -> int:
    """MISSION_CURRENT.mission_state (MISSION_STATE)."""
    if mission is None:
        return mavlink.MISSION_STATE_NO_MISSION
    if mission.finished:
        return mavlink.MISSION_STATE_COMPLETE
    return mavlink.MISSION_STATE_ACTIVE if flying_it else mavlink.MISSION_STATE_NOT_STARTED


INT32_MAX = 2 ** 31 - 1
_RELATIVE = (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)


def reposition_target(origin: codec.GeoOrigin, home_enu_m, here_enu_m, params, int_frame: int | None):
    """MAV_CMD_DO_REPOSITION's parameters -> (target ENU (3,), speed m/s, yaw ENU rad or None).

    ``params``: param1..7 as received (COMMAND_INT, ``int_frame`` given: x, y in
    1e-7 deg, INT32_MAX "here"; COMMAND_LONG: degrees, frame GLOBAL). param1
    speed (not finite: -1, the default); param4 yaw in rad from north, as PX4
    reads it and MAVSDK's ``goto_location`` sends it (NaN: keep); NaN
    latitude/longitude: here; altitude AMSL, or above home in the
    RELATIVE_ALT frames (NaN: the current one).
    """
    frame = mavlink.MAV_FRAME_GLOBAL if int_frame is None else int(int_frame)
    here = codec.enu_to_global(origin, here_enu_m)
    lat, lon = float(params[4]), float(params[5])
    if int_frame is not None:
        lat, lon = (math.nan, math.nan) if params[4] == INT32_MAX else (lat * 1e-7, lon * 1e-7)
    if math.isnan(lat) or math.isnan(lon):
        lat, lon = here[0], here[1]
    alt = float(params[6])
    if math.isnan(alt):
        alt = here[2]
    elif frame in _RELATIVE:
        alt += origin.alt_m + float(home_enu_m[2])
    yaw = None if math.isnan(params[3]) else codec.yaw_ned2enu(params[3])
    speed = float(params[0]) if math.isfinite(params[0]) else -1.0
    return codec.global_to_enu(origin, lat, lon, alt), speed, yaw
