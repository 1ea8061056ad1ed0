"""Who may control the SITL: controllers, control links, signing, clients (no I/O).

Open to anyone (read-only: they change nothing in the vehicle)
    HEARTBEAT, PARAM_REQUEST_LIST, PARAM_REQUEST_READ, PARAM_EXT_REQUEST_*,
    MISSION_REQUEST_LIST, MISSION_REQUEST_INT, MISSION_REQUEST,
    MISSION_REQUEST_PARTIAL_LIST, MISSION_ACK (the mission download
    protocol), TIMESYNC, PING, and COMMAND_LONG/COMMAND_INT with one of
    ``READ_ONLY_COMMANDS`` (REQUEST_MESSAGE, GET_MESSAGE_INTERVAL,
    REQUEST_AUTOPILOT_CAPABILITIES, GET_HOME_POSITION, the other
    MAV_CMD_REQUEST_* information requests). With a signing key, these are
    still accepted unsigned (a ground station without the key can watch).

Control (everything else the SITL acts on)
    Every other COMMAND_LONG/COMMAND_INT (arm/disarm, force-disarm, take-off,
    land, RTL, DO_SET_MODE, SET_MESSAGE_INTERVAL, mission start, ...),
    SET_MODE, SET_POSITION_TARGET_*, SET_ATTITUDE_TARGET,
    HIL_ACTUATOR_CONTROLS, PARAM_SET, PARAM_EXT_SET, MISSION_COUNT,
    MISSION_ITEM(_INT), MISSION_CLEAR_ALL, MISSION_SET_CURRENT,
    MISSION_WRITE_PARTIAL_LIST, SETUP_SIGNING, and any message type not
    listed as read-only (deny by default).

A control message is accepted only if all of these hold:

1. it arrived on a control link (the listen link and ``--control-out``
   links; plain ``--out`` links are telemetry-only);
2. its system/component ids are a configured controller's, allowed on that
   link (``Controller.link`` None: on every control link);
3. with signing (a key from ``--signing-key`` or SETUP_SIGNING): its
   signature verifies and its timestamp is new (``SignatureVerifier``);
   SETUP_SIGNING itself is refused when the key came from the command line;
4. without signing: it comes from the address the controller's first
   accepted control message came from (its binding). A binding moves to a
   new address only after the bound one has been silent for
   ``rebind_after_s`` both in wall-clock time and in vehicle time (a
   restarted companion takes over; a second process spoofing the ids from
   another port is ignored). Vehicle time matters because in lockstep the
   companion only speaks when the vehicle does: a SITL busy with a backlog
   of datagrams has not heard it, but its clock has not moved either. With
   signing a valid signature is the proof and the binding follows it at once.
   A binding is also released at once when the kernel reports the bound
   address unreachable (ICMP port unreachable: the controller's socket closed).

Ignored control messages are counted, and the first one from each source
(link, address, system, component) is reported once by STATUSTEXT
(``Verdict.report``), at most ``MAX_REPORTED_SOURCES`` sources.

Without signing the ids are not authenticated: whoever sends first from a
controller's ids holds the binding, and a configured controller that is not
connected (say the default ground station 255/190 when only the companion
flies) can be claimed by any process that reaches a control link. Signing
closes that; without it, list only the controllers in use (``--controller``).
"""

from __future__ import annotations

import collections
import re
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from mavcore.link.signing import SignatureVerifier

READ_ONLY_MESSAGES = frozenset({
    "HEARTBEAT", "PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_EXT_REQUEST_LIST",
    "PARAM_EXT_REQUEST_READ", "MISSION_REQUEST_LIST", "MISSION_REQUEST_INT", "MISSION_REQUEST",
    "MISSION_REQUEST_PARTIAL_LIST", "MISSION_ACK", "TIMESYNC", "PING",
})

