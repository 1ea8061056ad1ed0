"""Missions, rally points and DO_REPOSITION over MAVLink (pymavlink as the
ground station): MAV_CMD_MISSION_START flies an uploaded mission with
MISSION_CURRENT and MISSION_ITEM_REACHED as PX4 sends them, the return goes
to the closest rally point, and DO_REPOSITION (MAVSDK's goto_location) moves
a hovering vehicle in Hold. Positions are worked out here from the ENU
offsets through mavcore.frames, not read back from the SITL."""

from __future__ import annotations

import math
import time

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from mavcore.frames import enu2geodetic
from mavcore.mission import load_mission
from sitl.api import SitlThread
from sitl.flightstack import FlightMode

from test_sitl_mavlink import MISSION, Client

REL = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


@pytest.fixture()
def link():
    with SitlThread(MISSION, speed=4.0, sensor_hz=100) as sitl:
        c = Client(sitl.url)
        c.hello()
        yield sitl, c
        c.close()


def geo(sitl, de, dn):
    """(lat e7, lon e7) of the point ``de`` m east and ``dn`` m north of the vehicle's start."""
    h = load_mission(MISSION).home
    s = sitl.server.vehicle.home_enu_m
    lat, lon, _ = enu2geodetic(s[0] + de, s[1] + dn, 0.0, h.lat, h.lon, h.alt_m)
    return round(lat * 1e7), round(lon * 1e7)


def upload(c, items, mission_type=0):
    c.mav.mission_count_send(1, 1, len(items), mission_type)
    for i, (frame, cmd, p, x, y, z) in enumerate(items):
        r = c.recv("MISSION_REQUEST_INT", 3.0)
        assert r is not None and r.seq == i
        c.mav.mission_item_int_send(1, 1, i, frame, cmd, int(i == 0), 1, *p, x, y, z, mission_type)
    return c.recv("MISSION_ACK", 3.0).type


def horizontal_from_start(sitl):
    p, s = sitl.server.vehicle.sim.plant.p, sitl.server.vehicle.home_enu_m
    return p[0] - s[0], p[1] - s[1]


def test_mission_start_flies_the_items_and_reports_them_as_px4(link):
    sitl, c = link
    wp = geo(sitl, 6.0, 0.0)
    items = [(REL, mavlink.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, math.nan), *geo(sitl, 0.0, 0.0), 3.0),
             (2, mavlink.MAV_CMD_DO_CHANGE_SPEED, (1, 2.0, -1, 0), 0, 0, 0.0),
             (REL, mavlink.MAV_CMD_NAV_WAYPOINT, (0, 0.3, 0, math.nan), *wp, 3.0),
             (REL, mavlink.MAV_CMD_NAV_LAND, (0, 0, 0, math.nan), *wp, 0.0)]
    assert upload(c, items) == mavlink.MAV_MISSION_ACCEPTED
    assert c.command(mavlink.MAV_CMD_MISSION_START, 0, 0) == mavlink.MAV_RESULT_ACCEPTED
    hb = c.recv("HEARTBEAT", 3.0, lambda m: mavutil.mode_string_v10(m) == "MISSION")
    assert hb is not None
    assert c.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    reached, current = [], []
    end = time.monotonic() + 15.0
    while time.monotonic() < end and len(reached) < len(items):
        m = c.recv(("MISSION_ITEM_REACHED", "MISSION_CURRENT"), 0.5)
        if m is None:
            continue
        if m.get_type() == "MISSION_ITEM_REACHED":
            reached.append(m.seq)
        elif not current or current[-1] != m.seq:
            current.append(m.seq)
            assert m.total == len(items)
    assert reached == [0, 1, 2, 3]
    assert current[:3] == [0, 1, 2] or current[:3] == [0, 2, 3]   # DO items may pass within one frame
    # landed at the way-point: 6 m east of the start, within its 0.3 m acceptance radius
    de, dn = horizontal_from_start(sitl)
    assert math.hypot(de - 6.0, dn) < 0.3 + 0.05
    assert sitl.server.vehicle.stack.mission.finished


def test_do_reposition_in_hold_then_return_to_the_closest_rally_point(link):
    sitl, c = link
    rally = [(REL, 5100, (0, 0, 0, 0), *geo(sitl, 0.0, 6.0), 0.0),
             (REL, 5100, (0, 0, 0, 0), *geo(sitl, 30.0, 0.0), 0.0)]
    assert upload(c, rally, mavlink.MAV_MISSION_TYPE_RALLY) == mavlink.MAV_MISSION_ACCEPTED
    lat, lon = geo(sitl, 0.0, 4.0)
    send = lambda: c.mav.command_int_send(1, 1, REL, mavlink.MAV_CMD_DO_REPOSITION, 0, 0,   # noqa: E731
                                          -1, 1, 0, math.nan, lat, lon, 3.0)
    send()   # on the ground: refused
    assert c.recv("COMMAND_ACK", 3.0, lambda m: m.command == mavlink.MAV_CMD_DO_REPOSITION).result == \
        mavlink.MAV_RESULT_DENIED
    assert c.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    assert c.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan) == 0
    assert c.recv("STATUSTEXT", 10.0, lambda m: "Takeoff complete" in m.text) is not None
    send()
    assert c.recv("COMMAND_ACK", 3.0, lambda m: m.command == mavlink.MAV_CMD_DO_REPOSITION).result == \
        mavlink.MAV_RESULT_ACCEPTED
    ok = c.recv("GLOBAL_POSITION_INT", 10.0, lambda m: math.hypot(*horizontal_from_start(sitl)) > 3.9
                and abs(m.relative_alt - 3000) < 200)
    assert ok is not None
    c.pump(1.0)
    de, dn = horizontal_from_start(sitl)
    assert math.hypot(de, dn - 4.0) < 0.2
    assert sitl.server.vehicle.stack.mode is FlightMode.LOITER
    # from 4 m north: home is 4 m away, the rally point 6 m north 2 m, the other one 30 m
    assert c.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH) == mavlink.MAV_RESULT_ACCEPTED
    assert c.recv("STATUSTEXT", 15.0, lambda m: "rally point reached" in m.text) is not None
    de, dn = horizontal_from_start(sitl)
    assert math.hypot(de, dn - 6.0) < 0.5
