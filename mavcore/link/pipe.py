"""Datagram pipes: the transport seam under both ends of a MAVLink link.

The SITL's links (``sitl.link.Link``) and the companion's
(``companion.link.connection.Connection``) read and write whole datagrams
through a pipe; which pipe a connection string gives is decided in one place,
``mavcore.link.sockets.open_pipe``:

- ``UdpPipe`` (``udpin:``/``udpout:``/``udp:``): a UDP socket, read with one
  ``recvfrom`` per datagram. A wait is one blocking ``recvfrom`` under a
  kernel receive timeout (SO_RCVTIMEO) after an optional busy-poll, whose
  length adapts (``AdaptiveSpin``).
- ``MemoryPipe`` (``inproc:NAME``): the same datagrams, the same bytes,
  through in-memory queues of this process, no sockets. The vehicle end is
  registered under NAME by the SITL (``listen_memory``), the companion's end
  connects to it (``connect_memory``). It is cooperative: when the companion
  waits for a datagram and none is queued, its pipe runs the SITL's
  ``driver`` (``SitlServer.service``: handle the queued input, step a frame
  when the lockstep answer released it) in the caller's thread. The lockstep
  round trip becomes two function calls; nothing sleeps or switches
  processes, so a loaded machine costs the flight only its share of CPU.

Nothing here imports the companion: the companion imports this module.
"""

from __future__ import annotations

import collections
import errno
import socket
import struct
import threading
import time
from time import perf_counter
from typing import Callable

MEMORY_SCHEME = "inproc:"

#: The address a memory pipe's datagrams come from (vehicle end, companion end):
#: (host, port)-shaped, as the link statistics print addresses.
VEHICLE_ADDR = ("inproc", 0)
PEER_ADDR = ("inproc", 1)


def is_memory_url(url: str) -> bool:
    return url.startswith(MEMORY_SCHEME)


class AdaptiveSpin:
    """How long to busy-poll before sleeping in the kernel, learnt per wait.

    Spinning pays when the answer comes within the spin (the peer runs on
    another core right now): it saves a process wake-up, about as long as
    the answer itself on loopback. On a loaded machine the answer usually
    comes late and the spin only burns CPU the peer needs (issue 16:
    3.9x real time with spinning against 8.2x without, at load 3). So:
    after a wait whose spin missed, the next ``skip`` waits do not spin,
    ``skip`` doubling with every consecutive miss (1, 2, 4 ... ``MAX_SKIP``);
    a spin that catches the answer resets it. On an idle machine every spin
    hits and nothing changes; under load spinning is tried once every
    ``MAX_SKIP`` waits.

    Parameters
    ----------
    max_s : float
        The spin budget (SIM_LS_SPIN, ``RunnerConfig.spin_us``), seconds; 0: never spin.
    """

    MAX_SKIP = 256

    __slots__ = ("max_s", "skip", "misses", "n_spins", "n_hits")

    def __init__(self, max_s: float = 0.0) -> None:
        self.max_s = float(max_s)
        self.skip = 0
        self.misses = 0
        self.n_spins = 0
        self.n_hits = 0

    def budget(self) -> float:
        """Seconds to spin on this wait (0: sleep at once)."""
        if self.max_s <= 0.0:
            return 0.0
        if self.skip > 0:
            self.skip -= 1
            return 0.0
        self.n_spins += 1
        return self.max_s

    def hit(self) -> None:
        """The spin caught the datagram."""
        self.n_hits += 1
        self.misses = 0

    def miss(self) -> None:
        """The spin ran out: back off."""
        self.misses += 1
        self.skip = min(1 << (self.misses - 1), self.MAX_SKIP)


class UdpPipe:
    """A UDP socket as a datagram pipe (opened by ``mavcore.link.sockets.open_udp``).

    Parameters
    ----------
    sock : socket.socket
        Blocking.
    server : bool
        ``udpin``: serves whoever sends to it (``sendto``); else connected to ``peer``.
    peer : (host, port) or None
    """

    memory = False

    def __init__(self, sock: socket.socket, server: bool, peer) -> None:
        self.sock = sock
        self.server = server
        self.peer = peer
        self.spin = AdaptiveSpin(0.0)
        #: errno of the last failed ``recv`` (ECONNREFUSED: an ICMP error is queued), else 0.
        self.error = 0
        self._rcvtimeo = None

    def fileno(self) -> int:
        return self.sock.fileno()

    def send(self, buf: bytes) -> None:
        """To the connected peer (raises OSError as ``socket.send``)."""
        self.sock.send(buf)

    def sendto(self, buf: bytes, addr) -> None:
        self.sock.sendto(buf, addr)

    def _set_rcvtimeo(self, timeout_s: float) -> None:
        sec = int(timeout_s)
        usec = max(int((timeout_s - sec) * 1e6), 1 if sec == 0 else 0)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, struct.pack("@ll", sec, usec))
        self._rcvtimeo = timeout_s

    def recv(self, wait_s: float = 0.0, spin: bool = False):
        """(datagram, source address) waiting up to ``wait_s`` seconds (0: only
        what is queued now), or None. ``spin``: busy-poll first for the
        adaptive budget of ``self.spin``."""
        sock = self.sock
        try:
            if wait_s > 0:
                if spin:
                    s = self.spin
                    budget = s.budget()
                    if budget > 0:
                        t_end = perf_counter() + budget
                        while True:
                            try:
                                got = sock.recvfrom(65536, socket.MSG_DONTWAIT)
                            except BlockingIOError:
                                if perf_counter() < t_end:
                                    continue
                                s.miss()
                                break
                            s.hit()
                            return got
                if wait_s != self._rcvtimeo:
                    self._set_rcvtimeo(wait_s)
                return sock.recvfrom(65536)
            return sock.recvfrom(65536, socket.MSG_DONTWAIT)
        except OSError as exc:   # timeout/EAGAIN, ECONNREFUSED after an ICMP error, EINTR, ...
            self.error = exc.errno or 0
            return None

    def close(self) -> None:
        try:
            self.sock.close()
        except OSError:
            pass