READ_ONLY_COMMANDS = frozenset({
    mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAV_CMD_GET_MESSAGE_INTERVAL,
    mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, mavlink.MAV_CMD_GET_HOME_POSITION,
    mavlink.MAV_CMD_REQUEST_PROTOCOL_VERSION, mavlink.MAV_CMD_REQUEST_FLIGHT_INFORMATION,
    mavlink.MAV_CMD_REQUEST_CAMERA_INFORMATION, mavlink.MAV_CMD_REQUEST_CAMERA_SETTINGS,
    mavlink.MAV_CMD_REQUEST_CAMERA_CAPTURE_STATUS, mavlink.MAV_CMD_REQUEST_STORAGE_INFORMATION,
    mavlink.MAV_CMD_REQUEST_VIDEO_STREAM_INFORMATION, mavlink.MAV_CMD_REQUEST_VIDEO_STREAM_STATUS,
})

_COMMANDS = ("COMMAND_LONG", "COMMAND_INT")


def is_control(msg_type: str, command: int | None = None) -> bool:
    """True if a message of ``msg_type`` (and, for COMMAND_LONG/INT, ``command``) controls the vehicle."""
    if msg_type in _COMMANDS:
        return command not in READ_ONLY_COMMANDS
    return msg_type not in READ_ONLY_MESSAGES


@dataclass(frozen=True)
class Controller:
    """A system/component allowed to control the vehicle.

    Attributes
    ----------
    sysid, compid : int
        MAVLink ids (1..255 and 0..255).
    link : str or None
        Only on this control link (its connection string); None: on every control link.
    """

    sysid: int
    compid: int
    link: str | None = None

    def __post_init__(self) -> None:
        if not 1 <= self.sysid <= 255 or not 0 <= self.compid <= 255:
            raise ValueError("controller ids must be SYSID 1..255 / COMPID 0..255")

    def __str__(self) -> str:
        return f"{self.sysid}/{self.compid}" + (f"@{self.link}" if self.link else "")


#: Who controls the vehicle unless ``--controller`` says otherwise, on every control link:
#: the companion (1/191, MAV_COMP_ID_ONBOARD_COMPUTER); a ground station 255/190
#: (QGroundControl, DESIGN's GCS); MAVSDK as a ground station (system 245,
#: component 190: ``Configuration(ComponentType.GROUND_STATION)``); MAVProxy's
#: defaults (``--source-system 255 --source-component 230``).
DEFAULT_CONTROLLERS = (Controller(1, 191), Controller(255, 190), Controller(245, 190), Controller(255, 230))

_CONTROLLER = re.compile(r"\s*(\d{1,3})\s*/\s*(\d{1,3})\s*(?:@(.+))?")


def parse_controller(text: str) -> Controller:
    """``SYSID/COMPID[@LINK]`` -> Controller; ValueError if malformed."""
    m = _CONTROLLER.fullmatch(str(text))
    if m is None:
        raise ValueError(f"expected SYSID/COMPID or SYSID/COMPID@LINK, got {text!r}")
    return Controller(int(m.group(1)), int(m.group(2)), m.group(3).strip() if m.group(3) else None)


@dataclass(frozen=True)
class Verdict:
    """What to do with one incoming message.

    Attributes
    ----------
    accepted : bool
    reason : str
        Why it was ignored ("" when accepted).
    report : str or None
        A STATUSTEXT to send now (the first ignored message of its source,
        or a binding that moved), else None.
    bindings_changed : bool
        A controller was bound to a (new) address: the caller re-pins its client tables.
    """

    accepted: bool
    reason: str = ""
    report: str | None = None
    bindings_changed: bool = False


_ACCEPT = Verdict(True)
#: ``ControlPolicy.counts`` keys that are not reasons for ignoring a message.
_NOT_IGNORED = ("accepted", "rebound", "released")
_SIG_REASONS = {"unsigned": "unsigned", "bad_signature": "bad signature", "replay": "replayed signature",
                "stale": "stale signature", "malformed": "malformed signature"}


@dataclass
class _Binding:
    link: str
    addr: object
    last_s: float
    last_vehicle_s: float


