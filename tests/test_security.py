"""Attacks on the SITL over real UDP on loopback (sitl/auth.py in place).

The attack matrix: a legitimate ground station (255/190) uploads a mission,
sets a parameter and has the vehicle hover at 2 m; then every control
message the SITL acts on is sent from a foreign system id, from the ground
station's own ids on another source port, back through a telemetry-only
``--out`` link and, with signing on, with a wrong key, unsigned and as a
replay of the ground station's own signed packets. Nothing may change:
state, mode, position, parameters, mission, message intervals and signing
are read back over MAVLink, and every attack message is counted as ignored.
With signing on the ground station is plain pymavlink (``setup_signing``)
with the key MAVProxy derives from the same passphrase as the SITL's key
file, so a MAVProxy/pymavlink user with the passphrase still talks to it.
"""

from __future__ import annotations

import math
import socket
import time

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from sitl.api import SitlThread, free_udp_port
from test_sitl_mavlink import MISSION, Client

PASSPHRASE = "rows-and-vines"
NAN = float("nan")
CUSTOM = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
HOLD_Z_M = 2.0
PARAM, PARAM_VALUE = "MPC_XY_VEL_MAX", 4.0
WAYPOINTS = [(448000000 + 1000 * i, -6000000 - 500 * i, 2.5 + i) for i in range(3)]
HB = mavlink.MAVLINK_MSG_ID_HEARTBEAT


def attack_packets(mav) -> list[tuple[str, bytes]]:
    """Every control message the SITL acts on, packed by ``mav``: (type, packet).
    Each goes in a datagram of its own; the last one puts a HIL_ACTUATOR_CONTROLS
    behind a heartbeat (the generic parser instead of the lockstep fast path)."""
    cmds = [
        (mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (0, 21196, 0, 0, 0, 0, 0)),      # force disarm in flight
        (mavlink.MAV_CMD_NAV_LAND, (0, 0, 0, NAN, NAN, NAN, NAN)),
        (mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, (0,) * 7),
        (mavlink.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, NAN, NAN, NAN, 60.0)),
        (mavlink.MAV_CMD_DO_SET_MODE, (CUSTOM, 4, 6, 0, 0, 0, 0)),            # AUTO.LAND
        (mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, (HB, -1, 0, 0, 0, 0, 0)),       # silence the heartbeat
        (mavlink.MAV_CMD_MISSION_START, (0,) * 7),
        (mavlink.MAV_CMD_DO_REPOSITION, (-1, 1, 0, NAN, NAN, NAN, NAN)),        # go elsewhere, in Hold
        (31010, (1,) * 7),                                                      # unknown: deny by default
    ]
    out = []
    for c, p in cmds:
        out.append(("COMMAND_LONG", mav.command_long_encode(1, 1, c, 0, *p).pack(mav)))
        out.append(("COMMAND_INT", mav.command_int_encode(1, 1, 0, c, 0, 0, p[0], p[1], p[2], p[3],
                                                          0, 0, 0 if math.isnan(p[6]) else p[6]).pack(mav)))
    out += [
        ("SET_MODE", mav.set_mode_encode(1, CUSTOM, (6 << 16)).pack(mav)),   # OFFBOARD
        ("SET_POSITION_TARGET_LOCAL_NED", mav.set_position_target_local_ned_encode(
            0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0xDF8, 30, 30, -10, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav)),
        ("HIL_ACTUATOR_CONTROLS", mav.hil_actuator_controls_encode(0, [0.0] * 16, 0, 1).pack(mav)),
        ("PARAM_SET", mav.param_set_encode(1, 1, PARAM.encode(), 0.5, mavlink.MAV_PARAM_TYPE_REAL32).pack(mav)),
        ("MISSION_CLEAR_ALL", mav.mission_clear_all_encode(1, 1, 0).pack(mav)),
        ("MISSION_SET_CURRENT", mav.mission_set_current_encode(1, 1, 2).pack(mav)),
        ("MISSION_COUNT", mav.mission_count_encode(1, 1, 2, 0).pack(mav)),
        ("MISSION_ITEM_INT", mav.mission_item_int_encode(1, 1, 0, 6, 16, 0, 1, 0, 0, 0, 0, 1, 2, 3, 0).pack(mav)),
        ("MISSION_ITEM", mav.mission_item_encode(1, 1, 1, 6, 16, 0, 1, 0, 0, 0, 0, 1.0, 2.0, 3.0, 0).pack(mav)),
        ("SETUP_SIGNING", mav.setup_signing_encode(1, 1, list(range(7, 39)), 1).pack(mav)),
        ("SETUP_SIGNING", mav.setup_signing_encode(1, 1, [0] * 32, 0).pack(mav)),
        ("HIL_ACTUATOR_CONTROLS", mav.heartbeat_encode(6, 8, 0, 0, 4).pack(mav)
         + mav.hil_actuator_controls_encode(0, [0.0] * 16, 0, 0).pack(mav)),
    ]
    return [(t, bytes(p)) for t, p in out]


