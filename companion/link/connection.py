"""A thin MAVLink 2 link to the vehicle over pymavlink's ``mavutil``.

Connection strings follow pymavlink and are from the companion's point of
view: the bundled SITL listens with ``udpin:127.0.0.1:14540`` by default, so
the companion connects with ``udpout:127.0.0.1:14540`` (it sends first, the
SITL learns its address from that first heartbeat). ``udpin:HOST:PORT``
(wait for the vehicle to send), ``tcp:HOST:PORT``, ``tcpin:HOST:PORT`` and a
serial device (``/dev/ttyACM0[,baud]``) work too.

The companion is system 1, component 191 (MAV_COMP_ID_ONBOARD_COMPUTER) and
sends HEARTBEAT as MAV_TYPE_ONBOARD_CONTROLLER / MAV_AUTOPILOT_INVALID once a
second of vehicle time (``heartbeat_due``). Receiving never raises on bad
bytes: undecodable data is counted in ``n_bad`` and dropped. Timeouts that
guard the link's liveness (no answer at all) are wall-clock; everything the
flight does is timed by the vehicle's clock in the runner.

UDP sockets are opened by ``mavcore.link.sockets.open_udp``: ``udpout``
is connected to the vehicle (the kernel drops datagrams from anyone else),
``udpin`` binds exactly the address given, and a port in use is an error.
Every received message passes ``companion.link.auth.VehicleFilter`` (the
vehicle's ids, its address, signatures, plausible vehicle time); what it
drops is counted in ``link_stats()``. With ``signing_key`` every message
sent is signed (MAVLink 2) and only correctly signed vehicle messages are
accepted.
"""

from __future__ import annotations

import os
import select
import time
from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from mavcore.errors import InputError, LinkError, UnsafeMessage
from mavcore import codec
from mavcore.link.command_rules import actuator_problem, outgoing_problem
from .auth import FRAME_TYPES, LinkStats, VehicleFilter
from mavcore.link.signing import SignatureVerifier, enable_outgoing_signing, signing_timestamp
from mavcore.link.sockets import is_datagram_url, open_pipe
from .tlog import TlogWriter

COMPANION_SYSTEM_ID = 1
COMPANION_COMPONENT_ID = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER  # 191

_SCHEMES = ("udpin:", "udpout:", "udp:", "udpbcast:", "tcp:", "tcpin:")
_MEMORY = "inproc:"


def check_connection_string(url: str) -> None:
    """Reject strings pymavlink would silently misread (e.g. a log file path).

    Raises
    ------
    InputError
        Not ``udpin:/udpout:/udp:/udpbcast:/tcp:/tcpin:HOST:PORT``, ``inproc:NAME``
        (an in-process SITL, ``sitl.api.SitlInProcess``) nor a serial device.
    """
    if url.startswith(_SCHEMES):
        rest = url.split(":", 1)[1]
        host, sep, port = rest.rpartition(":")
        if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise InputError(f"--connect {url}", "expected SCHEME:HOST:PORT, e.g. udpout:127.0.0.1:14540")
        return
    if url.startswith(("/dev/", "COM")):
        return
    if url.startswith(_MEMORY) and len(url) > len(_MEMORY):
        return
    raise InputError(f"--connect {url}", "unknown connection string (use udpout:HOST:PORT, udpin:HOST:PORT, "
                     "tcp:HOST:PORT, tcpin:HOST:PORT or a serial device)")


