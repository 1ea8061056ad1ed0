"""UDP sockets of a MAVLink link, opened the safe way (both sides use it).

pymavlink's ``mavudp`` binds ``udpin`` sockets with SO_REUSEADDR (so a
second process on the same port "succeeds" and the two share, or steal,
each other's datagrams) and leaves ``udpout`` sockets unbound until the
first send, when the kernel binds them to 0.0.0.0: anyone on any interface
can then send to them. Here:

- ``udpin:HOST:PORT`` (and ``udp:``) binds exactly HOST:PORT, without
  SO_REUSEADDR: a port already in use is an error (``InputError``, one line);
- ``udpout:HOST:PORT`` resolves HOST once (an unknown host is an error) and
  ``connect()``s the socket: the kernel picks the local address by routing
  (loopback for a loopback peer) and drops datagrams from any other source.

No address is ever widened: loopback unless the user gives another one.

``open_pipe`` is the one place where a connection string becomes a datagram
pipe (``mavcore.link.pipe``), for the SITL's links and the companion's alike: a UDP
socket as above, or ``inproc:NAME``, the in-process transport.
"""

from __future__ import annotations

import errno
import socket
from dataclasses import dataclass

from mavcore.link.pipe import UdpPipe, connect_memory, is_memory_url, listen_memory

from ..errors import InputError

UDP_SCHEMES = ("udpin:", "udp:", "udpout:")


@dataclass(frozen=True, eq=False)
class UdpSocket:
    """An open UDP socket of a link.

    Attributes
    ----------
    sock : socket.socket
        Blocking (callers set timeouts).
    server : bool
        ``udpin``: serves whoever sends to it; ``udpout``: connected to ``peer``.
    peer : (host, port) or None
        The resolved destination of a ``udpout`` link.
    """

    sock: socket.socket
    server: bool
    peer: tuple[str, int] | None


def split_url(url: str) -> tuple[str, str, int]:
    """``SCHEME:HOST:PORT`` -> (scheme, host, port); ValueError if malformed."""
    scheme, sep, rest = url.partition(":")
    host, sep2, port = rest.rpartition(":")
    if not sep or not sep2 or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"bad connection string {url!r}")
    return scheme, host, int(port)


def is_udp_url(url: str) -> bool:
    return url.startswith(UDP_SCHEMES)


def is_datagram_url(url: str) -> bool:
    """A link read datagram by datagram through a ``mavcore.link.pipe`` pipe (UDP or in-process)."""
    return url.startswith(UDP_SCHEMES) or is_memory_url(url)


def open_pipe(url: str, option: str, listen: bool = False):
    """The datagram pipe of ``url``: ``mavcore.link.pipe.UdpPipe`` for ``udpin:``/``udp:``/
    ``udpout:`` (``open_udp``), ``mavcore.link.pipe.MemoryPipe`` for ``inproc:NAME``
    (``listen``: the vehicle end, registered under NAME; else the peer's end).

    Raises
    ------
    InputError
        As ``open_udp``; for ``inproc:``, a name in use or nobody listening.
    """
    if is_memory_url(url):
        try:
            return listen_memory(url) if listen else connect_memory(url)
        except ValueError as exc:
            raise InputError(f"{option} {url}", str(exc)) from None
    us = open_udp(url, option)
    return UdpPipe(us.sock, us.server, us.peer)


def open_udp(url: str, option: str) -> UdpSocket:
    """Open the UDP socket of ``url`` (``udpin:``, ``udp:`` or ``udpout:``).

    Parameters
    ----------
    url : str
        pymavlink connection string.
    option : str
        The command-line flag that gave it, for error messages (``--connect``).

    Raises
    ------
    InputError
        Malformed string, unknown host, port already in use, address not
        available: one line naming ``option`` and ``url``.
    """
    source = f"{option} {url}"
    try:
        scheme, host, port = split_url(url)
    except ValueError:
        raise InputError(source, "expected SCHEME:HOST:PORT, e.g. udpin:127.0.0.1:14540") from None
    try:
        infos = socket.getaddrinfo(host, port, socket.AF_INET, socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError) as exc:
        raise InputError(source, f"cannot resolve host {host!r}: {getattr(exc, 'strerror', None) or exc}") from None
    addr = infos[0][4]
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        if scheme in ("udpin", "udp"):
            sock.bind(addr)
            peer = None
        else:
            sock.connect(addr)
            peer = (addr[0], int(addr[1]))
    except OSError as exc:
        sock.close()
        if exc.errno == errno.EADDRINUSE:
            raise InputError(source, f"port {port} is already in use on {host}") from None
        if exc.errno == errno.EADDRNOTAVAIL:
            raise InputError(source, f"address {host} is not an address of this machine") from None
        raise InputError(source, f"cannot open: {exc.strerror or exc}") from None
    sock.setblocking(True)
    return UdpSocket(sock, peer is None, peer)