def _signing_mav(mav, key):
    from mavcore.link.signing import enable_outgoing_signing, signing_timestamp
    enable_outgoing_signing(mav, key, 0, signing_timestamp(time.time()))


def _set_up_flight(gcs):
    """Mission upload, a parameter, AUTO take-off to 2 m and hold (LOITER)."""
    gcs.mav.mission_count_send(1, 1, len(WAYPOINTS), 0)
    for _ in WAYPOINTS:
        r = gcs.recv("MISSION_REQUEST_INT", 3.0)
        lat, lon, alt = WAYPOINTS[r.seq]
        gcs.mav.mission_item_int_send(1, 1, r.seq, 6, 16, 0, 1, 0, 0, 0, 0, lat, lon, alt, 0)
    assert gcs.recv("MISSION_ACK", 3.0).type == mavlink.MAV_MISSION_ACCEPTED
    assert gcs.set_param(PARAM, PARAM_VALUE).param_value == pytest.approx(PARAM_VALUE)
    home_alt = 30.0
    assert gcs.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, NAN, NAN, NAN, home_alt + HOLD_Z_M) == 0
    assert gcs.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0
    hold = gcs.recv("HEARTBEAT", 10.0, lambda m: mavutil.mode_string_v10(m) == "LOITER")
    assert hold is not None and hold.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED


def _read_back(gcs, start_z):
    """Everything the attacks tried to change, read over MAVLink."""
    gcs.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    hb = gcs.recv("HEARTBEAT", 3.0)
    assert hb is not None, "heartbeat silenced"
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED and mavutil.mode_string_v10(hb) == "LOITER"
    lp = gcs.recv("LOCAL_POSITION_NED", 2.0)
    assert -lp.z - start_z == pytest.approx(HOLD_Z_M, abs=0.3), "the vehicle moved vertically"
    gcs.mav.param_request_read_send(1, 1, PARAM.encode(), -1)
    assert gcs.recv("PARAM_VALUE", 3.0, lambda m: m.param_id == PARAM).param_value == pytest.approx(PARAM_VALUE)
    gcs.mav.command_long_send(1, 1, mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, 0, HB, 0, 0, 0, 0, 0, 0)
    assert gcs.recv("MESSAGE_INTERVAL", 3.0, lambda m: m.message_id == HB).interval_us == 1_000_000
    gcs.mav.mission_request_list_send(1, 1, 0)
    assert gcs.recv("MISSION_COUNT", 3.0).count == len(WAYPOINTS)
    for i, (lat, lon, _) in enumerate(WAYPOINTS):
        gcs.mav.mission_request_int_send(1, 1, i, 0)
        it = gcs.recv("MISSION_ITEM_INT", 3.0, lambda m, i=i: m.seq == i)
        assert (it.x, it.y) == (lat, lon)
    gcs.mav.mission_ack_send(1, 1, 0, 0)


