"""Datagram pipes (mavcore/link/pipe.py): the adaptive lockstep spin, the in-process
pipe's delivery and cooperative driving, and the one place that picks a pipe
from a connection string (mavcore.link.sockets.open_pipe)."""

from __future__ import annotations

import socket
import time

import pytest

from mavcore.errors import InputError
from mavcore.link.sockets import open_pipe
from mavcore.link.pipe import PEER_ADDR, VEHICLE_ADDR, AdaptiveSpin, MemoryPipe, UdpPipe


def test_adaptive_spin_backs_off_exponentially_and_recovers():
    s = AdaptiveSpin(300e-6)
    assert s.budget() == 300e-6
    # consecutive misses: 1, 2, 4, 8 waits without spinning after each
    pattern = []
    for _ in range(4):
        s.miss()
        skipped = 0
        while s.budget() == 0.0:
            skipped += 1
        pattern.append(skipped)
    assert pattern == [1, 2, 4, 8]
    # a hit resets the back-off: the next miss skips one wait again
    s.hit()
    s.miss()
    assert [s.budget() for _ in range(2)] == [0.0, 300e-6]


def test_adaptive_spin_is_capped_and_never_spins_with_no_budget():
    s = AdaptiveSpin(1e-4)
    for _ in range(40):          # 2**39 uncapped
        s.miss()
    assert s.skip == AdaptiveSpin.MAX_SKIP
    off = AdaptiveSpin(0.0)
    off.miss()
    assert all(off.budget() == 0.0 for _ in range(5)) and off.n_spins == 0


def test_udp_pipe_spin_counts_a_miss_when_nothing_comes():
    a = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    a.bind(("127.0.0.1", 0))
    p = UdpPipe(a, True, None)
    p.spin.max_s = 2e-3
    try:
        t0 = time.perf_counter()
        assert p.recv(0.01, spin=True) is None          # spun, then slept out the timeout
        assert time.perf_counter() - t0 >= 0.01
        assert (p.spin.n_spins, p.spin.n_hits, p.spin.skip) == (1, 0, 1)
        b = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        b.bind(("127.0.0.1", 0))
        b.sendto(b"xyz", a.getsockname())
        data, addr = p.recv(0.5, spin=True)            # this wait skips the spin (back-off)
        assert data == b"xyz" and addr == b.getsockname() and p.spin.n_spins == 1
        b.close()
    finally:
        p.close()


def _pair(name):
    server = open_pipe(f"inproc:{name}", "--listen", listen=True)
    client = open_pipe(f"inproc:{name}", "--connect")
    return server, client


def test_memory_pipe_delivers_copies_in_order_with_addresses():
    server, client = _pair("t-order")
    try:
        assert isinstance(server, MemoryPipe) and client.peer == VEHICLE_ADDR and server.peer == PEER_ADDR
        buf = bytearray(b"frame-1")
        server.send(buf)
        buf[:] = b"changed"                        # the datagram was copied when sent
        server.send(b"frame-2")
        client.send(b"answer")
        assert client.recv() == (b"frame-1", VEHICLE_ADDR)
        assert client.recv() == (b"frame-2", VEHICLE_ADDR)
        assert client.recv() is None
        assert server.recv() == (b"answer", PEER_ADDR)
    finally:
        client.close()
        server.close()


def test_memory_pipe_wait_runs_the_other_ends_driver():
    server, client = _pair("t-drive")
    calls = []

    def step():                                # the vehicle answers the second turn only
        calls.append(1)
        if len(calls) == 2:
            server.send(b"frame")

    server.driver = step
    try:
        assert client.recv(1.0) == (b"frame", VEHICLE_ADDR)
        assert len(calls) == 2
        assert client.recv(0.0) is None and len(calls) == 2     # no wait: no driving
    finally:
        client.close()
        server.close()


def test_memory_pipe_wait_times_out_without_a_driver():
    server, client = _pair("t-timeout")
    try:
        t0 = time.monotonic()
        assert client.recv(0.02) is None
        assert time.monotonic() - t0 >= 0.02
    finally:
        client.close()
        server.close()


def test_inproc_names_are_checked_in_one_line():
    with pytest.raises(InputError, match="--connect inproc:nobody: no in-process vehicle listens"):
        open_pipe("inproc:nobody", "--connect")
    server, client = _pair("t-dup")
    try:
        with pytest.raises(InputError, match="already in use"):
            open_pipe("inproc:t-dup", "--listen", listen=True)
        with pytest.raises(InputError, match="already has a peer"):
            open_pipe("inproc:t-dup", "--connect")
    finally:
        client.close()
        server.close()
    # closed: the name is free again
    s2, c2 = _pair("t-dup")
    c2.close()
    s2.close()


def test_sitl_config_refuses_inproc_without_lockstep():
    from sitl.server import ServerConfig

    with pytest.raises(ValueError, match="lockstep"):
        ServerConfig(listen="inproc:x", lockstep=False)
    with pytest.raises(ValueError, match="lockstep"):
        ServerConfig(listen="inproc:x", lockstep=True, outs=("udpout:127.0.0.1:14550",))
