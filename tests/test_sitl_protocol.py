"""MAVLink microservice rules of the SITL's flight-stack face, over real UDP
with pymavlink as the client: command addressing and acknowledgement, the
parameter and mission protocols' edge cases, modes by SET_MODE and
COMMAND_INT, REQUEST_MESSAGE.

The expected behaviour comes from the MAVLink protocol pages (command,
parameter and mission microservices) and PX4's implementation of them, not
from the SITL's output.
"""

from __future__ import annotations

import struct
import time

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from sitl.api import SitlThread, free_udp_port
from sitl.flightstack import PARAM_SPECS, FlightMode

from test_sitl_mavlink import MISSION, Client

ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
SET_MODE = mavlink.MAV_CMD_DO_SET_MODE
CUSTOM = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


@pytest.fixture(scope="module")
def sitl():
    with SitlThread(MISSION, speed=4.0) as s:
        s.gcs_port = free_udp_port()
        yield s


@pytest.fixture()
def gcs(sitl):
    # A ground station with an unusual id, so that reply addressing is checked;
    # one source port for the module (the SITL binds a controller to its address).
    c = Client(sitl.url, sysid=245, compid=190, local_port=sitl.gcs_port)
    c.hello()
    yield c
    c.close()


def acks(gcs, cmd, seconds=0.4):
    """Every COMMAND_ACK for ``cmd`` received within ``seconds``."""
    out = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        m = gcs.recv("COMMAND_ACK", max(0.0, end - time.monotonic()), lambda m: m.command == cmd)
        if m is not None:
            out.append(m)
    return out


def said(gcs, text, timeout=1.0):
    """A STATUSTEXT containing ``text`` was received (or arrives within ``timeout``)."""
    if any(text in t for t in gcs.texts):
        return True
    return gcs.recv("STATUSTEXT", timeout, lambda m: text in m.text) is not None


# --- command protocol -----------------------------------------------------------


@pytest.mark.parametrize("target, answered", [
    ((1, 1), True), ((1, 0), True), ((0, 0), True),          # ours, our system, broadcast
    ((1, 191), False), ((2, 1), False), ((0, 191), False),   # another component or system
])
def test_command_long_addressing_and_single_ack(gcs, target, answered):
    mid = mavlink.MAVLINK_MSG_ID_HOME_POSITION
    gcs.mav.command_long_send(target[0], target[1], mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, 0,
                              mid, 0, 0, 0, 0, 0, 0)
    got = acks(gcs, mavlink.MAV_CMD_GET_MESSAGE_INTERVAL)
    if not answered:
        assert got == []
        return
    assert len(got) == 1                                        # exactly one ACK
    a = got[0]
    assert a.result == mavlink.MAV_RESULT_ACCEPTED
    assert (a.target_system, a.target_component) == (245, 190)  # addressed to the sender
    assert a.get_srcSystem() == 1 and a.get_srcComponent() == 1


def test_command_int_acked_and_addressed(gcs):
    # DO_SET_MODE by COMMAND_INT (MAVSDK's way): ACK to the sender, mode in the heartbeat.
    gcs.mav.command_int_send(1, 1, 0, SET_MODE, 0, 0, CUSTOM, 3, 0, 0, 0, 0, 0)
    got = acks(gcs, SET_MODE)
    assert [a.result for a in got] == [mavlink.MAV_RESULT_ACCEPTED]
    assert (got[0].target_system, got[0].target_component) == (245, 190)
    hb = gcs.recv("HEARTBEAT", 3.0, lambda m: m.custom_mode == 3 << 16)
    assert hb is not None and mavutil.mode_string_v10(hb) == "POSCTL"
    gcs.mav.command_int_send(1, 191, 0, SET_MODE, 0, 0, CUSTOM, 4, 3, 0, 0, 0, 0)
    assert acks(gcs, SET_MODE) == []
    assert gcs.command(SET_MODE, CUSTOM, 4, 3) == mavlink.MAV_RESULT_ACCEPTED