@pytest.mark.parametrize("signing", [False, True], ids=["unsigned", "signed"])
def test_attack_matrix_nothing_accepted(tmp_path, signing):
    key = None
    kw = {}
    if signing:
        from MAVProxy.modules.mavproxy_signing import SigningModule
        key = SigningModule.passphrase_to_key(None, PASSPHRASE)   # what MAVProxy's `signing setup` uses
        (tmp_path / "key.txt").write_text(PASSPHRASE + "\n")
        kw["signing_key_file"] = tmp_path / "key.txt"
    tele_port = free_udp_port()
    with SitlThread(MISSION, speed=3.0, outs=(f"udpout:127.0.0.1:{tele_port}",), **kw) as sitl:
        gcs = Client(sitl.url)
        if signing:   # plain pymavlink signing, the way mavutil users (and MAVProxy) set it up
            gcs.conn.setup_signing(key, sign_outgoing=True, link_id=0)
        tele = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        tele.bind(("127.0.0.1", tele_port))
        tele.settimeout(2.0)
        attackers = []
        try:
            gcs.hello()
            start_z = -gcs.recv("LOCAL_POSITION_NED", 2.0).z
            _set_up_flight(gcs)
            gcs.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            gcs.pump(0.3)
            server = sitl.server
            accepted_before = server.auth.counts["accepted"]
            ignored_before = sum(v for k, v in server.auth.counts.items() if k not in ("accepted", "rebound", "released"))
            texts_before = len(gcs.texts)

            # the attackers: (name, socket, destination, packets)
            _, tele_src = tele.recvfrom(4096)           # the SITL's telemetry-only socket
            host, port = sitl.listen.split(":")[1:]
            dest = (host, int(port))
            foreign = mavlink.MAVLink(None, srcSystem=42, srcComponent=1)
            spoof = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
            sources = [("foreign id", foreign, dest), ("gcs ids, foreign port", spoof, dest),
                       ("gcs ids, telemetry link", mavlink.MAVLink(None, 255, 190), tele_src)]
            if signing:
                wrong = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
                _signing_mav(wrong, bytes(range(32)))
                sources.append(("gcs ids, wrong key", wrong, dest))
            n_sent = 0
            for name, mav, to in sources:
                s = tele if to is tele_src else socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                if s is not tele:
                    attackers.append(s)
                for _, pkt in attack_packets(mav):
                    s.sendto(pkt, to)
                    n_sent += 1
            if signing:   # the ground station's own signed packets, replayed from another port
                replay = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                attackers.append(replay)
                # one legitimate PARAM_SET (accepted), then its exact bytes again from elsewhere
                legit = gcs.mav.param_set_encode(1, 1, PARAM.encode(), PARAM_VALUE, 9)
                buf = bytes(legit.pack(gcs.mav))
                gcs.conn.write(buf)
                assert gcs.recv("PARAM_VALUE", 3.0, lambda m: m.param_id == PARAM) is not None
                accepted_before += 1                         # that one was the ground station's
                for _ in range(3):
                    replay.sendto(buf, dest)
                    n_sent += 1
            gcs.pump(0.8, every=lambda: gcs.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, 8, 0, 0, 0), period=0.3)

            _read_back(gcs, start_z)
            counts = server.auth.counts
            assert counts["accepted"] == accepted_before
            ignored = sum(v for k, v in counts.items() if k not in ("accepted", "rebound", "released")) - ignored_before
            assert ignored == n_sent, dict(counts)
            assert counts["rebound"] == 0
            assert server.auth.binding(255, 190)[1] == ("127.0.0.1", gcs.conn.port.getsockname()[1])
            # one STATUSTEXT per attacking source, naming it
            reports = [t for t in gcs.texts[texts_before:] if t.startswith("ignored ")]
            assert len(reports) == len(sources) + (1 if signing else 0), reports
            assert any(t.startswith("ignored COMMAND_LONG from 42/1 ") and t.endswith(": not a controller")
                       for t in reports)
            if signing:
                assert any(t.endswith(": bad signature") for t in reports)
                assert any(t.endswith(": replayed signature") for t in reports)
                # the SITL still signs with the original key
                m = gcs.recv("HIGHRES_IMU", 2.0)
                assert m is not None and m.get_signed()
            else:
                assert any(t.endswith(": controller ids in use from another address") for t in reports)
                assert not gcs.recv("HIGHRES_IMU", 2.0).get_msgbuf()[2] & 1    # still not signing
            assert any("not a control link" in t for t in reports)
        finally:
            gcs.close()
            tele.close()
            for s in attackers:
                s.close()


def test_a_closed_controller_is_released_at_once():
    """A ground station that closes its socket (a restarted companion, a GCS
    relaunched) frees its ids at once: the kernel's port-unreachable report
    (IP_RECVERR) tells the SITL, so the next address need not wait out the
    binding's silence timeout. A live one keeps them (the attack matrix)."""
    home_iv = mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_HOME_POSITION
    with SitlThread(MISSION, speed=2.0) as sitl:
        first = Client(sitl.url)
        first.hello()
        assert first.command(*home_iv, 500_000) == mavlink.MAV_RESULT_ACCEPTED
        first.close()
        second = Client(sitl.url)
        try:
            t0 = time.monotonic()
            second.hello()
            assert second.command(*home_iv, 600_000) == mavlink.MAV_RESULT_ACCEPTED
            assert time.monotonic() - t0 < 2.0          # well inside the 3 s silence rule
            assert sitl.server.auth.counts["released"] == 1 and sitl.server.auth.counts["rebound"] == 0
            assert sitl.server.auth.binding(255, 190)[1][1] == second.conn.port.getsockname()[1]
        finally:
            second.close()


def test_a_closed_client_costs_the_lockstep_peer_no_frame():
    """With IP_RECVERR the kernel reports a closed client's ICMP error on the
    next send, about any peer, and drops that datagram: the SITL collects it
    and sends again, so the lockstep peer still gets every frame (consecutive
    frame times, no lockstep time-out) while clients come and go."""
    from fuzz_link import imu_time_usec

    with SitlThread(MISSION, lockstep=True, speed=1.0) as sitl:
        host, port = sitl.listen.split(":")[1:]
        dest = (host, int(port))
        peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        peer.bind(("127.0.0.1", 0))
        peer.settimeout(3.0)
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
        hb = bytes(mav.heartbeat_encode(18, 8, 0, 0, 4).pack(mav))
        peer.sendto(hb, dest)
        times, gone = [], 0
        try:
            while len(times) < 300:
                data = peer.recv(65536)
                t = imu_time_usec(data)
                if t is None or (times and t == times[-1]):
                    continue
                times.append(t)
                peer.sendto(bytes(mav.hil_actuator_controls_encode(t, [NAN] * 16, 0, 1).pack(mav)), dest)
                if len(times) % 40 == 0:       # a client that joins and leaves
                    c = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                    c.sendto(hb, dest)
                    c.close()
                    gone += 1
            # read while the peer is still there: once it closes, the SITL's next frame to it
            # draws an ICMP error and the lockstep lets go of it (CI, a loaded machine, read
            # it after that)
            engaged = sitl.server.lockstep_engaged
        finally:
            peer.close()
        assert gone == 7
        assert set(np.diff(times)) == {4000}                  # every frame, none skipped
        assert engaged
