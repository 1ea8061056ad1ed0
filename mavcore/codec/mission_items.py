"""The mission-item codec, both ends: MISSION_ITEM_INT / MISSION_ITEM to the
stored ``MissionItem`` (wire units, as the vehicle keeps them) and back,
item positions to and from world ENU about the vehicle's geodetic origin, and
the companion's encoding of its ENU way-points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from mavcore import frames

__all__ = ['GeoOrigin', 'MissionItem', 'mission_item_from_int', 'mission_item_from_float', 'global_to_enu',
           'enu_to_global', 'mission_item_enu', 'mission_item_int', 'encode_mission_item_int',
           'encode_mission_item', 'decode_mission_item_int']


@dataclass(frozen=True, slots=True)
class GeoOrigin:
    """Geodetic pose of the ENU origin (the mission's ``home``: map origin)."""

    lat_deg: float
    lon_deg: float
    alt_m: float


@dataclass(frozen=True, slots=True)
class MissionItem:
    """One stored MISSION_ITEM_INT, in wire units as received (x, y: 1e7 deg
    for global frames or 1e4 m for local frames; z in the item's frame)."""

    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    mission_type: int = 0


_GLOBAL_FRAMES = frozenset((
    mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    mavlink.MAV_FRAME_GLOBAL_INT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT, mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT))


def mission_item_from_int(msg):
    """MISSION_ITEM_INT -> ``flightstack.MissionItem`` (stored as on the wire)."""
    return MissionItem(int(msg.seq), int(msg.frame), int(msg.command), int(msg.current),
                       int(msg.autocontinue), float(msg.param1), float(msg.param2),
                       float(msg.param3), float(msg.param4), int(msg.x), int(msg.y),
                       float(msg.z), int(getattr(msg, "mission_type", 0)))


def mission_item_from_float(msg):
    """Legacy MISSION_ITEM (float x, y) -> ``MissionItem`` in MISSION_ITEM_INT
    units: degrees * 1e7 for global frames, metres * 1e4 for local ones.
    None if x or y is not finite or does not fit an int32."""
    scale = 1e7 if int(msg.frame) in _GLOBAL_FRAMES else 1e4
    x, y = float(msg.x), float(msg.y)
    if not (math.isfinite(x) and math.isfinite(y)):
        return None
    xi, yi = int(round(x * scale)), int(round(y * scale))
    if max(abs(xi), abs(yi)) >= 2 ** 31:
        return None
    return MissionItem(int(msg.seq), int(msg.frame), int(msg.command), int(msg.current),
                       int(msg.autocontinue), float(msg.param1), float(msg.param2),
                       float(msg.param3), float(msg.param4), xi, yi, float(msg.z),
                       int(getattr(msg, "mission_type", 0)))


_RELATIVE_FRAMES = frozenset((mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT))
_AMSL_FRAMES = frozenset((mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT))


def global_to_enu(origin: GeoOrigin, lat_deg: float, lon_deg: float, alt_amsl_m: float) -> tuple:
    """WGS-84 (deg, deg, m AMSL) -> world ENU (m) about ``origin``: the SITL's
    one way in from geodetic coordinates (missions, fences, rally points,
    DO_REPOSITION), through the project's pyproj tangent plane."""
    x, y, z = frames.geodetic2enu(float(lat_deg), float(lon_deg), float(alt_amsl_m),
                                  origin.lat_deg, origin.lon_deg, origin.alt_m)
    return float(x), float(y), float(z)


def enu_to_global(origin: GeoOrigin, pos_enu_m) -> tuple:
    """World ENU (m) -> (lat_deg, lon_deg, alt_m AMSL): ``global_to_enu``'s inverse."""
    lat, lon, alt = frames.enu2geodetic(float(pos_enu_m[0]), float(pos_enu_m[1]), float(pos_enu_m[2]),
                                        origin.lat_deg, origin.lon_deg, origin.alt_m)
    return float(lat), float(lon), float(alt)


def mission_item_enu(origin: GeoOrigin, home_enu_m, item) -> tuple | None:
    """Position of a stored ``MissionItem`` in world ENU (m), or None when the
    item has no position the SITL flies: MAV_FRAME_MISSION, a terrain frame,
    or latitude = longitude = 0 (QGC's "here"/unset). Global frames: x, y in
    1e7 deg; z AMSL (GLOBAL, GLOBAL_INT) or above home (the RELATIVE_ALT
    frames, as PX4 reads them). Local frames: x, y in 1e4 m, LOCAL_NED or
    LOCAL_ENU about the ENU origin."""
    f = int(item.frame)
    if f in _AMSL_FRAMES or f in _RELATIVE_FRAMES:
        if item.x == 0 and item.y == 0:
            return None
        alt = float(item.z) + (origin.alt_m + float(home_enu_m[2]) if f in _RELATIVE_FRAMES else 0.0)
        return global_to_enu(origin, item.x * 1e-7, item.y * 1e-7, alt)
    if f == mavlink.MAV_FRAME_LOCAL_ENU:
        return item.x * 1e-4, item.y * 1e-4, float(item.z)
    if f == mavlink.MAV_FRAME_LOCAL_NED:
        return item.y * 1e-4, item.x * 1e-4, -float(item.z)
    return None


def mission_item_int(mav, target_system: int, target_component: int, item):
    """``MissionItem`` -> MISSION_ITEM_INT for a download."""
    return mav.mission_item_int_encode(
        target_system, target_component, item.seq, item.frame, item.command, item.current,
        item.autocontinue, item.param1, item.param2, item.param3, item.param4,
        item.x, item.y, item.z, item.mission_type)


def encode_mission_item_int(mav, seq: int, pos_enu_m, home_lat_deg: float, home_lon_deg: float,
                            home_alt_m: float, target_system: int = 1, target_component: int = 1,
                            current: bool = False):
    """MISSION_ITEM_INT (NAV_WAYPOINT, ``mavlink.MAV_FRAME_GLOBAL_INT``) from an ENU way-point.

    Parameters
    ----------
    pos_enu_m : array_like (3,)
        Way-point about the mission home, ENU, m.
    home_lat_deg, home_lon_deg, home_alt_m : float
        Geodetic pose of the mission home (the map origin), WGS-84, m AMSL.

    Notes
    -----
    The altitude is AMSL (``home_alt_m + z``), so the item does not depend
    on where the vehicle happened to set its own home.
    """
    x, y, z = (float(c) for c in pos_enu_m)
    lat, lon, alt = frames.enu2geodetic(x, y, z, home_lat_deg, home_lon_deg, home_alt_m)
    return mav.mission_item_int_encode(
        target_system, target_component, seq, mavlink.MAV_FRAME_GLOBAL_INT, mavlink.MAV_CMD_NAV_WAYPOINT,
        1 if current else 0, 1, 0.0, 0.0, 0.0, math.nan,
        int(round(lat * 1e7)), int(round(lon * 1e7)), float(alt), mavlink.MAV_MISSION_TYPE_MISSION,
    )


def encode_mission_item(mav, seq: int, item, target_system: int = 1, target_component: int = 1,
                        mission_type: int = mavlink.MAV_MISSION_TYPE_MISSION, current: bool = False):
    """MISSION_ITEM_INT from a ``companion.mission_items.MissionItem`` (degrees, m AMSL).

    Latitude/longitude become 1e7 degrees here (the only place they may).
    ``mission_type``: MAV_MISSION_TYPE_MISSION or MAV_MISSION_TYPE_FENCE.
    """
    p1, p2, p3, p4 = (float(v) for v in item.params)
    return mav.mission_item_int_encode(
        target_system, target_component, seq, int(item.frame), int(item.command), 1 if current else 0,
        1 if item.autocontinue else 0, p1, p2, p3, p4,
        int(round(item.lat_deg * 1e7)), int(round(item.lon_deg * 1e7)), float(item.alt_m), mission_type,
    )


def decode_mission_item_int(msg, home_lat_deg: float, home_lon_deg: float, home_alt_m: float) -> np.ndarray:
    """MISSION_ITEM_INT in ``mavlink.MAV_FRAME_GLOBAL_INT`` -> ENU way-point (3,) m about home."""
    x, y, z = frames.geodetic2enu(msg.x * 1e-7, msg.y * 1e-7, float(msg.z), home_lat_deg, home_lon_deg, home_alt_m)
    return np.array((x, y, z))