def test_command_results(gcs):
    # supported with bad parameters -> DENIED; unknown -> UNSUPPORTED; never silence
    assert gcs.command(ARM, 0.5) == mavlink.MAV_RESULT_DENIED
    assert gcs.command(SET_MODE, 0, 3, 0) == mavlink.MAV_RESULT_DENIED      # no custom-mode flag
    assert gcs.command(SET_MODE, CUSTOM, 2, 0) == mavlink.MAV_RESULT_DENIED  # ALTCTL: not available
    assert gcs.command(SET_MODE, CUSTOM, float("nan"), 0) == mavlink.MAV_RESULT_DENIED
    assert gcs.command(mavlink.MAV_CMD_REQUEST_MESSAGE, float("nan")) == mavlink.MAV_RESULT_DENIED
    # not a message id (24 bits) nor an interval (int32 us): bad parameters (mavcore/link/command_rules.py)
    assert gcs.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 1e30, 1e30) == mavlink.MAV_RESULT_DENIED
    assert gcs.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 4242, 1000) == mavlink.MAV_RESULT_UNSUPPORTED
    assert gcs.command(mavlink.MAV_CMD_DO_SET_CAM_TRIGG_DIST, 5, 0, 1) == mavlink.MAV_RESULT_UNSUPPORTED
    # DO_REPOSITION: supported, but not on the ground (PX4 Hold needs a flying vehicle)
    assert gcs.command(mavlink.MAV_CMD_DO_REPOSITION, -1, 0, 0, 0, 44.8, -0.6, 40) == mavlink.MAV_RESULT_DENIED
    assert gcs.recv("HEARTBEAT", 3.0) is not None               # still alive


def test_command_fault_still_acked_failed(sitl, gcs):
    # A handler that breaks must not leave the sender waiting: one ACK, FAILED.
    cmds = sitl.server.commands.handlers
    orig = cmds[mavlink.MAV_CMD_GET_HOME_POSITION]

    def broken(p, int_frame):
        raise RuntimeError("boom")
    cmds[mavlink.MAV_CMD_GET_HOME_POSITION] = broken
    try:
        gcs.mav.command_long_send(1, 1, mavlink.MAV_CMD_GET_HOME_POSITION, 0, 0, 0, 0, 0, 0, 0, 0)
        assert [a.result for a in acks(gcs, mavlink.MAV_CMD_GET_HOME_POSITION)] == [mavlink.MAV_RESULT_FAILED]
    finally:
        cmds[mavlink.MAV_CMD_GET_HOME_POSITION] = orig


def test_request_message_version_and_home(gcs):
    assert gcs.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == \
        mavlink.MAV_RESULT_ACCEPTED
    v = gcs.recv("AUTOPILOT_VERSION", 3.0)
    for cap in (mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT, mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
                mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2,
                mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED):
        assert v.capabilities & cap
    # INT32 parameters are sent byte-wise (PX4), so C-cast PARAM_FLOAT must not be claimed
    assert v.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    assert not v.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    assert gcs.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION) == \
        mavlink.MAV_RESULT_ACCEPTED
    assert gcs.recv("HOME_POSITION", 3.0) is not None


# --- modes ------------------------------------------------------------------------------


def test_set_mode_message_changes_heartbeat_and_announces(gcs):
    posctl = FlightMode.POSCTL.main << 16
    gcs.mav.set_mode_send(1, CUSTOM, posctl)
    assert gcs.recv("HEARTBEAT", 3.0, lambda m: m.custom_mode == posctl) is not None
    assert said(gcs, "Mode POSCTL")
    loiter = FlightMode.LOITER.main << 16 | FlightMode.LOITER.sub << 24
    gcs.mav.set_mode_send(2, CUSTOM, 6 << 16)                    # another system: ignored
    gcs.mav.set_mode_send(1, CUSTOM, loiter)
    assert gcs.recv("HEARTBEAT", 3.0, lambda m: m.custom_mode == loiter) is not None
    assert said(gcs, "Mode AUTO.LOITER")
    # OFFBOARD without a setpoint stream: refused, announced, heartbeat unchanged
    assert gcs.command(SET_MODE, CUSTOM, 6, 0) == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    assert said(gcs, "Offboard denied")
    assert gcs.recv("HEARTBEAT", 3.0).custom_mode == loiter


# --- parameter protocol -----------------------------------------------------------------


def test_param_list_indices_once_each(gcs):
    gcs.mav.param_request_list_send(1, 1)
    seen = []
    while True:
        m = gcs.recv("PARAM_VALUE", 1.0)
        if m is None:
            break
        assert m.param_count == len(PARAM_SPECS)
        seen.append((m.param_index, m.param_id))
    assert sorted(i for i, _ in seen) == list(range(len(PARAM_SPECS)))    # 0..N-1 exactly once
    assert dict(seen) == {i: s.name for i, s in enumerate(PARAM_SPECS)}