class ControlPolicy:
    """The rules of the module docstring, as state and decisions (no I/O).

    Parameters
    ----------
    control_links : iterable of str
        Connection strings of the links that may carry control.
    controllers : iterable of Controller
    verifier : SignatureVerifier or None
        Signing on when set (``set_signing``).
    key_locked : bool
        The key came from the command line: SETUP_SIGNING is refused.
    rebind_after_s : float
        Silence of a bound address, in wall-clock seconds and in vehicle
        seconds both, after which another address may take the controller over.
    """

    MAX_REPORTED_SOURCES = 64

    def __init__(self, control_links, controllers=DEFAULT_CONTROLLERS, verifier: SignatureVerifier | None = None,
                 key_locked: bool = False, rebind_after_s: float = 3.0) -> None:
        self.control_links = frozenset(control_links)
        self.controllers = tuple(controllers)
        for c in self.controllers:
            if c.link is not None and c.link not in self.control_links:
                raise ValueError(f"controller {c}: {c.link!r} is not a control link "
                                 f"({', '.join(sorted(self.control_links))})")
        self._allowed = {}
        for c in self.controllers:
            links = self.control_links if c.link is None else frozenset((c.link,))
            self._allowed[(c.sysid, c.compid)] = self._allowed.get((c.sysid, c.compid), frozenset()) | links
        self.verifier = verifier
        self.key_locked = bool(key_locked and verifier is not None)
        self.rebind_after_s = float(rebind_after_s)
        self._bindings: dict[tuple[int, int], _Binding] = {}
        self._reported: set = set()
        self._overflow_reported = False
        #: accepted control messages, and ignored ones by reason (bounded: the reasons are fixed).
        self.counts: collections.Counter = collections.Counter()
        #: accepted control messages by source (link, address, sysid, compid): only
        #: bound sources are ever accepted, so this holds one entry per binding.
        self.accepted_from: collections.Counter = collections.Counter()

    # ------------------------------------------------------------------ signing
    @property
    def signing(self) -> bool:
        return self.verifier is not None

    def set_signing(self, verifier: SignatureVerifier | None) -> None:
        """Install (or with None remove) the over-the-air key (SETUP_SIGNING)."""
        if self.key_locked:
            raise RuntimeError("the signing key is fixed by the command line")
        self.verifier = verifier

    # ------------------------------------------------------------------ bindings
    def bound_addresses(self, link: str) -> set:
        """Addresses controllers are bound to on ``link`` (their client slots are pinned)."""
        return {b.addr for b in self._bindings.values() if b.link == link}

    def binding(self, sysid: int, compid: int):
        """(link, address) a controller is bound to, or None."""
        b = self._bindings.get((sysid, compid))
        return None if b is None else (b.link, b.addr)

    def release(self, link: str, addr) -> list[tuple[int, int]]:
        """Free the bindings at ``addr`` on ``link`` (its socket is known to be
        closed); returns the (sysid, compid) released."""
        ids = [k for k, b in self._bindings.items() if b.link == link and b.addr == addr]
        for k in ids:
            del self._bindings[k]
        self.counts["released"] += len(ids)
        return ids

    def observe(self, link: str, addr, sysid: int, compid: int, now_s: float, vehicle_s: float = 0.0) -> None:
        """Any message from ``addr`` on ``link``: keeps a binding there alive."""
        b = self._bindings.get((sysid, compid))
        if b is not None and b.addr == addr and b.link == link:
            b.last_s = now_s
            b.last_vehicle_s = vehicle_s

    # ------------------------------------------------------------------ decisions
    def authorize(self, link: str, addr, msg_type: str, command: int | None, sysid: int, compid: int,
                  packet: bytes | None, now_s: float, vehicle_s: float = 0.0) -> Verdict:
        """Decide on one incoming message.

        Parameters
        ----------
        link : str
            Connection string of the link it arrived on.
        addr : (host, port) or None
            Its source address (None on stream links).
        msg_type : str
            MAVLink message name.
        command : int or None
            MAV_CMD of a COMMAND_LONG/COMMAND_INT.
        sysid, compid : int
            Its source ids.
        packet : bytes or None
            The raw packet (signature checks), None if unknown.
        now_s : float
            Wall-clock seconds (monotonic), for the binding timeout.
        vehicle_s : float
            Vehicle time (s), for the binding timeout.
        """
        if not is_control(msg_type, command):
            return _ACCEPT
        ids = (sysid, compid)
        if link not in self.control_links:
            return self._ignore(link, addr, msg_type, ids, "not a control link (telemetry only)")
        links = self._allowed.get(ids)
        if links is None:
            return self._ignore(link, addr, msg_type, ids, "not a controller")
        if link not in links:
            return self._ignore(link, addr, msg_type, ids, "not a controller on this link")
        if msg_type == "SETUP_SIGNING" and self.key_locked:
            return self._ignore(link, addr, msg_type, ids, "signing key is set on the command line")
        b = self._bindings.get(ids)
        if self.verifier is not None:
            check = self.verifier.check(packet) if packet is not None else None
            if check is None or not check.ok:
                reason = _SIG_REASONS.get(check.verdict if check is not None else "unsigned", "bad signature")
                return self._ignore(link, addr, msg_type, ids, reason)
            if b is not None and b.link == link and b.addr == addr:
                b.last_s, b.last_vehicle_s = now_s, vehicle_s
                self._accepted(link, addr, ids)
                return _ACCEPT
            self._bindings[ids] = _Binding(link, addr, now_s, vehicle_s)
            self._accepted(link, addr, ids)
            return Verdict(True, bindings_changed=True)
        if b is None:
            self._bindings[ids] = _Binding(link, addr, now_s, vehicle_s)
            self._accepted(link, addr, ids)
            return Verdict(True, bindings_changed=True)
        if b.link == link and b.addr == addr:
            b.last_s, b.last_vehicle_s = now_s, vehicle_s
            self._accepted(link, addr, ids)
            return _ACCEPT
        if now_s - b.last_s > self.rebind_after_s and vehicle_s - b.last_vehicle_s > self.rebind_after_s:
            self._bindings[ids] = _Binding(link, addr, now_s, vehicle_s)
            self._accepted(link, addr, ids)
            self.counts["rebound"] += 1
            return Verdict(True, report=f"controller {sysid}/{compid} moved, now {_where(link, addr)}",
                           bindings_changed=True)
        return self._ignore(link, addr, msg_type, ids, "controller ids in use from another address")

    def _accepted(self, link: str, addr, ids) -> None:
        self.counts["accepted"] += 1
        self.accepted_from[(link, addr, ids[0], ids[1])] += 1

    def summary(self) -> dict:
        """JSON-ready counts: control accepted by source, ignored by reason, bindings moved."""
        return {
            "accepted": self.counts["accepted"],
            "accepted_from": [{"link": k[0], "address": None if k[1] is None else f"{k[1][0]}:{k[1][1]}",
                               "sysid": k[2], "compid": k[3], "messages": n}
                              for k, n in self.accepted_from.items()],
            "ignored": {k: v for k, v in self.counts.items() if k not in _NOT_IGNORED},
            "rebound": self.counts["rebound"],
            "released": self.counts["released"],
            "signing": self.signing,
        }

    def _ignore(self, link: str, addr, msg_type: str, ids, reason: str) -> Verdict:
        self.counts[reason] += 1
        source = (link, addr, ids)
        report = None
        if source not in self._reported:
            if len(self._reported) < self.MAX_REPORTED_SOURCES:
                self._reported.add(source)
                report = f"ignored {msg_type} from {ids[0]}/{ids[1]} {_where(link, addr)}: {reason}"
            elif not self._overflow_reported:
                self._overflow_reported = True
                report = f"ignoring control from more than {self.MAX_REPORTED_SOURCES} sources: not reported"
        return Verdict(False, reason, report)