class Connection:
    """MAVLink 2 link to one vehicle (system ``target_system``, component 1).

    Parameters
    ----------
    url : str
        pymavlink connection string (see the module docstring).
    tlog : TlogWriter or None
        Records every packet sent and received (already opened by the caller).
    target_system, target_component : int
        The vehicle (1/1, docs/mavlink.md "Who is who").
    signing_key : bytes or None
        32-byte MAVLink 2 signing key (``mavcore.link.signing.load_signing_key``).
    max_time_jump_s : float
        Vehicle-time tolerance of ``VehicleFilter`` (s).

    Notes
    -----
    The constructor does no I/O; ``open`` creates the socket.
    """

    def __init__(self, url: str, tlog: TlogWriter | None = None, target_system: int = 1,
                 target_component: int = 1, signing_key: bytes | None = None,
                 max_time_jump_s: float = 1.0) -> None:
        check_connection_string(url)
        self.url = url
        self.tlog = tlog
        self.target_system = target_system
        self.target_component = target_component
        self.signing_key = None if signing_key is None else bytes(signing_key)
        self.filter = VehicleFilter(target_system, target_component,
                                    None if signing_key is None else SignatureVerifier(signing_key),
                                    max_time_jump_s)
        self._parser = None        # MAVLink object without a key: signatures are VehicleFilter's
        self.n_bad = 0
        self.n_received = 0
        self.n_sent = 0
        self.handler: Callable[[object], None] | None = None
        self._conn = None
        self._mav = None
        self._fd = None
        self._is_udp = url.startswith(("udp", _MEMORY))   # datagrams carry whole packets
        self._last_heartbeat_s: float | None = None
        self._pipe = None          # datagram pipe (UDP socket or in-process, ``mavcore.link.pipe``), see ``open``
        self._dest = None          # udpout: the vehicle's resolved address
        self._rx_log = None        # packets received, not yet in the tlog (see ``_record_answer``)
        self._rx_frames = None     # [(index in _rx_log, HIGHRES_IMU time_usec)] of that batch
        self._tx_log = []          # packets sent while a received batch waits, in order
        #: Lockstep (set by the runner): a datagram that does not end a sensor
        #: frame (an immediate reply such as COMMAND_ACK or MISSION_REQUEST) is
        #: returned together with the vehicle's next frame datagram, so that
        #: whatever the caller does in reaction always follows the same frame
        #: whatever the arrival timing (UDP): same seed, same flight.
        self.frame_sync = False
        self._spin_s = 0.0
        #: Time stamp (us) for the .tlog records: the runner maps the vehicle's
        #: clock onto the wall clock (``MissionRunner._stamp_us``); None: wall clock.
        self.clock: Callable[[], int] | None = None

    @property
    def spin_s(self) -> float:
        """Lockstep (set by the runner): busy-poll up to this long (s) for the
        next datagram before sleeping in the kernel (UDP; adaptive, see
        ``mavcore.link.pipe.AdaptiveSpin``). The vehicle's next frame usually arrives
        within tens of microseconds, less than a process wake-up costs. Only
        worth it with the vehicle on another core and that core free."""
        return self._spin_s

    @spin_s.setter
    def spin_s(self, value: float) -> None:
        self._spin_s = float(value)
        if self._pipe is not None and not self._pipe.memory:
            self._pipe.spin.max_s = self._spin_s

    @property
    def in_process(self) -> bool:
        """The vehicle is an in-process SITL (``inproc:NAME``)."""
        return self._pipe is not None and self._pipe.memory

    def _stamp(self) -> int:
        c = self.clock
        return c() if c is not None else int(time.time() * 1e6)

    # --- lifetime ---------------------------------------------------------

    def open(self) -> "Connection":
        """Create the socket (or serial/TCP connection).

        Raises
        ------
        InputError
            Unknown host, port in use, connection refused: one line naming ``--connect``.
        """
        if is_datagram_url(self.url):
            # Read and write datagrams directly (``mavcore.link.pipe``): on UDP a
            # blocking socket with a kernel receive timeout (SO_RCVTIMEO) waits
            # for the next frame in one recvfrom() instead of select() +
            # recvfrom() + a failing recvfrom(); MSG_DONTWAIT polls without
            # waiting. In process (``inproc:``) a wait runs the SITL instead.
            pipe = open_pipe(self.url, "--connect")
            self._pipe = pipe
            self._dest = pipe.peer
            self._fd = None if pipe.memory else pipe.fileno()
            if not pipe.memory:
                pipe.spin.max_s = self._spin_s
            self._mav = mavlink.MAVLink(None, srcSystem=COMPANION_SYSTEM_ID, srcComponent=COMPANION_COMPONENT_ID)
            self._conn = pipe
        else:
            from pymavlink import mavutil  # deferred: importing mavutil is slow and sets a global dialect

            os.environ["MAVLINK20"] = "1"  # mavutil picks its dialect module from this variable
            try:
                self._conn = mavutil.mavlink_connection(
                    self.url, source_system=COMPANION_SYSTEM_ID, source_component=COMPANION_COMPONENT_ID,
                    dialect="common", autoreconnect=True, retries=0)   # one attempt: no "sleeping" retries on stdout
            except OSError as exc:
                raise InputError(f"--connect {self.url}", f"cannot connect: {exc.strerror or exc}") from None
            self._mav = self._conn.mav
            try:
                self._fd = self._conn.fd if self._conn.fd is not None else self._conn.port.fileno()
            except AttributeError:
                self._fd = None
        self._mav.robust_parsing = True
        self._parser = mavlink.MAVLink(None)
        self._parser.robust_parsing = True
        if self.signing_key is not None:
            ts = signing_timestamp(time.time())
            self.filter.verifier.timestamp = ts
            enable_outgoing_signing(self._mav, self.signing_key, 0, ts)
        return self

    def close(self) -> None:
        self._flush_rx()
        pipe, self._pipe = self._pipe, None
        if self._conn is not None:
            try:
                if pipe is not None:
                    pipe.close()
                else:
                    self._conn.close()
            except OSError:
                pass
            self._conn = None

    def link_stats(self) -> LinkStats:
        """What was received and dropped so far (``companion.link.auth``; for report.json)."""
        return self.filter.stats(self.n_bad)

    def auth_stats(self) -> dict:
        """``{"auth": link_stats()}`` as JSON, for report.json's ``link`` (the runner merges it)."""
        return {"auth": self.link_stats().to_dict()}

    def __enter__(self) -> "Connection":
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def mav(self):
        """pymavlink ``MAVLink`` protocol object (for the ``codec`` encoders)."""
        if self._mav is None:
            raise LinkError("connection is not open")
        return self._mav

    # --- send ---------------------------------------------------------------

    def send(self, msg) -> None:
        """Pack, send and record one message.

        Raises
        ------
        UnsafeMessage
            ``msg`` breaks ``command_rules`` (a non-finite or out-of-range
            command parameter, setpoint field, motor command or mission item):
            nothing is sent.
        """
        why = outgoing_problem(msg)
        if why is not None:
            raise UnsafeMessage(msg.get_type(), why)
        if self._pipe is None:
            self._mav.send(msg)
        else:
            mav = self._mav
            buf = msg.pack(mav)
            mav.seq = (mav.seq + 1) % 256
            mav.total_packets_sent += 1
            mav.total_bytes_sent += len(buf)
            self._write(buf)
        self.n_sent += 1
        if self.tlog is not None:
            self._record_sent(msg.get_msgbuf())

    def _record_sent(self, buf) -> None:
        if self._rx_log is None:
            self.tlog.write(buf, self._stamp())
        else:
            self._tx_log.append(buf)

    def _flush_rx(self) -> None:
        """Record what waits: the packets of the last batch received, then the
        packets sent since, with one stamp (the clock now)."""
        rx = self._rx_log
        if rx is not None:
            self._rx_log = None
            self._rx_frames = None
            tx, self._tx_log = self._tx_log, []
            if self.tlog is not None:
                self.tlog.write_many(rx + tx, self._stamp())

    def _record_answer(self, time_usec: int) -> None:
        """The answer to sensor frame ``time_usec`` went out (it is the last packet
        of ``_tx_log``): record the received packets up to and including that
        frame's HIGHRES_IMU, then what was sent since, stamped now, i.e. with
        the frame's vehicle time (the runner's clock, which reads the vehicle
        time of the frame just handled). In lockstep a batch is one frame and
        the whole batch goes; a batch of several frames (free-running vehicle)
        is recorded frame by frame, each with its own time. Deferred until
        after the answer: in lockstep the vehicle waits for it."""
        rx = self._rx_log
        if rx is None:
            return
        cut = None
        for k, (i, t) in enumerate(self._rx_frames):
            if t == time_usec:
                cut = k
                break
        if cut is None or cut == len(self._rx_frames) - 1:
            self._flush_rx()
            return
        i = self._rx_frames[cut][0] + 1
        tx, self._tx_log = self._tx_log, []
        self.tlog.write_many(rx[:i] + tx, self._stamp())
        self._rx_log = rx[i:]
        self._rx_frames = [(j - i, t) for j, t in self._rx_frames[cut + 1:]]

    def _write(self, buf: bytes) -> None:
        pipe = self._pipe
        if pipe is not None:
            try:
                if self._dest is not None:
                    pipe.send(buf)                            # connected to the vehicle
                elif self.filter.vehicle_addr is not None:    # udpin: the vehicle's bound address
                    pipe.sendto(buf, self.filter.vehicle_addr)
            except OSError:   # e.g. ECONNREFUSED left by an ICMP error: UDP is lossy anyway
                pass
        else:
            self._conn.write(buf)

    def send_actuators(self, time_usec: int, motor_cmd, armed: bool) -> None:
        """Send and record ``codec.encode_hil_actuator_controls(mav, time_usec,
        motor_cmd, armed)``, packed by ``codec.pack_hil_actuator_controls``
        (the lockstep answer: once per sensor frame). ``UnsafeMessage`` (nothing
        sent) for motor commands that break ``command_rules.actuator_problem``."""
        mav = self._mav
        if motor_cmd is not None:
            why = actuator_problem(*motor_cmd)
            if why is not None:
                raise UnsafeMessage("HIL_ACTUATOR_CONTROLS", why)
        if self._pipe is None or mav.signing.sign_outgoing:
            self.send(codec.encode_hil_actuator_controls(mav, time_usec, motor_cmd, armed))
            if self.tlog is not None:
                self._record_answer(time_usec)
            return
        buf = codec.pack_hil_actuator_controls(mav.seq, mav.srcSystem, mav.srcComponent, time_usec, motor_cmd,
                                               armed)
        mav.seq = (mav.seq + 1) % 256
        mav.total_packets_sent += 1
        self._write(buf)
        self.n_sent += 1
        if self.tlog is not None:
            self._record_sent(buf)
            self._record_answer(time_usec)

    def send_heartbeat(self) -> None:
        self.send(self._mav.heartbeat_encode(
            mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE))

    def heartbeat_due(self, vehicle_time_s: float) -> None:
        """Send the 1 Hz heartbeat if a second of vehicle time has passed since the last one."""
        last = self._last_heartbeat_s
        if last is None or vehicle_time_s - last >= 1.0 or vehicle_time_s < last:
            self._last_heartbeat_s = vehicle_time_s
            self.send_heartbeat()

    # --- receive --------------------------------------------------------------

    def _parse(self, data: bytes) -> list:
        try:
            msgs = self._parser.parse_buffer(data)
        except Exception:  # noqa: BLE001 - pymavlink raises on some garbage; never crash the link
            msgs = None
            self.n_bad += 1
            self._reset_parser()
        if self._is_udp and self._parser.buf_len() > 0:
            # A UDP datagram carries whole packets: leftover bytes are garbage
            # (or a bad header claiming a long length) and must not swallow
            # the next datagram, which in lockstep would stall the vehicle.
            self._reset_parser()
        if not msgs:
            return []
        good = []
        for m in msgs:
            if m.get_type() in ("BAD_DATA", "UNKNOWN") or isinstance(m, mavlink.MAVLink_bad_data):
                self.n_bad += 1
                continue
            good.append(m)
        return good

    def _reset_parser(self) -> None:
        self._parser.buf = bytearray()
        self._parser.buf_index = 0
        self._parser.expected_length = mavlink.HEADER_LEN_V1 + 2

    def feed(self, data: bytes) -> list:
        """Parse raw bytes as if received (used by tests and replay); returns good
        messages (not filtered: ``VehicleFilter`` judges what came from a socket)."""
        if self._parser is None:
            self._parser = mavlink.MAVLink(None)
            self._parser.robust_parsing = True
        return self._parse(data)

    def _parse_datagram(self, data: bytes) -> list:
        """Messages of one UDP datagram: the per-frame types decoded by
        ``codec.split_datagram``, everything else by pymavlink (``_parse``)."""
        if self.signing_key is not None:
            return self._parse(data)
        out = []
        for part in codec.split_datagram(data):
            if type(part) is bytes:
                out += self._parse(part)
            else:
                out.append(part)
        return out

    def _poll_udp(self, timeout_s: float) -> list:
        """``poll`` on the datagram pipe: the next datagram, waiting up to
        ``timeout_s``, then whatever else is already queued (with
        ``frame_sync``: up to the end of the next sensor frame, each read
        waiting up to ``timeout_s``)."""
        self._flush_rx()
        pipe = self._pipe
        vfilter = self.filter
        out: list = []
        wait = timeout_s > 0
        sync = wait and self.frame_sync
        sync_until = None
        spin = wait and self._spin_s > 0
        for k in range(256):  # bound the drain so a flood cannot starve the caller
            if sync and k == 1:
                sync_until = time.monotonic() + timeout_s
            if wait and (k == 0 or (sync and time.monotonic() < sync_until)):
                got = pipe.recv(timeout_s, spin)
            else:
                got = pipe.recv(0.0)
            if got is None:   # timeout / nothing queued (EAGAIN), ECONNREFUSED, EINTR
                break
            data, addr = got
            if data:
                out += vfilter.filter(self._parse_datagram(data), addr)
            # In lockstep the vehicle sends one datagram per frame, ending with
            # its sensor frame (HIGHRES_IMU, ArduCopter RAW_IMU), and waits for the answer: return it at once instead
            # of paying for a drain read that finds nothing.
            if out and out[-1].get_type() in FRAME_TYPES:
                break
        if out:
            self.n_received += len(out)
            if self.tlog is not None:
                self._flush_rx()
                # stamped when written (after the frame was handled: its vehicle time)
                self._rx_log = [m.get_msgbuf() for m in out]
                self._rx_frames = [(i, m.time_usec) for i, m in enumerate(out) if m.get_type() in FRAME_TYPES]
        return out

    def poll(self, timeout_s: float = 0.0) -> list:
        """Receive every message available now, waiting up to ``timeout_s`` for the first.

        Returns
        -------
        list of pymavlink messages, in arrival order; garbage dropped.
        """
        conn = self._conn
        if conn is None:
            raise LinkError("connection is not open")
        if self.tlog is not None:
            self.tlog.tick()   # flushed at least once a flush interval, even while the link is silent
        if self._pipe is not None:
            return self._poll_udp(timeout_s)
        if timeout_s > 0 and self._fd is not None:
            try:
                ready, _, _ = select.select((self._fd,), (), (), timeout_s)
            except (OSError, ValueError):
                ready = (True,)
            if not ready:
                return []
        out: list = []
        tlog = self.tlog
        for _ in range(256):  # bound the drain so a flood cannot starve the caller
            try:
                data = conn.recv(65536)
            except OSError:
                break
            if not data:
                break
            for m in self.filter.filter(self._parse(data), None):
                out.append(m)
                if tlog is not None:
                    tlog.write(m.get_msgbuf(), self._stamp())
        self.n_received += len(out)
        if not out and timeout_s > 0 and self._fd is None:
            time.sleep(min(timeout_s, 0.001))
        return out

    def wait_for(self, predicate: Callable[[object], bool], timeout_s: float, what: str):
        """Receive until a message satisfies ``predicate``; others go to ``self.handler``.

        Raises
        ------
        LinkError
            Nothing matched within ``timeout_s`` seconds of wall clock.
        """
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise LinkError(f"{self.url}: no {what} within {timeout_s:g} s")
            found = None
            for m in self.poll(min(left, 0.05)):
                if found is None and predicate(m):
                    found = m
                elif self.handler is not None:
                    self.handler(m)
            if found is not None:
                return found

    def wait_heartbeat(self, timeout_s: float = 10.0):
        """Wait for the vehicle's HEARTBEAT, sending ours once a wall second so
        a ``udpin`` peer learns our address."""
        deadline = time.monotonic() + timeout_s
        while True:
            self.send_heartbeat()
            try:
                return self.wait_for(self._is_vehicle_heartbeat, min(1.0, max(deadline - time.monotonic(), 1e-3)),
                                     "HEARTBEAT")
            except LinkError:
                if time.monotonic() >= deadline:
                    raise LinkError(f"{self.url}: no vehicle HEARTBEAT within {timeout_s:g} s") from None

    def _is_vehicle_heartbeat(self, m) -> bool:
        return (m.get_type() == "HEARTBEAT" and m.get_srcSystem() == self.target_system
                and m.get_srcComponent() == self.target_component)