def test_param_read_by_index_and_full_length_name(gcs):
    names = [s.name for s in PARAM_SPECS]
    long_name = next(n for n in names if len(n) == 16)                  # no NUL on the wire
    i = names.index(long_name)
    gcs.mav.param_request_read_send(1, 1, b"", i)
    m = gcs.recv("PARAM_VALUE", 3.0)
    assert (m.param_id, m.param_index) == (long_name, i)
    gcs.mav.param_request_read_send(1, 1, long_name.encode(), -1)
    m = gcs.recv("PARAM_VALUE", 3.0)
    assert (m.param_id, m.param_index) == (long_name, i)
    m = gcs.set_param(long_name, 12.0)
    assert m.param_value == pytest.approx(12.0) and m.param_index == i
    gcs.mav.param_request_read_send(1, 1, b"", len(names))             # out of range: silence
    assert gcs.recv("PARAM_VALUE", 0.4) is None


def test_param_set_unknown_or_bad_is_answered_safely(gcs):
    gcs.texts.clear()
    gcs.mav.param_set_send(1, 1, b"NO_SUCH_PARAM", 1.0, mavlink.MAV_PARAM_TYPE_REAL32)
    assert gcs.recv("PARAM_VALUE", 0.4) is None                       # PX4: no PARAM_VALUE
    assert said(gcs, "NO_SUCH_PARAM")
    old = gcs.set_param("MPC_LAND_SPEED", 0.9).param_value
    assert old == pytest.approx(0.9)
    m = gcs.set_param("MPC_LAND_SPEED", float("nan"))                 # rejected: old value back
    assert m.param_value == pytest.approx(0.9)
    wire = struct.unpack("<f", struct.pack("<i", 7))[0]                 # out of range [0, 2]
    m = gcs.set_param("COM_OBL_ACT", wire, mavlink.MAV_PARAM_TYPE_INT32)
    assert struct.unpack("<i", struct.pack("<f", m.param_value))[0] == 0
    gcs.mav.param_set_send(1, 191, b"MPC_LAND_SPEED", 0.5, mavlink.MAV_PARAM_TYPE_REAL32)
    assert gcs.recv("PARAM_VALUE", 0.4) is None                       # not for us
    assert gcs.recv("HEARTBEAT", 3.0) is not None


# --- mission protocol -------------------------------------------------------------------


def wp(i):
    return (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mavlink.MAV_CMD_NAV_WAYPOINT, 0, 1,
            0.0, 0.0, 0.0, 0.0, 448000000 + 100 * i, -6000000, 2.0, 0)


def test_mission_upload_lost_ack_and_sequence(gcs):
    gcs.mav.mission_count_send(1, 1, 2, 0)
    assert gcs.recv("MISSION_REQUEST_INT", 3.0).seq == 0
    gcs.mav.mission_item_int_send(1, 1, 1, *wp(1))                     # out of sequence
    assert gcs.recv("MISSION_REQUEST_INT", 3.0).seq == 0                 # asked again for 0
    gcs.mav.mission_item_int_send(1, 1, 0, *wp(0))
    r = gcs.recv("MISSION_REQUEST_INT", 3.0)
    assert (r.seq, r.target_system, r.target_component) == (1, 245, 190)
    gcs.mav.mission_item_int_send(1, 1, 1, *wp(1))
    assert gcs.recv("MISSION_ACK", 3.0).type == mavlink.MAV_MISSION_ACCEPTED
    # The ACK was lost for the ground station, which re-sends the last item:
    # the vehicle acknowledges again (PX4 PR #9547) instead of reporting an error.
    gcs.mav.mission_item_int_send(1, 1, 1, *wp(1))
    assert gcs.recv("MISSION_ACK", 3.0).type == mavlink.MAV_MISSION_ACCEPTED
    gcs.mav.mission_request_list_send(1, 1, 0)
    assert gcs.recv("MISSION_COUNT", 3.0).count == 2