class MemoryPipe:
    """One end of an in-memory datagram pipe (see the module docstring).

    Datagrams are queued as bytes (a copy) with the sender's address. Both
    ends live in one process; queue operations are atomic (``deque``), so a
    pipe also works between threads, where a waiting ``recv`` without a
    ``driver`` on the other end polls every millisecond.
    """

    memory = True
    server = False
    error = 0

    def __init__(self, name: str, addr, peer) -> None:
        self.name = name
        self.addr = addr
        self.peer = peer
        self.inbox: collections.deque = collections.deque()
        self.other: MemoryPipe | None = None
        #: Called by the other end's ``recv`` when it waits and finds nothing
        #: queued: runs this end's owner one turn (it may send, or not).
        self.driver: Callable[[], None] | None = None
        self.closed = False

    def fileno(self) -> int:
        raise OSError(errno.ENOTSOCK, "an in-process pipe has no file descriptor")

    def send(self, buf: bytes) -> None:
        other = self.other
        if other is not None and not other.closed:
            other.inbox.append((bytes(buf), self.addr))

    def sendto(self, buf: bytes, addr) -> None:
        self.send(buf)

    #: Wall-clock step of a wait that the other end cannot satisfy at once
    #: (before lockstep engages; a peer in another thread).
    IDLE_SLEEP_S = 1e-3

    def recv(self, wait_s: float = 0.0, spin: bool = False):
        """(datagram, source address), waiting up to ``wait_s`` seconds
        (running the other end's driver meanwhile), or None."""
        inbox = self.inbox
        if inbox:
            return inbox.popleft()
        if wait_s <= 0:
            return None
        other = self.other
        drive = other.driver if other is not None else None
        deadline = None
        while True:
            if drive is not None:
                drive()
                if inbox:
                    return inbox.popleft()
            now = time.monotonic()
            if deadline is None:
                deadline = now + wait_s
            elif now >= deadline:
                return None
            time.sleep(min(self.IDLE_SLEEP_S, deadline - now))
            if inbox:
                return inbox.popleft()

    def close(self) -> None:
        self.closed = True
        if self.driver is not None:
            self.driver = None
        _unregister(self)


_registry: dict[str, MemoryPipe] = {}
_registry_lock = threading.Lock()


def listen_memory(url: str) -> MemoryPipe:
    """The vehicle end of ``inproc:NAME``, registered under NAME.

    Raises
    ------
    ValueError
        No NAME, or NAME is in use in this process.
    """
    name = url[len(MEMORY_SCHEME):]
    if not name:
        raise ValueError(f"bad connection string {url!r} (expected inproc:NAME)")
    with _registry_lock:
        if name in _registry:
            raise ValueError(f"in-process link {name!r} is already in use")
        pipe = MemoryPipe(name, VEHICLE_ADDR, None)
        _registry[name] = pipe
    return pipe


def connect_memory(url: str) -> MemoryPipe:
    """The companion's end of ``inproc:NAME`` (the vehicle end must be listening).

    Raises
    ------
    ValueError
        Nobody listens on NAME in this process, or someone is connected already.
    """
    name = url[len(MEMORY_SCHEME):]
    with _registry_lock:
        server = _registry.get(name)
        if server is None:
            raise ValueError(f"no in-process vehicle listens on {name!r}")
        if server.other is not None and not server.other.closed:
            raise ValueError(f"in-process link {name!r} already has a peer")
        pipe = MemoryPipe(name, PEER_ADDR, VEHICLE_ADDR)
        pipe.other, server.other = server, pipe
        server.peer = PEER_ADDR
    return pipe


def _unregister(pipe: MemoryPipe) -> None:
    with _registry_lock:
        if _registry.get(pipe.name) is pipe:
            del _registry[pipe.name]
