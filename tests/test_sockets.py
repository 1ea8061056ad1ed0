"""Where the SITL's and the companion's sockets are bound, read from the kernel
(/proc), not from our own objects; bounded, expiring udpin clients over real
UDP. (Ports in use: tests/test_bad_input.py.)"""

from __future__ import annotations

import os
import socket
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore.errors import InputError
from fuzz_link import inet_sockets   # benchmarks/ (pyproject: pytest pythonpath)
from companion.link import Connection
from sitl.api import SitlThread, free_udp_port
from test_sitl_mavlink import MISSION, Client

pytestmark = pytest.mark.skipif(not Path("/proc/net/udp").exists(), reason="needs Linux /proc")


def test_every_sitl_socket_is_loopback_and_udpout_connected():
    """The SITL's listen, telemetry-only and control links, as the kernel sees them."""
    before = set(inet_sockets(os.getpid()))
    ports = [free_udp_port() for _ in range(3)]
    with SitlThread(MISSION, listen=f"udpin:127.0.0.1:{ports[0]}", outs=(f"udpout:127.0.0.1:{ports[1]}",),
                    control_outs=(f"udpout:127.0.0.1:{ports[2]}",), speed=1.0):
        socks = [s for s in inet_sockets(os.getpid()) if s not in before]
    assert len(socks) == 3 and all(proto == "udp" and local[0] == "127.0.0.1" for proto, local, _ in socks)
    by_remote = {remote: local for _, local, remote in socks}
    assert by_remote[("0.0.0.0", 0)] == ("127.0.0.1", ports[0])       # udpin: bound, open to peers
    assert ("127.0.0.1", ports[1]) in by_remote                          # udpout: connected to its peer
    assert ("127.0.0.1", ports[2]) in by_remote


def test_every_companion_socket_is_loopback():
    before = {s for s in inet_sockets(os.getpid())}
    port = free_udp_port()
    conns = [Connection(f"udpout:127.0.0.1:{port}").open(), Connection(f"udpin:127.0.0.1:{free_udp_port()}").open()]
    try:
        new = [s for s in inet_sockets(os.getpid()) if s not in before]
    finally:
        for c in conns:
            c.close()
    assert len(new) == 2
    out = [s for s in new if s[2] != ("0.0.0.0", 0)]
    assert len(out) == 1 and out[0][1][0] == "127.0.0.1" and out[0][2] == ("127.0.0.1", port)
    listen = [s for s in new if s[2] == ("0.0.0.0", 0)]
    assert len(listen) == 1 and listen[0][1][0] == "127.0.0.1"


def test_udpin_clients_bounded_expiring_controller_kept():
    with SitlThread(MISSION, speed=2.0, max_clients=4, client_timeout_s=0.4) as sitl:
        gcs = Client(sitl.url)
        gcs.hello()
        assert gcs.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_HOME_POSITION,
                           500_000) == 0    # control: binds (and pins) the ground station
        host, port = sitl.listen.split(":")[1:]
        flood = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(40)]
        mav = mavlink.MAVLink(None, 77, 1)
        hb = bytes(mav.heartbeat_encode(6, 8, 0, 0, 4).pack(mav))
        try:
            for s in flood:
                s.sendto(hb, (host, int(port)))
            gcs.pump(0.3)
            clients = sitl.server.links[0].clients
            assert len(clients) == 4 and ("127.0.0.1", gcs.conn.port.getsockname()[1]) in clients
            assert clients.n_evicted >= 40 - 3
            assert gcs.recv("HIGHRES_IMU", 1.0) is not None          # the controller still gets telemetry
            time.sleep(0.7)                                          # the flood falls silent
            gcs.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            gcs.pump(0.3)
            assert set(clients) == {("127.0.0.1", gcs.conn.port.getsockname()[1])}
        finally:
            for s in flood:
                s.close()
            gcs.close()


def test_unresolvable_host_is_one_line_error():
    with pytest.raises(InputError) as exc:
        Connection("udpout:no.such.host.invalid:1").open()
    assert "--connect udpout:no.such.host.invalid:1" in str(exc.value) and "resolve" in str(exc.value)


def test_a_pending_icmp_error_does_not_drop_the_next_datagram():
    """IP_RECVERR makes the kernel report a closed peer's ICMP error on the
    next sendto, about any peer, and drop that datagram: the SITL's link
    collects the error (the closed address goes to ``gone``) and sends again."""
    from sitl.link import Link as _Link

    link = _Link(f"udpin:127.0.0.1:{free_udp_port()}")
    live = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    live.bind(("127.0.0.1", 0))
    live.settimeout(1.0)
    closed = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closed.bind(("127.0.0.1", 0))
    dead = closed.getsockname()
    closed.close()
    try:
        link._sendto(b"to the closed port", dead)
        time.sleep(0.05)
        link._sendto(b"to the live one", live.getsockname())
        assert live.recv(100) == b"to the live one"
        assert link.gone == [dead]
    finally:
        link.close()
        live.close()
