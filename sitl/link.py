"""One MAVLink link of the SITL: a socket (or in-process pipe) with our own
common-dialect MAVLink 2 encoder, its clients, frame batching and parsing.

``sitl.server.SitlServer`` opens one per ``--listen`` / ``--out`` /
``--control-out`` address and drives them (pacing, lockstep, dispatch).
"""

from __future__ import annotations

import errno
import socket
import time
from struct import error as struct_error

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from mavcore.link.sockets import is_datagram_url, open_pipe

from .auth import ClientTable
from .vehicle_id import COMPONENT_ID, SYSTEM_ID

#: Linux's IP_RECVERR (the socket module does not export it).
_IP_RECVERR = getattr(socket, "IP_RECVERR", 11)


class Link:
    """One MAVLink link with our own common-dialect MAVLink 2 encoder.

    UDP links are our own sockets (``mavcore.link.sockets.open_udp``: a
    ``udpin`` port in use is an error, ``udpout`` is connected to its peer so
    nobody else can write to it), read and written directly (one
    ``recvfrom`` per datagram; one ``sendto`` per client for a frame's
    telemetry, see ``BATCH_BYTES``, and per reply): mavutil's per-message
    bookkeeping costs more than the rest of a frame's telemetry. A ``udpin``
    link serves the addresses that sent it something, at most
    ``max_clients`` of them, expiring after ``client_timeout_s`` of silence
    (``sitl.auth.ClientTable``); replies go to the requester only. Other
    link types (TCP, serial) go through mavutil.

    Incoming packets are parsed by a ``MAVLink`` object without a key
    (``parser``): signatures are checked by ``sitl.auth`` with our rules;
    ``mav`` packs (and signs, when signing is on).
    """

    def __init__(self, url: str, control: bool = True, max_clients: int = 8,
                 client_timeout_s: float = 10.0, option: str = "--listen") -> None:
        self.url = url
        self.control = control
        #: A datagram link (UDP or in-process, ``mavcore.link.pipe``): read datagram by datagram.
        self.udp = is_datagram_url(url)
        self.conn = None
        self.pipe = None
        self.clients = ClientTable(max_clients, client_timeout_s)
        if self.udp:
            self.pipe = open_pipe(url, option, listen=True)
            self.memory = self.pipe.memory
            self.sock = None if self.memory else self.pipe.sock
            self.server = self.pipe.server
            self.peer = self.pipe.peer
            self.fd = None if self.memory else self.sock.fileno()
            self.mav = mavlink.MAVLink(None, srcSystem=SYSTEM_ID, srcComponent=COMPONENT_ID)
        else:
            self.memory = False
            self.conn = mavutil.mavlink_connection(url, source_system=SYSTEM_ID,
                                                   source_component=COMPONENT_ID, retries=0)
            # Replace the module-global-dialect encoder by our own (common, v2):
            # independent of MAVLINK20/MAVLINK_DIALECT and of other users of mavutil.
            self.conn.mav = mavlink.MAVLink(self.conn, srcSystem=SYSTEM_ID, srcComponent=COMPONENT_ID)
            self.conn.WIRE_PROTOCOL_VERSION = "2.0"
            self.conn.first_byte = False
            self.mav = self.conn.mav
            self.sock = None
            self.server = False
            self.peer = None
            port = getattr(self.conn, "port", None)
            self.fd = port.fileno() if isinstance(port, socket.socket) else self.conn.fd
        self.mav.robust_parsing = True
        #: Peers the kernel reported unreachable, for the server to forget (``collect_unreachable``).
        self.gone: list = []
        self._recverr = False
        if self.server:
            try:   # ICMP errors with the address they concern: a closed peer is noticed at once
                self.sock.setsockopt(socket.IPPROTO_IP, _IP_RECVERR, 1)
                self._recverr = hasattr(socket, "MSG_ERRQUEUE")
            except OSError:
                pass
        self.parser = mavlink.MAVLink(None, srcSystem=SYSTEM_ID, srcComponent=COMPONENT_ID)
        self.parser.robust_parsing = True
        self.last_addr = None
        self._batch: list | None = None
        self._batch_len = 0

    @property
    def has_peer(self) -> bool:
        return bool(self.clients) if self.server else True

    #: A frame's telemetry is sent as few datagrams of at most this many
    #: bytes (several whole MAVLink packets each, in order): on loopback one
    #: ``sendto`` costs as much as encoding several messages, mostly by waking
    #: the receiver, so a frame is one wake-up instead of four or five.
    BATCH_BYTES = 1200

    def begin_frame(self) -> None:
        self._batch = []
        self._batch_len = 0

    def end_frame(self) -> None:
        if self._batch:
            self._transmit_now(b"".join(self._batch))
        self._batch = None

    def transmit(self, buf: bytes) -> None:
        batch = self._batch
        if batch is None:
            self._transmit_now(buf)
            return
        if self._batch_len + len(buf) > self.BATCH_BYTES and batch:
            self._transmit_now(b"".join(batch))
            batch.clear()
            self._batch_len = 0
        batch.append(buf)
        self._batch_len += len(buf)

    def _transmit_now(self, buf: bytes) -> None:
        if self.server:
            for addr in self.clients:   # one failing client must not cost the others their telemetry
                self._sendto(buf, addr)
            return
        try:
            if self.pipe is not None:
                self.pipe.send(buf)
            else:
                self.conn.write(buf)
        except OSError:
            pass

    def _sendto(self, buf: bytes, addr) -> None:
        """``sendto`` on the server socket. With IP_RECVERR the kernel reports a
        pending ICMP error (about any peer) on the next call and drops that
        datagram: collect the error and send once more."""
        try:
            self.sock.sendto(buf, addr)
        except OSError as exc:
            if exc.errno == errno.ECONNREFUSED and self._recverr:
                self.collect_unreachable()
                try:
                    self.sock.sendto(buf, addr)
                except OSError:
                    pass

    def collect_unreachable(self) -> None:
        """Move the addresses the kernel reported unreachable (ICMP port
        unreachable: the peer's socket is closed) from the error queue to
        ``gone`` (``IP_RECVERR``, Linux; elsewhere nothing is reported)."""
        if not self._recverr:
            return
        for _ in range(64):
            try:
                _, _, _, addr = self.sock.recvmsg(1, 512, socket.MSG_ERRQUEUE | socket.MSG_DONTWAIT)
            except OSError:
                return
            if addr and addr not in self.gone:
                self.gone.append(addr)

    def send(self, msg) -> None:
        """Pack (signing if set up) and send a pymavlink message."""
        try:
            buf = msg.pack(self.mav)
        except (struct_error, ValueError, TypeError, OverflowError):
            return
        self.mav.seq = (self.mav.seq + 1) & 0xFF
        self.transmit(buf)

    def reply(self, msg, addr=None) -> None:
        """Send to ``addr`` or the peer whose datagram is being handled (UDP
        server), else like ``send``."""
        addr = addr or self.last_addr
        if not self.server or addr is None:
            self.send(msg)
            return
        try:
            buf = msg.pack(self.mav)
        except (struct_error, ValueError, TypeError, OverflowError):
            return
        self.mav.seq = (self.mav.seq + 1) & 0xFF
        self._sendto(buf, addr)

    def send_fast(self, packer, args: tuple) -> None:
        """Send through a ``codec.FastPacker``."""
        try:
            buf = packer.pack(self.mav, args)
        except (struct_error, ValueError, TypeError, OverflowError):
            return
        self.transmit(buf)

    def recv_datagram(self, wait_s: float = 0.0, spin: bool = False) -> bytes | None:
        """Next datagram, waiting up to ``wait_s`` seconds (0: only what is
        queued now), or None (datagram links only).

        ``spin``: busy-poll before sleeping in the kernel, for the pipe's
        adaptive budget (``mavcore.link.pipe.AdaptiveSpin``, at most SIM_LS_SPIN). A
        lockstep answer from a peer on another core comes back within tens of
        microseconds, less than a process wake-up costs; on a loaded machine
        it comes late and the spin backs off."""
        got = self.pipe.recv(wait_s, spin)
        if got is None:
            if self.pipe.error == errno.ECONNREFUSED:
                self.pipe.error = 0
                self.collect_unreachable()
            return None
        data, addr = got
        if self.server:
            self.clients.admit(addr, time.monotonic())
        self.last_addr = addr
        return data

    def parse(self, data: bytes) -> list:
        """Every message in the datagram ``data`` (BAD_DATA objects for garbage).

        A datagram holds whole packets: the parser starts afresh on each, so a
        truncated packet can never swallow the next datagram.
        """
        mav = self.parser
        mav.buf = bytearray()
        mav.buf_index = 0
        try:
            return mav.parse_buffer(data) or []
        except Exception:   # pymavlink raised on garbage: drop the buffer
            mav.buf = bytearray()
            mav.buf_index = 0
            return []

    def receive(self):
        """Messages of the next datagram or packet (list, maybe empty), or
        None when nothing is waiting."""
        if self.udp:
            data = self.recv_datagram()
            return None if data is None else self.parse(data)
        # A stream (TCP, serial): packets may span reads, so the parser keeps its buffer.
        try:
            data = self.conn.recv(4096)
        except OSError:
            return None
        if not data:
            return None
        try:
            return self.parser.parse_buffer(data) or []
        except Exception:   # pymavlink raised on garbage: drop the buffer
            self.parser.buf = bytearray()
            self.parser.buf_index = 0
            return []

    def close(self) -> None:
        try:
            if self.pipe is not None:
                self.pipe.close()
            else:
                self.conn.close()
        except OSError:
            pass
