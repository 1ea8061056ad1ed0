"""Where the SITL's DO_REPOSITION goes (sitl.mission_store.reposition_target),
and the geodetic reading of stored items (mavcore.codec.mission_item_enu), on
points worked out through mavcore.frames (the project's pyproj plane)."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore.frames import enu2geodetic
from mavcore.codec import GeoOrigin, mission_item_enu
from mavcore.codec import MissionItem
from sitl.mission_store import INT32_MAX, reposition_target

ORIGIN = GeoOrigin(44.8, -0.6, 30.0)
HOME = (2.0, -1.0, 0.5)          # the vehicle's start point, ENU about the origin


def ll(e, n, u=0.0):
    return enu2geodetic(e, n, u, ORIGIN.lat_deg, ORIGIN.lon_deg, ORIGIN.alt_m)


def test_reposition_in_a_relative_frame_over_command_int():
    lat, lon, _ = ll(12.0, 9.0)
    p = (-1.0, 1.0, 0.0, math.pi / 2, round(lat * 1e7), round(lon * 1e7), 3.0)
    target, speed, yaw = reposition_target(ORIGIN, HOME, (0.0, 0.0, 4.0), p,
                                           mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
    # 3 m above home (0.5 m up): z = 3.5; 1e-7 deg is 1.1 cm of latitude
    assert target == pytest.approx((12.0, 9.0, 3.5), abs=0.02)
    assert speed == -1.0 and yaw == pytest.approx(0.0)       # NED heading 90 deg (east) = ENU yaw 0


def test_reposition_nan_and_int32_max_keep_where_the_vehicle_is():
    here = (5.0, -3.0, 2.0)
    p = (2.0, 0.0, 0.0, math.nan, INT32_MAX, INT32_MAX, math.nan)
    target, speed, yaw = reposition_target(ORIGIN, HOME, here, p, mavlink.MAV_FRAME_GLOBAL_INT)
    assert target == pytest.approx(here, abs=1e-6) and speed == 2.0 and yaw is None
    lat, lon, alt = ll(-4.0, 6.0, 7.0)                       # COMMAND_LONG: degrees, altitude AMSL
    target, _, _ = reposition_target(ORIGIN, HOME, here, (-1, 0, 0, math.nan, lat, lon, alt), None)
    assert target == pytest.approx((-4.0, 6.0, 7.0), abs=1e-6)


def test_stored_items_in_amsl_relative_and_local_frames():
    lat, lon, alt = ll(10.0, 20.0, 1.5)

    def item(frame, x, y, z):
        return MissionItem(0, frame, 16, 0, 1, 0.0, 0.0, 0.0, 0.0, x, y, z)

    amsl = mission_item_enu(ORIGIN, HOME, item(mavlink.MAV_FRAME_GLOBAL, round(lat * 1e7), round(lon * 1e7), alt))
    assert amsl == pytest.approx((10.0, 20.0, 1.5), abs=0.02)
    rel = mission_item_enu(ORIGIN, HOME, item(mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, round(lat * 1e7),
                                              round(lon * 1e7), 1.0))
    assert rel == pytest.approx((10.0, 20.0, 1.5), abs=0.02)  # 1 m above home's 0.5 m
    assert mission_item_enu(ORIGIN, HOME, item(mavlink.MAV_FRAME_LOCAL_NED, 20000, 100000, -1.5)) == \
        pytest.approx((10.0, 2.0, 1.5))                        # x north 2 m, y east 10 m, z down
    assert mission_item_enu(ORIGIN, HOME, item(mavlink.MAV_FRAME_GLOBAL, 0, 0, 10.0)) is None
    assert mission_item_enu(ORIGIN, HOME, item(mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT, 1, 1, 10.0)) is None


def test_a_fence_upload_during_a_mission_leaves_it_flying_a_new_mission_stops_it():
    from mavcore.mission import load_mission
    from sitl.flightstack import FlightMode
    from sitl.server import SitlServer
    from test_sitl_mavlink import MISSION

    srv = SitlServer(load_mission(MISSION))          # no links: the protocol is driven directly
    srv.step_once()

    def upload(mission_type, items):
        srv.missions.handle_count(len(items), mission_type, 0.0)
        for it in items:
            srv.missions.handle_item(it, 0.0)
        srv.mission_link.sync_store()                  # what the server does before its MISSION_ACK

    h = srv.vehicle.home_enu_m
    lat, lon, _ = ll(h[0] + 5.0, h[1])
    wp = MissionItem(0, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 16, 1, 1, 0.0, 0.0, 0.0, math.nan,
                     round(lat * 1e7), round(lon * 1e7), 2.0)
    upload(0, [wp])
    assert srv.vehicle.stack.start_mission(srv.vehicle.sim.time_us, srv.vehicle.state(), None).accepted
    assert srv.vehicle.stack.arm(srv.vehicle.sim.time_us, srv.vehicle.state()).accepted
    for _ in range(100):
        srv.step_once()
    flying = srv.vehicle.stack.mission
    fence = [MissionItem(i, mavlink.MAV_FRAME_GLOBAL_INT, 5001, 0, 1, 3.0, 0.0, 0.0, 0.0, x, y, 0.0, 1)
             for i, (x, y) in enumerate(((447900000, -6100000), (448100000, -6100000), (448000000, -5900000)))]
    upload(1, fence)
    assert srv.vehicle.stack.fence is not None
    assert srv.vehicle.stack.mode is FlightMode.MISSION and srv.vehicle.stack.mission is flying
    upload(0, [wp])
    assert srv.vehicle.stack.mode is FlightMode.LOITER and srv.vehicle.stack.mission is not flying