def test_mission_count_zero_fence_and_clear(gcs):
    gcs.mav.mission_count_send(1, 1, 1, 0)
    gcs.recv("MISSION_REQUEST_INT", 3.0)
    gcs.mav.mission_item_int_send(1, 1, 0, *wp(0))
    assert gcs.recv("MISSION_ACK", 3.0).type == mavlink.MAV_MISSION_ACCEPTED
    gcs.mav.mission_count_send(1, 1, 0, 0)                             # empty upload = clear
    assert gcs.recv("MISSION_ACK", 3.0).type == mavlink.MAV_MISSION_ACCEPTED
    gcs.mav.mission_request_list_send(1, 1, 0)
    assert gcs.recv("MISSION_COUNT", 3.0).count == 0
    fence = mavlink.MAV_MISSION_TYPE_FENCE

    def upload_fence(vertex_count):
        gcs.mav.mission_count_send(1, 1, 3, fence)
        for i in range(3):
            r = gcs.recv("MISSION_REQUEST_INT", 3.0)
            assert (r.seq, r.mission_type) == (i, fence)
            # a triangle of about 2 km around the vehicle (it starts within metres of 44.8 N 0.6 W)
            lat, lon = ((447900000, -6100000), (448100000, -6100000), (448000000, -5900000))[i]
            gcs.mav.mission_item_int_send(1, 1, i, mavlink.MAV_FRAME_GLOBAL_INT, 5001, 0, 1, vertex_count, 0, 0, 0,
                                          lat, lon, 0.0, fence)
        return gcs.recv("MISSION_ACK", 3.0)

    a = upload_fence(4)                         # a polygon of 4 vertices in 3 items: refused, nothing stored
    assert (a.type, a.mission_type) == (mavlink.MAV_MISSION_ERROR, fence)
    gcs.mav.mission_request_list_send(1, 1, fence)
    c = gcs.recv("MISSION_COUNT", 3.0)
    assert (c.count, c.mission_type) == (0, fence)
    a = upload_fence(3)
    assert (a.type, a.mission_type) == (mavlink.MAV_MISSION_ACCEPTED, fence)
    gcs.mav.mission_request_list_send(1, 1, fence)
    c = gcs.recv("MISSION_COUNT", 3.0)
    assert (c.count, c.mission_type) == (3, fence)
    # a stored fence: the SYS_STATUS geofence bit is present, enabled and healthy (MAVProxy's fence module)
    bit = mavlink.MAV_SYS_STATUS_GEOFENCE
    st = gcs.recv("SYS_STATUS", 3.0, lambda m: m.onboard_control_sensors_enabled & bit)
    assert st.onboard_control_sensors_present & bit and st.onboard_control_sensors_health & bit
    gcs.mav.mission_clear_all_send(1, 1, mavlink.MAV_MISSION_TYPE_ALL)
    assert gcs.recv("MISSION_ACK", 3.0).type == mavlink.MAV_MISSION_ACCEPTED


def test_mission_upload_rerequests_after_a_vehicle_timeout(gcs):
    gcs.mav.mission_count_send(1, 1, 1, 0)
    t0 = time.monotonic()
    assert gcs.recv("MISSION_REQUEST_INT", 3.0).seq == 0
    r = gcs.recv("MISSION_REQUEST_INT", 3.0)                           # we stay silent
    assert r is not None and r.seq == 0
    # 0.5 s of vehicle time: 0.125 s of wall time at speed 4 (tests/test_sitl_links.py times it exactly)
    assert time.monotonic() - t0 < 1.5
    gcs.mav.mission_item_int_send(1, 1, 0, *wp(0))
    assert gcs.recv("MISSION_ACK", 3.0).type == mavlink.MAV_MISSION_ACCEPTED


# --- arming ------------------------------------------------------------------------------


def test_disarm_in_flight_needs_force(gcs):
    z0 = gcs.recv("LOCAL_POSITION_NED", 3.0).z
    # param7 = 0 m AMSL is below home (30 m): PX4 uses the minimum takeoff altitude
    assert gcs.command(mavlink.MAV_CMD_NAV_TAKEOFF) == mavlink.MAV_RESULT_ACCEPTED
    assert said(gcs, "Using minimum takeoff altitude")
    assert gcs.command(ARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    air = gcs.recv("EXTENDED_SYS_STATE", 5.0, lambda m: m.landed_state != mavlink.MAV_LANDED_STATE_ON_GROUND)
    assert air is not None
    assert gcs.recv("LOCAL_POSITION_NED", 5.0, lambda m: m.z < z0 - 0.5) is not None
    assert gcs.command(ARM, 1) == mavlink.MAV_RESULT_ACCEPTED          # already armed: no-op
    assert gcs.command(ARM, 0) == mavlink.MAV_RESULT_DENIED
    assert gcs.recv("HEARTBEAT", 3.0).base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    assert gcs.command(ARM, 0, 21196) == mavlink.MAV_RESULT_ACCEPTED
    assert gcs.recv("HEARTBEAT", 3.0, lambda m: not m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
