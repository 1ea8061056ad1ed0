"""The SITL's control policy and client table (sitl/auth.py), as pure logic:
which messages are control, controllers, control links, address bindings,
signing, one report per source; bounded, expiring clients."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore.link.signing import SignatureVerifier
from sitl.auth import (
    DEFAULT_CONTROLLERS, READ_ONLY_COMMANDS, ClientTable, ControlPolicy, Controller, IntakeBudget, is_control,
    parse_controller,
)
from sitl.server import SitlServer

LISTEN = "udpin:127.0.0.1:14540"
GCS_OUT = "udpout:127.0.0.1:14550"
TELEM = "udpout:127.0.0.1:14560"
A, B = ("127.0.0.1", 40001), ("127.0.0.1", 40002)
KEY = bytes(range(32))
ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM


def policy(**kw):
    return ControlPolicy((LISTEN, GCS_OUT), **kw)


def test_every_handled_message_is_classified():
    """Every message type the SITL acts on is control unless it only reads;
    every command it executes that changes something is control (a new
    handler or command fails here until it is classified)."""
    from mavcore.mission import load_mission
    from test_sitl_mavlink import MISSION

    server = SitlServer(load_mission(MISSION))          # no I/O: nothing is opened
    read_only = {"PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "MISSION_REQUEST_LIST", "MISSION_REQUEST_INT",
                 "MISSION_REQUEST", "TIMESYNC", "PING"}
    handled = set(server._handlers)
    assert {t for t in handled if not is_control(t, -1)} == read_only
    writes = {mavlink.MAV_CMD_COMPONENT_ARM_DISARM, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND,
              mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, mavlink.MAV_CMD_DO_SET_MODE,
              mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAV_CMD_MISSION_START, mavlink.MAV_CMD_DO_REPOSITION}
    reads = {mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, mavlink.MAV_CMD_REQUEST_MESSAGE,
             mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, mavlink.MAV_CMD_GET_HOME_POSITION}
    assert set(server.commands.handlers) == writes | reads
    for cmd in writes:
        assert is_control("COMMAND_LONG", cmd) and is_control("COMMAND_INT", cmd)
    for cmd in READ_ONLY_COMMANDS:
        assert not is_control("COMMAND_LONG", cmd)
    assert is_control("COMMAND_LONG", 31999)           # unknown commands: deny by default
    assert is_control("RC_CHANNELS_OVERRIDE")          # unknown types: deny by default


def test_defaults_accept_companion_and_ground_stations_only():
    p = policy()
    for i, c in enumerate(DEFAULT_CONTROLLERS):
        v = p.authorize(LISTEN, ("127.0.0.1", 41000 + i), "COMMAND_LONG", ARM, c.sysid, c.compid, None, 0.0)
        assert v.accepted and v.bindings_changed
    v = p.authorize(LISTEN, A, "COMMAND_LONG", ARM, 42, 1, None, 0.0)
    assert not v.accepted and v.reason == "not a controller"
    assert v.report == f"ignored COMMAND_LONG from 42/1 at 127.0.0.1:40001 on {LISTEN}: not a controller"
    # read-only requests from anyone, and they never bind
    assert p.authorize(LISTEN, A, "PARAM_REQUEST_LIST", None, 42, 1, None, 0.0) == p.authorize(
        LISTEN, B, "COMMAND_LONG", mavlink.MAV_CMD_REQUEST_MESSAGE, 42, 1, None, 0.0)
    assert p.authorize(LISTEN, A, "PARAM_REQUEST_LIST", None, 42, 1, None, 0.0).accepted


def test_telemetry_link_and_per_link_controller():
    p = ControlPolicy((LISTEN, GCS_OUT), (Controller(1, 191), Controller(255, 190, GCS_OUT)))
    assert not p.authorize(TELEM, None, "SET_MODE", None, 1, 191, None, 0.0).accepted
    assert p.authorize(TELEM, None, "SET_MODE", None, 1, 191, None, 0.0).reason.startswith("not a control link")
    v = p.authorize(LISTEN, A, "SET_MODE", None, 255, 190, None, 0.0)
    assert not v.accepted and v.reason == "not a controller on this link"
    assert p.authorize(GCS_OUT, None, "SET_MODE", None, 255, 190, None, 0.0).accepted
    with pytest.raises(ValueError):
        ControlPolicy((LISTEN,), (Controller(1, 191, TELEM),))


def test_binding_foreign_port_rebind_after_silence_and_observe():
    """(wall s, vehicle s) pairs: a binding moves only after 3 s of silence in both."""
    p = policy(rebind_after_s=3.0)
    assert p.authorize(LISTEN, A, "HIL_ACTUATOR_CONTROLS", None, 1, 191, None, 10.0, 100.0).accepted
    assert p.binding(1, 191) == (LISTEN, A)
    v = p.authorize(LISTEN, B, "HIL_ACTUATOR_CONTROLS", None, 1, 191, None, 11.0, 101.0)   # spoofed, other port
    assert not v.accepted and v.reason == "controller ids in use from another address"
    p.observe(LISTEN, A, 1, 191, 12.5, 102.5)              # a heartbeat from A keeps the binding
    assert not p.authorize(LISTEN, B, "SET_MODE", None, 1, 191, None, 15.0, 105.0).accepted
    # 5 s of wall clock but the vehicle clock stood still (a SITL busy with a backlog): no move
    assert not p.authorize(LISTEN, B, "SET_MODE", None, 1, 191, None, 17.5, 102.6).accepted
    # 30 s of vehicle time in 1 s of wall clock (a fast simulation): no move either
    assert not p.authorize(LISTEN, B, "SET_MODE", None, 1, 191, None, 13.5, 132.5).accepted
    v = p.authorize(LISTEN, B, "SET_MODE", None, 1, 191, None, 15.6, 105.6)   # A silent 3.1 s in both: B
    assert v.accepted and v.bindings_changed and "moved" in v.report
    assert p.bound_addresses(LISTEN) == {B}
    assert p.counts["rebound"] == 1
    assert p.summary()["accepted_from"] == [
        {"link": LISTEN, "address": "127.0.0.1:40001", "sysid": 1, "compid": 191, "messages": 1},
        {"link": LISTEN, "address": "127.0.0.1:40002", "sysid": 1, "compid": 191, "messages": 1}]


def test_one_report_per_source_and_bounded():
    p = policy()
    first = p.authorize(LISTEN, A, "PARAM_SET", None, 42, 1, None, 0.0)
    again = p.authorize(LISTEN, A, "SET_MODE", None, 42, 1, None, 0.0)
    assert first.report and again.report is None and not again.accepted
    reports = [p.authorize(LISTEN, ("127.0.0.1", 50000 + i), "PARAM_SET", None, 42, 1, None, 0.0).report
               for i in range(200)]
    sent = [r for r in reports if r]
    assert len(sent) == ControlPolicy.MAX_REPORTED_SOURCES          # 63 more + the overflow notice
    assert "more than" in sent[-1]
    assert p.counts["not a controller"] == 202


def _signed(key, sysid=1, compid=191, ts=10**9, cmd=True):
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.timestamp = key, True, ts
    m = (mav.command_long_encode(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0) if cmd
         else mav.setup_signing_encode(1, 1, list(bytes(32)), 0))
    return bytes(m.pack(mav))


def test_signing_rules():
    p = policy(verifier=SignatureVerifier(KEY, 10**9), key_locked=True)
    unsigned = bytes(mavlink.MAVLink(None, 1, 191).command_long_encode(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)
                     .pack(mavlink.MAVLink(None, 1, 191)))
    assert p.authorize(LISTEN, A, "COMMAND_LONG", ARM, 1, 191, unsigned, 0.0).reason == "unsigned"
    assert p.authorize(LISTEN, A, "COMMAND_LONG", ARM, 1, 191, _signed(OTHER_KEY), 0.0).reason == "bad signature"
    good = _signed(KEY, ts=10**9 + 5)
    assert p.authorize(LISTEN, A, "COMMAND_LONG", ARM, 1, 191, good, 0.0).accepted
    assert p.authorize(LISTEN, A, "COMMAND_LONG", ARM, 1, 191, good, 0.1).reason == "replayed signature"
    # with a valid signature the binding follows at once (the key is the proof)
    assert p.authorize(LISTEN, B, "COMMAND_LONG", ARM, 1, 191, _signed(KEY, ts=10**9 + 9), 0.2).accepted
    assert p.binding(1, 191) == (LISTEN, B)
    # a key from the command line cannot be changed over the air, even signed
    v = p.authorize(LISTEN, B, "SETUP_SIGNING", None, 1, 191, _signed(KEY, ts=10**9 + 20, cmd=False), 0.3)
    assert not v.accepted and "command line" in v.reason
    # read-only requests stay open without a signature
    assert p.authorize(LISTEN, A, "PARAM_REQUEST_READ", None, 42, 1, unsigned, 0.4).accepted
    with pytest.raises(RuntimeError):
        p.set_signing(None)


OTHER_KEY = bytes(range(1, 33))


def test_parse_controller():
    assert parse_controller("255/190") == Controller(255, 190)
    assert parse_controller(" 1 / 191 @udpin:127.0.0.1:5 ") == Controller(1, 191, "udpin:127.0.0.1:5")
    for bad in ("255", "a/b", "0/1", "256/1", "1/256", "1/2/3"):
        with pytest.raises(ValueError):
            parse_controller(bad)


def test_client_table_bounded_lru_pinned_and_expiring():
    t = ClientTable(max_clients=3, expiry_s=5.0)
    for i in range(3):
        t.admit(("h", i), float(i))
    t.admit(("h", 0), 3.0)                     # 0 heard again: 1 is now the oldest
    t.pinned = {("h", 1)}
    t.admit(("h", 9), 3.5)                     # full: the oldest unpinned (2) makes room
    assert set(t) == {("h", 0), ("h", 1), ("h", 9)} and t.n_evicted == 1
    for k in range(1000):                      # a flood of new source ports stays bounded
        t.admit(("x", k), 4.0 + k * 1e-3)
    assert len(t) == 3 and ("h", 1) in t      # and never pushes the pinned controller out
    t.admit(("x", 5000), 20.0)                 # 15 s later: the silent ones expire at the sweep
    assert set(t) == {("h", 1), ("x", 5000)} and t.n_expired >= 1
    t.pinned = set()
    t.admit(("y", 1), 30.0)                    # 10 s and 29 s of silence: both expired
    assert set(t) == {("y", 1)}
    with pytest.raises(ValueError):
        ClientTable(0, 1.0)


def test_intake_budget_sheds_floods_from_unbound_sources():
    b = IntakeBudget(max_bytes=1024, rate_hz=100.0, burst=10)
    assert not b.admit(1025, 0.0) and b.n_oversized == 1          # no ground station sends that
    assert [b.admit(300, 0.0) for _ in range(12)] == [True] * 10 + [False] * 2   # the burst
    assert b.admit(300, 0.011) and not b.admit(300, 0.011)        # 11 ms at 100/s: one token back
    # a steady 1000/s flood for one second: 100 pass (the rate), the rest are dropped unparsed
    passed = sum(b.admit(100, 1.0 + k * 1e-3) for k in range(1000))
    assert passed == pytest.approx(100 + 10, abs=2) and b.n_over_rate > 800
    with pytest.raises(ValueError):
        IntakeBudget(max_bytes=100)


def test_release_frees_a_closed_controller_and_forget_unpins():
    p = policy()
    assert p.authorize(LISTEN, A, "SET_MODE", None, 255, 190, None, 0.0, 0.0).accepted
    assert p.release(LISTEN, B) == [] and p.release(LISTEN, A) == [(255, 190)]
    assert p.binding(255, 190) is None and p.counts["released"] == 1
    assert p.authorize(LISTEN, B, "SET_MODE", None, 255, 190, None, 0.1, 0.1).accepted   # at once
    t = ClientTable(2, 5.0)
    t.admit(A, 0.0)
    t.pinned = {A}
    t.forget(A)
    assert A not in t and A not in t.pinned