def _where(link: str, addr) -> str:
    if addr is None:
        return f"on {link}"
    try:
        return f"at {addr[0]}:{addr[1]} on {link}"
    except (TypeError, IndexError):
        return f"on {link}"


class ClientTable:
    """The peers a ``udpin`` link sends telemetry to: bounded, expiring.

    A datagram from a new address admits it; when ``max_clients`` are
    already there, the least recently heard unpinned one is dropped for it
    (a flood of new source ports costs at most ``max_clients`` sends per
    message, and never locks a newcomer out). Clients silent for longer than
    ``expiry_s`` are dropped at the next admission after a sweep interval
    (1 s, or half of ``expiry_s`` if shorter).
    Pinned addresses (bound controllers, ``ControlPolicy.bound_addresses``)
    are never dropped, so a controller that waits for the vehicle keeps
    receiving it.

    Parameters
    ----------
    max_clients : int
        At least 1.
    expiry_s : float
        Wall-clock seconds of silence after which a client is dropped.
    """

    SWEEP_INTERVAL_S = 1.0

    def __init__(self, max_clients: int = 8, expiry_s: float = 10.0) -> None:
        if int(max_clients) < 1 or not expiry_s > 0:
            raise ValueError("max_clients must be >= 1 and expiry_s > 0")
        self.max_clients = int(max_clients)
        self.expiry_s = float(expiry_s)
        self._last: dict = {}
        self.pinned: set = set()
        self._next_sweep = 0.0
        self._sweep_every = min(self.SWEEP_INTERVAL_S, self.expiry_s / 2)
        self.n_evicted = 0
        self.n_expired = 0

    def __iter__(self):
        return iter(self._last)

    def __len__(self) -> int:
        return len(self._last)

    def __bool__(self) -> bool:
        return bool(self._last)

    def __contains__(self, addr) -> bool:
        return addr in self._last

    def admit(self, addr, now_s: float) -> None:
        """A datagram from ``addr`` at ``now_s`` (wall-clock seconds)."""
        last = self._last
        if addr in last:
            last[addr] = now_s
            if now_s < self._next_sweep:
                return
        if now_s >= self._next_sweep:
            self.sweep(now_s)
        if addr not in last and len(last) >= self.max_clients:
            victims = [a for a in last if a not in self.pinned]
            if not victims:
                return   # every slot is a bound controller: the newcomer only gets replies
            oldest = min(victims, key=last.__getitem__)
            del last[oldest]
            self.n_evicted += 1
        last[addr] = now_s

    def forget(self, addr) -> None:
        """Drop ``addr`` now (its socket is closed), pinned or not."""
        self._last.pop(addr, None)
        self.pinned.discard(addr)

    def sweep(self, now_s: float) -> None:
        """Drop unpinned clients silent for more than ``expiry_s``."""
        self._next_sweep = now_s + self._sweep_every
        old = [a for a, t in self._last.items() if now_s - t > self.expiry_s and a not in self.pinned]
        for a in old:
            del self._last[a]
        self.n_expired += len(old)


