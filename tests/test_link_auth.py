"""What the companion believes (companion/link/auth.py): the vehicle's ids, the
address of its first heartbeat, signatures, plausible vehicle time; the rules
alone and through a real Connection on loopback UDP."""

from __future__ import annotations

import socket
import time

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.link import Connection
from companion.link.auth import VehicleFilter
from mavcore.link.signing import SignatureVerifier, enable_outgoing_signing

VEH, SPOOF = ("127.0.0.1", 40001), ("127.0.0.1", 40002)
KEY = bytes(range(32))
T0 = 2 * 10**13


def _mav(sysid=1, compid=1, key=None, ts=T0):
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    if key is not None:
        enable_outgoing_signing(mav, key, 0, ts)
    return mav


def _msg(mav, m):
    """``m`` packed by ``mav`` and parsed back (a received message, raw bytes kept)."""
    return mavlink.MAVLink(None).parse_buffer(bytes(m.pack(mav)))[0]


def hb(mav):
    return _msg(mav, mav.heartbeat_encode(2, 12, 0, 0, 3))


def imu(mav, t_us):
    return _msg(mav, mav.highres_imu_encode(t_us, *([0.0] * 13), 0, 0))


def lpos(mav, t_ms):
    return _msg(mav, mav.local_position_ned_encode(t_ms, 0, 0, 0, 0, 0, 0))


def test_ids_then_first_heartbeat_binds_the_address():
    f, v = VehicleFilter(), _mav()
    assert not f.accept(imu(v, 4000), VEH)                 # nothing before the vehicle's heartbeat
    assert not f.accept(hb(_mav(1, 191)), VEH)             # not the vehicle's component
    assert f.accept(hb(v), VEH)
    assert not f.accept(hb(v), SPOOF)                      # sysid 1 from another port
    assert not f.accept(imu(v, 4000), SPOOF)
    assert f.accept(imu(v, 4000), VEH)
    s = f.stats(bad_packets=2)
    assert (s.received, s.accepted, s.before_heartbeat, s.foreign_id, s.foreign_address) == (6, 2, 1, 1, 2)
    assert s.vehicle_address == "127.0.0.1:40001" and s.bad_packets == 2 and s.dropped == 4
    assert s.to_dict()["dropped"] == 4


def test_time_jumps_dropped_clock_never_moved_by_one_frame():
    f, v = VehicleFilter(max_time_jump_s=1.0, resync_frames=25), _mav()
    assert f.accept(hb(v), VEH)
    t = 10_000_000
    for k in range(10):
        assert f.accept(imu(v, t + 4000 * k), VEH)
    t += 36_000
    assert not f.accept(imu(v, t + 24_000_000), VEH)       # one spoofed frame 24 s ahead
    assert not f.accept(imu(v, t - 5_000_000), VEH)        # ... or 5 s back
    assert f.clock_s == pytest.approx(t * 1e-6)
    assert f.accept(imu(v, t + 4000), VEH)                 # the real stream goes on
    assert f.accept(lpos(v, (t + 4000) // 1000), VEH)
    assert not f.accept(lpos(v, (t + 4000) // 1000 + 1500), VEH)   # a timed message 1.5 s off
    assert f.stats().time_jump == 3


def test_agreeing_jumped_frames_re_anchor_the_clock():
    f, v = VehicleFilter(max_time_jump_s=1.0, resync_frames=25), _mav()
    f.accept(hb(v), VEH)
    f.accept(imu(v, 1_000_000), VEH)
    later = 60_000_000                                     # the vehicle rebooted, or a long gap
    got = [f.accept(imu(v, later + 4000 * k), VEH) for k in range(30)]
    assert got == [False] * 24 + [True] * 6
    assert f.stats().clock_resyncs == 1 and f.clock_s == pytest.approx((later + 4000 * 29) * 1e-6)
    # jumps that do not agree with each other never re-anchor
    f2 = VehicleFilter(resync_frames=5)
    f2.accept(hb(v), VEH)
    f2.accept(imu(v, 1_000_000), VEH)
    # (alternately 30 s and 50 s ahead: each 20 s away from the previous one)
    assert not any(f2.accept(imu(v, (30 + 20 * (k % 2)) * 1_000_000 + 4000 * k), VEH) for k in range(20))


def test_signing_required_when_keyed():
    f = VehicleFilter(verifier=SignatureVerifier(KEY, T0))
    assert not f.accept(hb(_mav()), VEH)                               # unsigned
    assert not f.accept(hb(_mav(key=bytes(range(1, 33)))), VEH)        # another key
    signed = _mav(key=KEY)
    m = hb(signed)
    assert f.accept(m, VEH)
    assert not f.accept(m, VEH)                                        # replayed
    s = f.stats()
    assert (s.unsigned, s.bad_signature, s.replayed, s.accepted) == (1, 1, 1, 1)


def test_connection_drops_a_spoofed_vehicle_on_real_udp():
    """Companion on ``udpin``: the vehicle (port A) binds by its heartbeat; a
    second process sending sysid 1/1 heartbeats and a far-future HIGHRES_IMU
    from port B is dropped and counted, and our replies go to A only."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    conn = Connection(f"udpin:127.0.0.1:{port}").open()
    veh = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    spoof = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    veh.bind(("127.0.0.1", 0))
    spoof.bind(("127.0.0.1", 0))
    veh.settimeout(1.0)
    spoof.settimeout(0.2)
    v, sp = _mav(), _mav()
    dest = ("127.0.0.1", port)
    try:
        veh.sendto(bytes(v.heartbeat_encode(2, 12, 0, 0, 3).pack(v)), dest)
        got = conn.poll(1.0)
        assert [m.get_type() for m in got] == ["HEARTBEAT"]
        for k in range(5):
            spoof.sendto(bytes(sp.heartbeat_encode(2, 12, 128, 0, 4).pack(sp)), dest)
            spoof.sendto(bytes(sp.highres_imu_encode(24_000_000 + k, *([9.0] * 13), 0, 0).pack(sp)), dest)
        veh.sendto(bytes(v.highres_imu_encode(4000, *([0.0] * 13), 0, 0).pack(v)), dest)
        got = []
        end = time.monotonic() + 2.0
        while time.monotonic() < end and not any(m.get_type() == "HIGHRES_IMU" for m in got):
            got += conn.poll(0.1)
        assert [(m.get_type(), m.time_usec) for m in got if m.get_type() == "HIGHRES_IMU"] == [("HIGHRES_IMU", 4000)]
        assert not [m for m in got if m.get_type() == "HEARTBEAT"]
        s = conn.link_stats()
        assert s.foreign_address == 10 and s.vehicle_address == f"127.0.0.1:{veh.getsockname()[1]}"
        conn.send_heartbeat()
        assert veh.recvfrom(4096)[0]                         # replies go to the vehicle
        with pytest.raises(socket.timeout):
            spoof.recvfrom(4096)                             # ... and never to the spoofer
    finally:
        conn.close()
        veh.close()
        spoof.close()
