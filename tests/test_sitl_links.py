"""The SITL's protocol parts (sitl.mission_link, sitl.params_link,
sitl.setpoints) driven without sockets: decoded messages in, what each part
sends to the requester's link, broadcasts and says out."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore.frames import enu2geodetic

GCS = (255, 190)


class FakeLink:
    """What a part uses of ``sitl.link.Link``: its encoder, the requester's
    address and ``reply``; ``send`` for the value a PARAM_SET leaves."""

    def __init__(self):
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self.last_addr = ("127.0.0.1", 14550)
        self.has_peer = True
        self.replies, self.sent = [], []

    def reply(self, msg, addr=None):
        self.replies.append((msg, addr))

    def send(self, msg):
        self.sent.append(msg)


def received(encode):
    """A message as the vehicle receives it from the ground station (packed and parsed)."""
    gcs = mavlink.MAVLink(None, srcSystem=GCS[0], srcComponent=GCS[1])
    buf = encode(gcs).pack(gcs)
    return mavlink.MAVLink(None).parse_char(buf)


@pytest.fixture
def srv():
    from mavcore.mission import load_mission
    from sitl.server import SitlServer
    from test_sitl_mavlink import MISSION

    s = SitlServer(load_mission(MISSION))      # no I/O: nothing is opened
    s.step_once()
    return s


def test_a_two_item_upload_is_requested_item_by_item_acked_and_flown(srv):
    from sitl.mission_link import VehicleMission

    out, said, refused = [], [], []
    v = srv.vehicle
    part = VehicleMission(10, v.sim, v.stack, v.params, v.autopilot, v.origin, v.home_enu_m,
                          srv.vehicle.state, srv._mav, out.append, lambda sev, text: said.append(text),
                          lambda kind, why: refused.append(kind))
    link = FakeLink()
    o = srv.vehicle.origin
    h = srv.vehicle.home_enu_m
    points = [enu2geodetic(h[0] + 5.0 * k, h[1], 0.0, o.lat_deg, o.lon_deg, o.alt_m) for k in (1, 2)]
    part.on_count(link, received(lambda m: m.mission_count_encode(1, 1, 2, 0)))
    for seq, (lat, lon, _) in enumerate(points):
        part.on_item_int(link, received(lambda m: m.mission_item_int_encode(
            1, 1, seq, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mavlink.MAV_CMD_NAV_WAYPOINT, 0, 1,
            0.0, 0.0, 0.0, math.nan, round(lat * 1e7), round(lon * 1e7), 2.0, 0)))
    kinds = [(m.get_type(), getattr(m, "seq", None)) for m, _ in link.replies]
    assert kinds == [("MISSION_REQUEST_INT", 0), ("MISSION_REQUEST_INT", 1), ("MISSION_ACK", None)]
    assert all((m.target_system, m.target_component) == GCS for m, _ in link.replies)
    assert link.replies[-1][0].type == mavlink.MAV_MISSION_ACCEPTED
    assert len(srv.vehicle.stack.mission.items) == 2 and refused == []
    assert said == ["Mission stored: 2 items"]
    current = [m for m in out if m.get_type() == "MISSION_CURRENT"]
    assert [(m.seq, m.total) for m in current] == [(0, 2)]      # the new mission, at its first item


def test_upload_re_requests_on_the_vehicle_clock_not_the_wall_clock(srv, monkeypatch):
    """A silent uploader is asked again for the awaited item after ``MissionServer.RETRY_S``
    (0.5 s) of vehicle time, not before, with the wall clock frozen (so no wall time passes);
    after ``MAX_RETRIES`` (5) re-requests the upload is cancelled. The clock is the
    simulation's (``sim.time_us``), stepped here by hand in microseconds."""
    import time

    from mavcore.services.mission import MissionServer

    frozen = time.monotonic()
    monkeypatch.setattr(time, "monotonic", lambda: frozen)
    monkeypatch.setattr(time, "time", lambda: 1.8e9)
    part = srv.mission_link
    sim = srv.vehicle.sim
    link = FakeLink()
    t0 = sim.time_us
    part.on_count(link, received(lambda m: m.mission_count_encode(1, 1, 2, 0)))
    assert [(m.get_type(), m.seq) for m, _ in link.replies] == [("MISSION_REQUEST_INT", 0)]
    retry_us = round(MissionServer.RETRY_S * 1e6)
    sim.time_us = t0 + retry_us - 1                 # 1 us short of the retry: nothing
    part.tick()
    assert len(link.replies) == 1
    sim.time_us = t0 + retry_us                     # the retry is due
    part.tick()
    assert [(m.get_type(), m.seq) for m, _ in link.replies[1:]] == [("MISSION_REQUEST_INT", 0)]
    assert link.replies[1][1] == link.last_addr     # to the uploader's address
    part.tick()                                     # the clock did not move: no second re-request
    assert len(link.replies) == 2
    for k in range(2, MissionServer.MAX_RETRIES + 1):
        sim.time_us = t0 + k * retry_us
        part.tick()
    assert [m.get_type() for m, _ in link.replies].count("MISSION_REQUEST_INT") == 1 + MissionServer.MAX_RETRIES
    sim.time_us = t0 + (MissionServer.MAX_RETRIES + 1) * retry_us
    part.tick()
    last = link.replies[-1][0]
    assert last.get_type() == "MISSION_ACK" and last.type == mavlink.MAV_MISSION_OPERATION_CANCELLED
    assert not part.server.uploading


def test_param_set_applies_and_sends_the_value_held_to_every_link(srv):
    from sitl.params_link import VehicleParams

    links, changed = [FakeLink(), FakeLink()], []
    v = srv.vehicle
    part = VehicleParams(v.params, v.autopilot, v.sim, v.collision_prevention, lambda: links,
                         lambda sev, text: None, lambda: changed.append(True))
    part.on_set(links[0], received(lambda m: m.param_set_encode(
        1, 1, b"MPC_XY_VEL_MAX", 3.5, mavlink.MAV_PARAM_TYPE_REAL32)))
    assert srv.vehicle.params["MPC_XY_VEL_MAX"] == 3.5 and changed == [True]
    part.apply()
    assert srv.vehicle.sim.onboard.gains.max_speed_xy_m_s == 3.5          # pushed into the onboard controller
    for link in links:
        assert [(m.param_id, m.param_value) for m in link.sent] == [("MPC_XY_VEL_MAX", 3.5)]


def test_set_mode_without_the_custom_flag_is_refused(srv):
    refused = []
    from sitl.setpoints import VehicleSetpoints
    part = VehicleSetpoints(srv.vehicle.sim, srv.vehicle.stack, srv.vehicle.collision_prevention, srv.vehicle.state,
                            lambda kind, why: refused.append(kind))
    mode = srv.vehicle.stack.mode
    part.on_set_mode(FakeLink(), received(lambda m: m.set_mode_encode(1, 0, 0)))
    assert refused == ["SET_MODE"] and srv.vehicle.stack.mode is mode
