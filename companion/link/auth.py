"""Which incoming messages the companion believes: its vehicle's, and only those (no I/O).

A message is accepted when, in this order:

1. its system/component ids are the vehicle's (DESIGN: 1/1);
2. with a signing key: its signature verifies and its timestamp is new
   (``mavcore.link.signing.SignatureVerifier``; the vehicle signs all it sends);
3. it comes from the vehicle's address: the source address of the first
   HEARTBEAT that passed 1-2 binds it (before that only a HEARTBEAT is
   accepted); a spoofed sysid 1 from another port is dropped. The binding
   never moves (a vehicle keeps its address; a new companion run starts afresh);
4. its vehicle time is plausible (``TIMED_FIELDS``): the vehicle clock is
   the newest accepted HIGHRES_IMU ``time_usec``; a timed message more than
   ``max_time_jump_s`` (default 1 s) before or after it is dropped. A
   HIGHRES_IMU that jumps is dropped too, unless ``resync_frames``
   consecutive jumped frames agree with each other (each within the
   tolerance of the previous one, increasing): then the clock re-anchors
   there (a vehicle reboot, a long gap), so one spoofed frame can never
   move the clock and a lost stretch of frames cannot lock the link out.

Everything dropped is counted by reason (``LinkStats``, for report.json).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from mavcore.link.signing import SignatureVerifier

#: The sensor-frame messages that carry the vehicle's clock (PX4: HIGHRES_IMU,
#: ArduCopter: RAW_IMU; ``mavcore.autopilot``).
FRAME_TYPES = frozenset({"HIGHRES_IMU", "RAW_IMU"})

#: Messages the runner times by, and their vehicle-time field (s = field * scale).
TIMED_FIELDS = {
    "HIGHRES_IMU": ("time_usec", 1e-6),
    "RAW_IMU": ("time_usec", 1e-6),
    "ODOMETRY": ("time_usec", 1e-6),
    "LOCAL_POSITION_NED": ("time_boot_ms", 1e-3),
    "ATTITUDE": ("time_boot_ms", 1e-3),
    "ATTITUDE_QUATERNION": ("time_boot_ms", 1e-3),
    "DISTANCE_SENSOR": ("time_boot_ms", 1e-3),
}


@dataclass(frozen=True)
class LinkStats:
    """What the companion's link received and dropped (counts of messages).

    Attributes
    ----------
    received : int
        Messages decoded (before the checks).
    accepted : int
        Messages passed to the flight logic.
    foreign_id : int
        Not from the vehicle's system/component.
    foreign_address : int
        The vehicle's ids from another address than the vehicle's.
    before_heartbeat : int
        The vehicle's messages before its first heartbeat bound its address.
    unsigned, bad_signature, replayed : int
        Signing on: no signature; a signature that does not verify; an old
        (replayed or stale) timestamp.
    time_jump : int
        Vehicle time more than the tolerance away from the vehicle clock.
    clock_resyncs : int
        Times the clock re-anchored after agreeing jumped frames.
    bad_packets : int
        Undecodable data (set by the connection).
    vehicle_address : str or None
        ``host:port`` the vehicle is bound to.
    """

    received: int = 0
    accepted: int = 0
    foreign_id: int = 0
    foreign_address: int = 0
    before_heartbeat: int = 0
    unsigned: int = 0
    bad_signature: int = 0
    replayed: int = 0
    time_jump: int = 0
    clock_resyncs: int = 0
    bad_packets: int = 0
    vehicle_address: str | None = None

    @property
    def dropped(self) -> int:
        return self.received - self.accepted

    def to_dict(self) -> dict:
        d = asdict(self)
        d["dropped"] = self.dropped
        return d


_SIG_COUNTER = {"unsigned": "unsigned", "bad_signature": "bad_signature", "malformed": "bad_signature",
                "replay": "replayed", "stale": "replayed"}


class VehicleFilter:
    """The rules of the module docstring, as state and decisions (no I/O).

    Parameters
    ----------
    sysid, compid : int
        The vehicle's ids.
    verifier : SignatureVerifier or None
        Signing on: every vehicle message must be signed.
    max_time_jump_s : float
        Tolerance between a timed message and the vehicle clock (s, > 0).
    resync_frames : int
        Agreeing jumped HIGHRES_IMU frames that re-anchor the clock (>= 2).
    """

    def __init__(self, sysid: int = 1, compid: int = 1, verifier: SignatureVerifier | None = None,
                 max_time_jump_s: float = 1.0, resync_frames: int = 25) -> None:
        if not max_time_jump_s > 0 or int(resync_frames) < 2:
            raise ValueError("max_time_jump_s must be > 0 and resync_frames >= 2")
        self.sysid = int(sysid)
        self.compid = int(compid)
        self.verifier = verifier
        self.max_time_jump_s = float(max_time_jump_s)
        self.resync_frames = int(resync_frames)
        self.vehicle_addr = None
        self._bound = False
        self.clock_s: float | None = None
        self._cand_s: float | None = None    # last jumped frame of a candidate re-anchoring run
        self._cand_n = 0
        self._n = {k: 0 for k in ("received", "accepted", "foreign_id", "foreign_address", "before_heartbeat",
                                  "unsigned", "bad_signature", "replayed", "time_jump", "clock_resyncs")}

    def stats(self, bad_packets: int = 0) -> LinkStats:
        a = self.vehicle_addr
        where = None if a is None else (f"{a[0]}:{a[1]}" if isinstance(a, tuple) and len(a) == 2 else str(a))
        return LinkStats(**self._n, bad_packets=int(bad_packets), vehicle_address=where)

    def filter(self, msgs, addr) -> list:
        """The accepted messages of one datagram (or read) from ``addr`` (None on a stream link)."""
        if not msgs:
            return []
        accept = self.accept
        return [m for m in msgs if accept(m, addr)]

    def accept(self, m, addr) -> bool:
        """Decide on one message (see the module docstring)."""
        n = self._n
        n["received"] += 1
        if m.get_srcSystem() != self.sysid or m.get_srcComponent() != self.compid:
            n["foreign_id"] += 1
            return False
        if self.verifier is not None:
            check = self.verifier.check(bytes(m.get_msgbuf()))
            if not check.ok:
                n[_SIG_COUNTER.get(check.verdict, "bad_signature")] += 1
                return False
        mtype = m.get_type()
        if not self._bound:
            if mtype != "HEARTBEAT":
                n["before_heartbeat"] += 1
                return False
            self._bound = True
            self.vehicle_addr = addr
        elif addr != self.vehicle_addr:
            n["foreign_address"] += 1
            return False
        timed = TIMED_FIELDS.get(mtype)
        if timed is not None and not self._time_ok(mtype, float(getattr(m, timed[0])) * timed[1]):
            n["time_jump"] += 1
            return False
        n["accepted"] += 1
        return True

    def _time_ok(self, mtype: str, t_s: float) -> bool:
        clock = self.clock_s
        tol = self.max_time_jump_s
        if mtype not in FRAME_TYPES:
            return clock is None or abs(t_s - clock) <= tol
        if clock is None or abs(t_s - clock) <= tol:
            if clock is None or t_s > clock:
                self.clock_s = t_s
            self._cand_s, self._cand_n = None, 0
            return True
        cand = self._cand_s
        if cand is not None and cand < t_s <= cand + tol:
            self._cand_n += 1
        else:
            self._cand_n = 1
        self._cand_s = t_s
        if self._cand_n >= self.resync_frames:
            self.clock_s = t_s
            self._cand_s, self._cand_n = None, 0
            self._n["clock_resyncs"] += 1
            return True
        return False