class IntakeBudget:
    """Bounds the work that datagrams from unbound addresses may cost (no I/O).

    A ``udpin`` link reads every datagram anyone sends it, and parsing costs
    the SITL 0.1-0.3 ms per packet: a flood would stall the vehicle's clock
    and, in lockstep, the flight. Datagrams from a bound controller's address
    (``ClientTable.pinned``) always pass; from any other address a datagram
    passes only if it is at most ``max_bytes`` long (a ground station sends
    one packet, at most 280 bytes, per datagram) and a token is left in a
    bucket refilled at ``rate_hz`` (``burst`` at most), shared by all of them.
    What does not pass is dropped unparsed and counted.

    Parameters
    ----------
    max_bytes : int
    rate_hz : float
        Datagrams per wall-clock second from all unbound addresses together.
    burst : int
    """

    def __init__(self, max_bytes: int = 1024, rate_hz: float = 1000.0, burst: int = 250) -> None:
        if max_bytes < 280 or not rate_hz > 0 or burst < 1:
            raise ValueError("max_bytes >= 280, rate_hz > 0, burst >= 1")
        self.max_bytes = int(max_bytes)
        self.rate_hz = float(rate_hz)
        self.burst = float(burst)
        self._tokens = float(burst)
        self._last_s: float | None = None
        self.n_oversized = 0
        self.n_over_rate = 0

    def admit(self, size: int, now_s: float) -> bool:
        """May a datagram of ``size`` bytes from an unbound address be parsed now?"""
        if size > self.max_bytes:
            self.n_oversized += 1
            return False
        last = self._last_s
        self._last_s = now_s
        if last is not None and now_s > last:
            self._tokens = min(self.burst, self._tokens + (now_s - last) * self.rate_hz)
        if self._tokens < 1.0:
            self.n_over_rate += 1
            return False
        self._tokens -= 1.0
        return True
