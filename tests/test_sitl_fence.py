"""Geofence geometry (sitl.fence), the fence failsafe and rally-point returns
of the SITL's flight stack (sitl.flightstack, sitl.rally), on hand-worked
shapes. The failsafe tests put the vehicle 0.5 m either side of the fence:
a fence check that misplaced the boundary (e.g. scaled it) fails them."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl.fence import (CIRCLE_EXCLUSION, CIRCLE_INCLUSION, POLYGON_EXCLUSION, POLYGON_INCLUSION, Fence, FenceError,
                        fence_from_items, point_in_polygon)
from mavcore.codec import MissionItem
from sitl.flightstack import FlightMode, FlightStack, NavState, Parameters
from sitl.rally import RallyError, rally_points_from_items, return_destination

# an L-shaped (concave) field: 0..10 x 0..4 plus 0..4 x 4..10
L_SHAPE = ((0, 0), (10, 0), (10, 4), (4, 4), (4, 10), (0, 10))


def item(seq, command, x_m, y_m, p1=0.0):
    """A fence item in MAV_FRAME_LOCAL_ENU (x, y in 1e-4 m), read by ``xy``."""
    return MissionItem(seq, mavlink.MAV_FRAME_LOCAL_ENU, command, 0, 1, p1, 0.0, 0.0, 0.0,
                       round(x_m * 1e4), round(y_m * 1e4), 0.0, 1)


def xy(it):
    return it.x * 1e-4, it.y * 1e-4, it.z


def polygon_items(command, verts, start=0):
    return [item(start + i, command, x, y, p1=len(verts)) for i, (x, y) in enumerate(verts)]


def test_point_in_a_concave_polygon():
    assert point_in_polygon(2, 8, L_SHAPE)          # in the upright arm
    assert point_in_polygon(8, 2, L_SHAPE)          # in the foot
    assert not point_in_polygon(8, 8, L_SHAPE)      # in the notch
    assert not point_in_polygon(-0.1, 2, L_SHAPE)


def test_inclusion_and_exclusion_areas_combine_as_px4_reads_them():
    items = (polygon_items(POLYGON_INCLUSION, L_SHAPE)
             + [item(6, CIRCLE_INCLUSION, 20, 20, p1=3.0)]
             + polygon_items(POLYGON_EXCLUSION, ((1, 1), (2, 1), (2, 2)), start=7)
             + [item(10, CIRCLE_EXCLUSION, 8, 2, p1=1.0)])
    f = fence_from_items(items, xy)
    assert len(f.inclusion_polygons) == 1 and len(f.exclusion_polygons) == 1
    assert not f.breached(2, 8)                 # inside the L
    assert not f.breached(21, 21)               # inside the other inclusion area (any one will do)
    assert f.breached(8, 8)                     # in no inclusion area
    assert f.breached(1.8, 1.2)                 # inside the exclusion triangle, inside the L
    assert f.breached(8.5, 2.0)                 # inside the exclusion circle
    assert not f.breached(9.5, 2.0)             # 1.5 m from its centre
    assert not Fence(exclusion_circles=((0, 0, 1),)).breached(5, 5)   # exclusions only: elsewhere allowed


def test_malformed_fence_lists_are_refused_by_name():
    square = ((0, 0), (1, 0), (1, 1), (0, 1))
    with pytest.raises(FenceError, match="4 vertices"):
        fence_from_items(polygon_items(POLYGON_INCLUSION, square)[:3], xy)
    with pytest.raises(FenceError, match="at least 3"):
        fence_from_items(polygon_items(POLYGON_INCLUSION, square[:2]), xy)
    with pytest.raises(FenceError, match="radius"):
        fence_from_items([item(0, CIRCLE_INCLUSION, 0, 0, p1=0.0)], xy)
    with pytest.raises(FenceError, match="not a fence item"):
        fence_from_items([item(0, 16, 0, 0)], xy)


def test_rally_points_and_the_closest_return_destination():
    pts = rally_points_from_items([dataclasses.replace(item(0, 5100, 30, 0), mission_type=2),
                                   dataclasses.replace(item(1, 5100, 0, -8), mission_type=2)], xy)
    assert pts == ((30.0, 0.0, 0.0), (0.0, -8.0, 0.0))
    # from (20, 0): rally 10 m away beats home 20 m away; from (0, -3): home 3 m, rally 5 m
    assert return_destination((20, 0, 5), (0, 0, 0), pts) == ((30.0, 0.0, 0.0), True)
    assert return_destination((0, -3, 5), (0, 0, 0), pts) == ((0.0, 0.0, 0.0), False)
    with pytest.raises(RallyError):
        rally_points_from_items([item(0, 16, 0, 0)], xy)


# --- the flight stack's failsafe -------------------------------------------------


def nav(p, landed=False):
    return NavState(np.array(p, float), np.zeros(3), 0.0, 0.0, landed)


def flying_stack(action: int, fence: Fence, rally=()):
    params = Parameters(initial={"GF_ACTION": action, "RTL_RETURN_ALT": 0.0})
    st = FlightStack(params, (0.0, 0.0, 0.0))
    st.fence, st.rally_points = fence, rally
    t = 0
    assert st.arm(t, nav((5, 5, 0), landed=True)).accepted
    st.update(t, nav((5, 5, 0), landed=True))
    st.pop_events()
    return st


SQUARE = Fence(inclusion_polygons=(((0, 0), (10, 0), (10, 10), (0, 10)),))


@pytest.mark.parametrize("action, mode, status", [
    (1, FlightMode.LOITER, mavlink.MAV_STATE_ACTIVE),      # warning only: the mode stays
    (2, FlightMode.LOITER, mavlink.MAV_STATE_CRITICAL),    # hold: a failsafe
    (3, FlightMode.RTL, mavlink.MAV_STATE_ACTIVE),
    (5, FlightMode.LAND, mavlink.MAV_STATE_ACTIVE),
])
def test_a_breach_triggers_gf_action_once(action, mode, status):
    st = flying_stack(action, SQUARE)
    st.update(1_000_000, nav((9.5, 5, 3)))                  # 0.5 m inside: nothing
    assert not st.fence_breached and st.mode is FlightMode.LOITER and not st.pop_events()
    st.update(1_010_000, nav((10.5, 5, 3)))                 # 0.5 m outside: the action
    assert st.fence_breached and st.mode is mode and st.system_status == status
    texts = [e.text for e in st.pop_events()]
    assert len(texts) == 1 and texts[0].startswith("Geofence breached")
    st.update(1_020_000, nav((10.6, 5, 3)))                 # still outside: not again
    assert not [e for e in st.pop_events() if "Geofence" in e.text]
    st.update(1_030_000, nav((9.5, 5, 3)))                  # back inside: healthy again
    assert not st.fence_breached


def test_no_action_with_gf_action_0_and_arming_outside_the_fence_is_refused():
    st = flying_stack(0, SQUARE)
    st.update(1_000_000, nav((10.5, 5, 3)))
    assert st.fence_breached and st.mode is FlightMode.LOITER and st.system_status == mavlink.MAV_STATE_ACTIVE
    st2 = FlightStack(Parameters(), (0.0, 0.0, 0.0))
    st2.fence = SQUARE
    r = st2.arm(0, nav((10.5, 5, 0), landed=True))
    assert not r.accepted and r.reason == "vehicle outside geofence"


def test_fence_return_goes_to_the_closest_rally_point_and_lands_there():
    rally = ((14.0, 5.0, 0.0),)   # 3.5 m from the breach point, home is 11.6 m away
    st = flying_stack(3, SQUARE, rally)
    p = np.array([10.5, 5.0, 3.0])
    t = 1_000_000
    for _ in range(2000):
        out = st.update(t, nav(p))
        if st.mode is FlightMode.LAND:
            break
        if out.setpoint is not None and out.setpoint.pos_enu_m is not None:
            p = np.array(out.setpoint.pos_enu_m, float)    # an ideal vehicle
        t += 10_000
    assert st.mode is FlightMode.LAND
    assert math.hypot(p[0] - 14.0, p[1] - 5.0) < 0.5
    assert any("rally point reached" in e.text for e in st.pop_events())


def test_disarmed_outside_the_fence_is_unhealthy_but_takes_no_action():
    st = FlightStack(Parameters(initial={"GF_ACTION": 3}), (0.0, 0.0, 0.0))
    st.fence = SQUARE
    st.update(0, nav((10.5, 5, 0), landed=True))
    assert st.fence_breached and st.mode is FlightMode.LOITER and not st.pop_events()
    st.update(10_000, nav((9.5, 5, 0), landed=True))
    assert not st.fence_breached
