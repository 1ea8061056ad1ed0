"""sitl.auth's control rules at their edges (issue 19: each safety rule's test must fail when
the rule is broken; ``benchmarks/mutation.py`` checks it). Times are passed in: no clock."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore.link.signing import SignatureVerifier
from sitl.auth import (
    DEFAULT_CONTROLLERS, READ_ONLY_COMMANDS, READ_ONLY_MESSAGES, ClientTable, ControlPolicy, Controller,
    IntakeBudget, is_control, parse_controller,
)

LISTEN = "udpin:127.0.0.1:14540"
GCS_OUT = "udpout:127.0.0.1:14550"
A, B = ("127.0.0.1", 40001), ("127.0.0.1", 40002)
KEY = bytes(range(32))


def policy(**kw):
    return ControlPolicy((LISTEN, GCS_OUT), **kw)


def ctl(p, addr, now, vehicle, link=LISTEN, ids=(1, 191), msg="SET_MODE", packet=None):
    return p.authorize(link, addr, msg, None, ids[0], ids[1], packet, now, vehicle)


# --------------------------------------------------------------------------- classification
def test_read_only_sets_are_the_documented_ones():
    assert READ_ONLY_MESSAGES == {
        "HEARTBEAT", "PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_EXT_REQUEST_LIST",
        "PARAM_EXT_REQUEST_READ", "MISSION_REQUEST_LIST", "MISSION_REQUEST_INT", "MISSION_REQUEST",
        "MISSION_REQUEST_PARTIAL_LIST", "MISSION_ACK", "TIMESYNC", "PING"}
    assert mavlink.MAV_CMD_COMPONENT_ARM_DISARM not in READ_ONLY_COMMANDS
    assert len(READ_ONLY_COMMANDS) == 12


@pytest.mark.parametrize("msg", ["COMMAND_LONG", "COMMAND_INT"])
def test_commands_are_control_unless_read_only(msg):
    assert not is_control(msg, mavlink.MAV_CMD_REQUEST_MESSAGE)
    assert is_control(msg, mavlink.MAV_CMD_COMPONENT_ARM_DISARM)
    assert is_control(msg, None)
    assert not is_control("PING") and is_control("SET_MODE")


# --------------------------------------------------------------------------- controllers
@pytest.mark.parametrize("ids,ok", [((1, 0), True), ((255, 255), True), ((0, 1), False), ((256, 1), False),
                                    ((1, -1), False), ((1, 256), False)])
def test_controller_ids_in_range(ids, ok):
    if ok:
        assert Controller(*ids).sysid == ids[0]
    else:
        with pytest.raises(ValueError):
            Controller(*ids)


def test_controller_text_and_parse_round_trip():
    assert str(Controller(1, 191)) == "1/191"
    assert str(Controller(255, 190, GCS_OUT)) == f"255/190@{GCS_OUT}"
    assert parse_controller(str(Controller(255, 190, GCS_OUT))) == Controller(255, 190, GCS_OUT)
    assert DEFAULT_CONTROLLERS == (Controller(1, 191), Controller(255, 190), Controller(245, 190),
                                   Controller(255, 230))


def test_a_controller_listed_twice_gets_the_union_of_its_links():
    p = ControlPolicy((LISTEN, GCS_OUT), (Controller(9, 9, LISTEN), Controller(9, 9, GCS_OUT)))
    assert ctl(p, A, 0.0, 0.0, ids=(9, 9)).accepted
    assert ctl(p, None, 0.0, 0.0, link=GCS_OUT, ids=(9, 9)).reason == "controller ids in use from another address"
    q = ControlPolicy((LISTEN, GCS_OUT), (Controller(9, 9, GCS_OUT),))
    assert ctl(q, A, 0.0, 0.0, ids=(9, 9)).reason == "not a controller on this link"


# --------------------------------------------------------------------------- bindings
@pytest.mark.parametrize("silence,moves", [(3.0, False), (3.001, True)])
def test_rebinding_needs_more_than_rebind_after_s_in_both_clocks(silence, moves):
    """Default rebind_after_s = 3 s: silent exactly 3 s keeps the binding, 3.001 s moves it."""
    p = policy()
    assert ctl(p, A, 10.0, 100.0).accepted
    v = ctl(p, B, 10.0 + silence, 100.0 + silence)
    assert v.accepted is moves
    assert p.binding(1, 191) == (LISTEN, B if moves else A)
    if moves:
        assert v.bindings_changed and v.report == f"controller 1/191 moved, now at 127.0.0.1:40002 on {LISTEN}"
        assert p.counts["rebound"] == 1 and p.summary()["rebound"] == 1
    else:
        assert v.reason == "controller ids in use from another address"


@pytest.mark.parametrize("wall,vehicle", [(10.0, 2.9), (2.9, 10.0)])
def test_rebinding_needs_silence_in_both_clocks(wall, vehicle):
    """Silent 10 s by one clock but only 2.9 s by the other: the binding stays."""
    p = policy(rebind_after_s=3.0)
    assert ctl(p, A, 0.0, 0.0).accepted
    assert not ctl(p, B, wall, vehicle).accepted
    assert p.binding(1, 191) == (LISTEN, A)


def test_traffic_from_the_bound_address_keeps_the_binding_alive():
    p = policy(rebind_after_s=3.0)
    ctl(p, A, 0.0, 0.0)
    assert ctl(p, A, 2.0, 2.0).accepted                          # refreshes (wall and vehicle)
    assert not ctl(p, B, 4.0, 4.0).accepted                      # A last heard at 2 s
    assert ctl(p, B, 5.1, 5.1).accepted


def test_observe_refreshes_only_the_bound_address_on_its_link():
    p = policy(rebind_after_s=3.0)
    ctl(p, A, 0.0, 0.0)
    p.observe(LISTEN, B, 1, 191, 2.0, 2.0)                       # another address: no refresh
    p.observe(GCS_OUT, A, 1, 191, 2.0, 2.0)                      # another link: no refresh
    p.observe(LISTEN, A, 1, 190, 2.0, 2.0)                       # other ids: no refresh
    assert ctl(p, B, 3.5, 3.5).accepted
    p = policy(rebind_after_s=3.0)
    ctl(p, A, 0.0, 0.0)
    p.observe(LISTEN, A, 1, 191, 2.0, 2.0)
    assert not ctl(p, B, 3.5, 3.5).accepted and ctl(p, B, 5.1, 5.1).accepted


def test_observe_refreshes_the_vehicle_clock_too():
    p = policy(rebind_after_s=3.0)
    ctl(p, A, 0.0, 0.0)
    p.observe(LISTEN, A, 1, 191, 0.0, 2.0)                       # wall stood, vehicle clock moved
    assert not ctl(p, B, 4.0, 4.0).accepted                      # vehicle: 2 s of silence only


def test_the_first_binding_is_reported_as_a_change_and_later_traffic_is_not():
    p = policy()
    v = ctl(p, A, 0.0, 0.0)
    assert v.accepted and v.bindings_changed and v.report is None
    v = ctl(p, A, 0.1, 0.1)
    assert v.accepted and not v.bindings_changed
    assert p.bound_addresses(LISTEN) == {A} and p.bound_addresses(GCS_OUT) == set()
    assert p.binding(255, 190) is None


def test_bindings_are_per_link():
    p = policy()
    assert ctl(p, None, 0.0, 0.0, link=GCS_OUT).accepted
    assert not ctl(p, None, 1.0, 1.0, link=LISTEN).accepted      # same ids, same (None) address, other link
    assert ctl(p, None, 1.0, 1.0, link=GCS_OUT).accepted


def test_release_only_on_the_given_link():
    p = policy()
    ctl(p, A, 0.0, 0.0)
    assert p.release(GCS_OUT, A) == []
    assert p.binding(1, 191) == (LISTEN, A)
    assert p.release(LISTEN, A) == [(1, 191)] and p.summary()["released"] == 1


# --------------------------------------------------------------------------- signing
def _signed(ts, sysid=1, compid=191, key=KEY, setup=False):
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.timestamp = key, True, ts
    m = (mav.setup_signing_encode(1, 1, list(bytes(32)), 0) if setup
         else mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
    return bytes(m.pack(mav))


def test_signed_traffic_from_the_bound_address_is_not_a_binding_change():
    p = policy(verifier=SignatureVerifier(KEY, 10**9))
    v = ctl(p, A, 0.0, 0.0, packet=_signed(10**9 + 1))
    assert v.accepted and v.bindings_changed
    v = ctl(p, A, 0.1, 0.1, packet=_signed(10**9 + 2))
    assert v.accepted and not v.bindings_changed
    v = ctl(p, A, 0.2, 0.2, link=GCS_OUT, packet=_signed(10**9 + 3))     # same address, other link
    assert v.accepted and v.bindings_changed
    assert p.summary()["signing"] is True


def test_signing_without_a_packet_is_unsigned():
    p = policy(verifier=SignatureVerifier(KEY, 10**9))
    v = ctl(p, A, 0.0, 0.0, packet=None)
    assert not v.accepted and v.reason == "unsigned"


def test_setup_signing_allowed_when_the_key_is_not_locked():
    p = policy(verifier=SignatureVerifier(KEY, 10**9))
    assert not p.key_locked
    assert p.authorize(LISTEN, A, "SETUP_SIGNING", None, 1, 191, _signed(10**9 + 1, setup=True), 0.0).accepted
    p.set_signing(None)
    assert not p.signing and p.summary()["signing"] is False
    q = policy(key_locked=True)                                  # no key: nothing to lock
    assert not q.key_locked
    q.set_signing(SignatureVerifier(KEY, 0))
    assert q.signing


# --------------------------------------------------------------------------- reports and summary
def test_reports_bounded_at_max_reported_sources_plus_one_notice():
    p = policy()
    assert ControlPolicy.MAX_REPORTED_SOURCES == 64
    reports = [ctl(p, ("127.0.0.1", 50000 + i), 0.0, 0.0, ids=(42, 1)).report for i in range(70)]
    assert all(reports[:64]) and reports[64] == "ignoring control from more than 64 sources: not reported"
    assert reports[65:] == [None] * 5
    assert p.summary()["ignored"] == {"not a controller": 70}


def test_summary_counts_and_addresses():
    p = policy()
    ctl(p, A, 0.0, 0.0)
    ctl(p, A, 0.1, 0.1)
    ctl(p, None, 0.2, 0.2, link=GCS_OUT, ids=(255, 190))
    ctl(p, B, 0.3, 0.3)
    s = p.summary()
    assert s["accepted"] == 3 and s["rebound"] == 0 and s["released"] == 0
    assert s["accepted_from"] == [
        {"link": LISTEN, "address": "127.0.0.1:40001", "sysid": 1, "compid": 191, "messages": 2},
        {"link": GCS_OUT, "address": None, "sysid": 255, "compid": 190, "messages": 1}]
    assert s["ignored"] == {"controller ids in use from another address": 1}


def test_report_names_where_for_each_address_kind():
    p = policy()
    assert ctl(p, None, 0.0, 0.0, ids=(42, 1)).report == f"ignored SET_MODE from 42/1 on {LISTEN}: not a controller"
    assert ctl(p, 7, 0.0, 0.0, ids=(42, 1)).report == f"ignored SET_MODE from 42/1 on {LISTEN}: not a controller"
    assert ctl(p, ("h",), 0.0, 0.0, ids=(42, 1)).report.endswith(f"on {LISTEN}: not a controller")


# --------------------------------------------------------------------------- client table
def test_client_table_expiry_is_strictly_after_expiry_s():
    t = ClientTable(max_clients=4, expiry_s=4.0)
    t.admit(A, 0.0)
    t.admit(B, 4.0)                       # sweep at 4.0: A silent exactly 4 s stays
    assert A in t and len(t) == 2 and bool(t)
    t.admit(("h", 1), 6.0)                # sweep (every min(1 s, expiry/2)): A silent 6 s goes
    assert A not in t and t.n_expired == 1 and list(t) == [B, ("h", 1)]


def test_client_table_sweeps_every_min_one_second_or_half_the_expiry():
    t = ClientTable(max_clients=4, expiry_s=0.5)
    assert t._sweep_every == 0.25
    t.admit(A, 0.0)
    t.admit(A, 0.1)                       # heard again: no sweep until 0.25
    t.admit(B, 0.7)                       # sweep: A silent 0.6 s > 0.5 s
    assert A not in t
    assert ClientTable(2, 10.0)._sweep_every == 1.0


def test_client_table_known_client_skips_the_sweep_until_due():
    t = ClientTable(max_clients=4, expiry_s=1.0)
    t.admit(A, 0.0)
    t.admit(B, 0.1)                       # next sweep at 0.5 (half the expiry)
    t.admit(B, 1.2)                       # due: A (silent 1.2 s) expires
    assert A not in t and B in t
    t.admit(("h", 1), 1.3)
    t.admit(B, 2.5)                       # sweep due at 1.7: ("h", 1) silent 1.2 s expires
    assert ("h", 1) not in t


def test_client_table_evicts_only_when_full_and_refuses_when_all_pinned():
    t = ClientTable(max_clients=2, expiry_s=100.0)
    t.admit(A, 0.0)
    t.admit(B, 0.1)
    assert t.n_evicted == 0 and len(t) == 2
    t.pinned = {A, B}
    t.admit(("h", 1), 0.2)
    assert ("h", 1) not in t and len(t) == 2 and t.n_evicted == 0
    t.pinned = {B}
    t.admit(("h", 1), 0.3)
    assert set(t) == {B, ("h", 1)} and t.n_evicted == 1
    assert not ClientTable(1, 1.0)


@pytest.mark.parametrize("args", [(0, 1.0), (1, 0.0), (1, -1.0)])
def test_client_table_settings(args):
    with pytest.raises(ValueError):
        ClientTable(*args)
    assert ClientTable(1, 1e-3).max_clients == 1


# --------------------------------------------------------------------------- intake budget
def test_intake_size_limit_is_inclusive():
    b = IntakeBudget(max_bytes=300, rate_hz=1.0, burst=5)
    assert b.admit(300, 0.0) and not b.admit(301, 0.0)
    assert b.n_oversized == 1 and b.n_over_rate == 0


def test_intake_tokens_refill_at_the_rate_up_to_the_burst():
    b = IntakeBudget(max_bytes=300, rate_hz=10.0, burst=2)
    assert [b.admit(10, 0.0) for _ in range(3)] == [True, True, False]
    assert b.admit(10, 0.1) and not b.admit(10, 0.1)               # 0.1 s at 10/s: exactly one token
    assert [b.admit(10, 100.0) for _ in range(3)] == [True, True, False]   # refilled to the burst only
    assert not b.admit(10, 50.0)                                   # time going back refills nothing
    assert b.n_over_rate == 4


def test_intake_half_a_token_is_not_enough():
    b = IntakeBudget(max_bytes=300, rate_hz=10.0, burst=1)
    assert b.admit(10, 0.0)
    assert not b.admit(10, 0.05)
    assert b.admit(10, 0.1)


@pytest.mark.parametrize("kw", [{"max_bytes": 279}, {"rate_hz": 0.0}, {"burst": 0}])
def test_intake_settings(kw):
    with pytest.raises(ValueError):
        IntakeBudget(**kw)
    b = IntakeBudget(max_bytes=280, rate_hz=1e-3, burst=1)
    assert (b.max_bytes, b.burst) == (280, 1.0)


def test_vehicle_time_defaults_to_zero():
    """authorize/observe without a vehicle time count it as 0 s (a caller with no vehicle clock)."""
    p = policy(rebind_after_s=0.5)
    assert p.authorize(LISTEN, A, "SET_MODE", None, 1, 191, None, 0.0, 0.0).accepted
    assert not p.authorize(LISTEN, B, "SET_MODE", None, 1, 191, None, 10.0).accepted   # vehicle 0 - 0
    q = policy(rebind_after_s=3.0)
    assert q.authorize(LISTEN, A, "SET_MODE", None, 1, 191, None, 0.0, 5.0).accepted
    q.observe(LISTEN, A, 1, 191, 10.0)                   # vehicle time 0
    assert q.authorize(LISTEN, B, "SET_MODE", None, 1, 191, None, 20.0, 3.2).accepted


@pytest.mark.parametrize("wall,vehicle", [(3.0, 10.0), (10.0, 3.0)])
def test_silence_of_exactly_rebind_after_s_in_one_clock_keeps_the_binding(wall, vehicle):
    p = policy(rebind_after_s=3.0)
    assert ctl(p, A, 0.0, 0.0).accepted
    assert not ctl(p, B, wall, vehicle).accepted


def test_signed_control_is_counted_as_accepted():
    p = policy(verifier=SignatureVerifier(KEY, 10**9))
    ctl(p, A, 0.0, 0.0, packet=_signed(10**9 + 1))
    ctl(p, A, 0.1, 0.1, packet=_signed(10**9 + 2))
    s = p.summary()
    assert s["accepted"] == 2 and s["accepted_from"][0]["messages"] == 2
