"""The flight-ready mission a flight stack flies on its own (pure).

One list of items is built here and written three ways: the QGroundControl
``.plan``, the ``QGC WPL 110`` file (``companion.plan_io``) and the
MISSION_INT upload (``mavcore.codec.encode_mission_item``). Order:

==  =======================  ================================================
#   command                  what
==  =======================  ================================================
0   NAV_TAKEOFF (22)         at the launch point, to the first way-point's
                             altitude (ArduCopter refuses AUTO without it);
                             param4 = yaw toward S_p
1   DO_CHANGE_SPEED (178)    param1 = 1 (ground speed), param2 = the plan's
                             speed, param3 = -1 (throttle unchanged): PX4
                             would otherwise fly at MPC_XY_CRUISE (5 m/s)
2   DO_SET_ROI_LOCATION      the pointing target S_p of eq. (21), AMSL: both
    (195)                    stacks then yaw the nose (or a gimbal) at it
3.. NAV_WAYPOINT (16)        the way-points; param2 = the acceptance radius
                             (``companion.margins``: at most a third of the
                             corridor, so the stack does not turn across a
                             row); param4 = yaw (deg, from north, clockwise)
                             toward S_p, the same in all three exports and
                             consistent with the ROI
end RETURN_TO_LAUNCH (20)    back to where the vehicle armed, and land
==  =======================  ================================================

Altitudes: **AMSL**, frame MAV_FRAME_GLOBAL (0) in the .plan/WPL files (QGC
``AltitudeMode`` 2, absolute) and in MISSION_ITEM_INT. The map frame's z = 0
is ``home.alt_m`` AMSL and the DEM is in that frame, so a way-point's AMSL
altitude is ``home.alt_m + DEM(x, y) + height_agl_m`` wherever the vehicle
arms; a relative frame (3) would shift everything by the arming point's
height (1.35 m on the tilted hexagon 12 m from the origin). The terrain
frame (MAV_FRAME_GLOBAL_TERRAIN_ALT, 10) was not chosen: PX4 does not fly
it in missions, and ArduPilot resolves it against SRTM terrain tiles
(30-100 m posts) that cannot hold 1.5 m above ground between vine rows.

Unused params are 0, as QGroundControl writes them; no param is NaN (the
yaws of the take-off and the landing are the heading toward S_p, not
"unchanged").

Geofence: one inclusion polygon (MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
5001, mission type FENCE; param1 = vertex count, param2 = group 0) around
the field (``coverage.boundary``), grown so that the flown path keeps the
fence margin inside it (``companion.margins``: navigation accuracy +
tracking allowance, stated in plan.json ``margins``). PX4 and ArduPilot 4.x both take fence polygons through the
mission protocol with MAV_MISSION_TYPE_FENCE; the QGC ``.plan`` carries it
in ``geoFence.polygons``; the WPL format has no fence.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mavcore.frames import enu2geodetic

MAV_CMD_NAV_WAYPOINT = 16
MAV_CMD_NAV_RETURN_TO_LAUNCH = 20
MAV_CMD_NAV_LAND = 21
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_CHANGE_SPEED = 178
MAV_CMD_DO_SET_ROI_LOCATION = 195
MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION = 5001
MAV_FRAME_GLOBAL = 0
MAV_FRAME_MISSION = 2
SPEED_TYPE_GROUND = 1


@dataclass(frozen=True)
class MissionItem:
    """One mission item in geodetic coordinates (WGS-84 degrees, metres AMSL).

    ``params`` are param1..param4 (0 = unused); ``lat_deg``, ``lon_deg``,
    ``alt_m`` are 0 for items without a position (frame MAV_FRAME_MISSION).
    """

    command: int
    frame: int
    params: tuple[float, float, float, float]
    lat_deg: float = 0.0
    lon_deg: float = 0.0
    alt_m: float = 0.0
    autocontinue: bool = True


@dataclass(frozen=True)
class FlightItems:
    """What the flight stack needs: the mission, the fence vertices and the planned home.

    Attributes
    ----------
    mission : tuple of MissionItem
    fence : tuple of MissionItem
        NAV_FENCE_POLYGON_VERTEX_INCLUSION items, one per vertex (mission type FENCE).
    fence_latlon_deg : (K, 2) array
        The same vertices as (lat, lon).
    home : (lat_deg, lon_deg, alt_m)
        The mission home (map origin), for the files' planned-home entries.
    """

    mission: tuple[MissionItem, ...]
    fence: tuple[MissionItem, ...]
    fence_latlon_deg: np.ndarray
    home: tuple[float, float, float]


def yaw_to_target_deg(p_enu_m: np.ndarray, target_enu_m: np.ndarray) -> np.ndarray:
    """(N,) heading (deg, from north, clockwise, in [0, 360)) from each point toward the target."""
    d = np.asarray(target_enu_m, float)[:2] - np.asarray(p_enu_m, float)[:, :2]
    return np.degrees(np.arctan2(d[:, 0], d[:, 1])) % 360.0


def build_flight_items(waypoints_p_enu_m: np.ndarray, target_enu_m: np.ndarray,
                       home: tuple[float, float, float], speed_m_s: float,
                       launch_enu_m: np.ndarray | None = None,
                       fence_enu_m: np.ndarray | None = None, end: str = "rtl",
                       speed_changes=None, acceptance_radius_m: float = 0.0) -> FlightItems:
    """The mission of the module table from ENU way-points (map frame, m).

    Parameters
    ----------
    waypoints_p_enu_m : (N, 3)
        Way-point positions (ENU, m, z in the map frame: z = 0 is ``home[2]`` AMSL).
    target_enu_m : (3,)
        Pointing target S_p (ENU, m).
    home : (lat_deg, lon_deg, alt_m)
        Geodetic pose of the map origin.
    speed_m_s : float
    launch_enu_m : (2,) or (3,), optional
        Where the take-off starts (ENU, m); default: under the first way-point.
    fence_enu_m : (K, 2), optional
        Inclusion fence polygon (ENU, m).
    end : {"rtl", "land"}
        RETURN_TO_LAUNCH, or NAV_LAND at the launch point.
    speed_changes : sequence of (way-point index, speed m/s), optional
        A DO_CHANGE_SPEED before each of those way-points (a sortie's transit
        and coverage speeds); default one, ``speed_m_s``, before the first.
    acceptance_radius_m : float
        NAV_WAYPOINT param2 (m); 0 leaves it to the stack's default (PX4
        NAV_ACC_RAD, ArduCopter WPNAV_RADIUS).
    """
    lat0, lon0, alt0 = (float(v) for v in home)
    wp = np.asarray(waypoints_p_enu_m, float)

    def geo(x, y, z):
        lat, lon, alt = enu2geodetic(float(x), float(y), float(z), lat0, lon0, alt0)
        return lat, lon, alt

    launch = wp[0, :2] if launch_enu_m is None else np.asarray(launch_enu_m, float)[:2]
    yaw_launch = float(yaw_to_target_deg(np.array([[launch[0], launch[1], 0.0]]), target_enu_m)[0])
    acc = float(acceptance_radius_m)
    changes = dict((int(i), float(v)) for i, v in (speed_changes or ((0, speed_m_s),)))

    def speed_item(v: float) -> MissionItem:
        return MissionItem(MAV_CMD_DO_CHANGE_SPEED, MAV_FRAME_MISSION, (SPEED_TYPE_GROUND, v, -1.0, 0.0))

    items = [MissionItem(MAV_CMD_NAV_TAKEOFF, MAV_FRAME_GLOBAL, (0.0, 0.0, 0.0, yaw_launch),
                         *geo(launch[0], launch[1], wp[0, 2])),
             speed_item(changes.pop(0, float(speed_m_s))),
             MissionItem(MAV_CMD_DO_SET_ROI_LOCATION, MAV_FRAME_GLOBAL, (0.0, 0.0, 0.0, 0.0), *geo(*target_enu_m))]
    yaw = yaw_to_target_deg(wp, target_enu_m)
    for i, (p, psi) in enumerate(zip(wp, yaw)):
        if i in changes:
            items.append(speed_item(changes[i]))
        items.append(MissionItem(MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL, (0.0, acc, 0.0, float(psi)), *geo(*p)))
    if end == "land":
        items.append(MissionItem(MAV_CMD_NAV_LAND, MAV_FRAME_GLOBAL, (0.0, 0.0, 0.0, yaw_launch),
                                 *geo(launch[0], launch[1], wp[0, 2])))
    else:
        items.append(MissionItem(MAV_CMD_NAV_RETURN_TO_LAUNCH, MAV_FRAME_MISSION, (0.0, 0.0, 0.0, 0.0)))
    fence_ll = np.zeros((0, 2))
    fence: list[MissionItem] = []
    if fence_enu_m is not None and len(fence_enu_m) >= 3:
        ll = [geo(x, y, 0.0)[:2] for x, y in np.asarray(fence_enu_m, float)]
        fence_ll = np.array(ll)
        k = len(ll)
        fence = [MissionItem(MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, MAV_FRAME_GLOBAL,
                             (float(k), 0.0, 0.0, 0.0), lat, lon, 0.0) for lat, lon in ll]
    return FlightItems(mission=tuple(items), fence=tuple(fence), fence_latlon_deg=fence_ll, home=(lat0, lon0, alt0))
