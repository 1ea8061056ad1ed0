"""The MAVLink mission protocol, both sides, as pure state machines.

https://mavlink.io/en/services/mission.html (MISSION_INT variant)::

    client (companion, GCS)           server (vehicle)
    MISSION_COUNT(n, type)    ->
                              <-      MISSION_REQUEST_INT(0, type)
    MISSION_ITEM_INT(0)       ->
    ...                               ...
    MISSION_ITEM_INT(n-1)     ->
                              <-      MISSION_ACK(MAV_MISSION_ACCEPTED, type)

The same handshake carries the three lists a vehicle stores apart
(``mission_type`` MISSION 0, FENCE 1, RALLY 2). The vehicle drives an
upload: it requests each item, re-requests one that does not come (after
``MissionServer.RETRY_S``) and cancels after ``MAX_RETRIES``
(MAV_MISSION_OPERATION_CANCELLED); an item out of sequence is answered by
requesting the awaited one again. The client re-sends MISSION_COUNT while
no request comes, and the last item it sent while the vehicle is silent.

- ``MissionServer`` (the SITL, ``sitl.server``): storage of the three lists
  and the server's half of upload, download, clear and set-current; its
  replies are small records (``SendRequest``, ``SendCount``, ``SendItem``,
  ``SendAck``) that ``encode_reply`` turns into MAVLink.
- ``MissionUploadClient`` (the companion, ``companion.flight.core``): the
  client's half of an upload, with its timeouts and retries on the caller's
  clock (``mavcore.services.base``).

No sockets, no clock: the caller passes the time in.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from mavcore import codec
from mavcore.codec import MissionItem
from mavcore.errors import CommandRejected, LinkError
from mavcore.link.command_rules import mission_item_problem

from .base import ClientTransaction, elapsed_s

#: Items a vehicle stores by default (``energy.max_mission_items`` sets the SITL's).
MAX_MISSION_ITEMS = 2000

# --- server side (the vehicle: storage and the upload/download handshakes) ---


@dataclass(frozen=True, slots=True)
class SendRequest:
    """Reply: ask the peer for item ``seq`` (MISSION_REQUEST_INT)."""

    seq: int
    mission_type: int


@dataclass(frozen=True, slots=True)
class SendCount:
    """Reply: MISSION_COUNT."""

    count: int
    mission_type: int


@dataclass(frozen=True, slots=True)
class SendItem:
    """Reply: MISSION_ITEM_INT."""

    item: MissionItem


@dataclass(frozen=True, slots=True)
class SendAck:
    """Reply: MISSION_ACK with a MAV_MISSION_RESULT."""

    result: int
    mission_type: int


class MissionServer:
    """Mission, fence and rally storage with the MISSION_INT upload/download
    handshakes.

    The three lists (``mission_type`` MISSION 0, FENCE 1, RALLY 2) are
    stored apart; one upload at a time. ``validate(mission_type, items)``,
    when given, is asked at the end of an upload and may refuse the list
    (``(MAV_MISSION_RESULT, why)``: the stored list stays as it was), e.g. a
    fence polygon with a missing vertex. ``version`` counts every change
    of a stored list. Upload timeouts are timed by the caller's clock
    (``tick(now_s)``, seconds): the SITL passes its vehicle clock, as PX4's
    mission server runs on its own (in a lockstep simulation, simulated) time.
    An out-of-sequence item is answered by requesting the awaited one again;
    the last item re-sent after the upload's ACCEPTED (the peer lost the ACK)
    is acknowledged again, as PX4 does.

    Methods return the list of replies to send to the peer.
    """

    RETRY_S = 0.5
    #: Re-requests before an upload is cancelled: PX4's protocol timeout, 5 s without
    #: progress (MAVLINK_MISSION_PROTOCOL_TIMEOUT_DEFAULT). At 20 % loss each way a
    #: round trip fails 36 % of the time: ten in a row 4e-5, five (2.5 s) 0.6 %.
    MAX_RETRIES = 10
    TYPES = (mavlink.MAV_MISSION_TYPE_MISSION, mavlink.MAV_MISSION_TYPE_FENCE, mavlink.MAV_MISSION_TYPE_RALLY)

    def __init__(self, max_items: int = MAX_MISSION_ITEMS, validate=None) -> None:
        self.max_items = int(max_items)
        self.stored: dict[int, tuple[MissionItem, ...]] = {t: () for t in self.TYPES}
        self.current_seq = 0
        self.version = 0
        self.validate = validate
        self._upload: list[MissionItem] | None = None
        self._upload_type = mavlink.MAV_MISSION_TYPE_MISSION
        self._upload_count = 0
        #: Item count of the upload just completed (None after any other
        #: transfer): a re-sent last item means the peer lost our ACK.
        self._acked_count: int | None = None
        self._last_s = 0.0
        self._retries = 0
        #: Why the last item handled was refused (``command_rules.mission_item_problem``), else None.
        self.refused: str | None = None

    @property
    def items(self) -> tuple[MissionItem, ...]:
        """The stored mission (type MISSION)."""
        return self.stored[mavlink.MAV_MISSION_TYPE_MISSION]

    @property
    def uploading(self) -> bool:
        return self._upload is not None

    def _store(self, mission_type: int, items: tuple) -> None:
        self.stored[mission_type] = items
        if mission_type == mavlink.MAV_MISSION_TYPE_MISSION:
            self.current_seq = 0
        self.version += 1

    def handle_count(self, count: int, mission_type: int, now_s: float) -> list:
        self._acked_count = None
        if mission_type not in self.stored:
            return [SendAck(mavlink.MAV_MISSION_UNSUPPORTED, mission_type)]
        if count < 0 or count > self.max_items:
            self._upload = None
            return [SendAck(mavlink.MAV_MISSION_NO_SPACE, mission_type)]
        if count == 0:
            self._upload = None
            self._store(mission_type, ())
            return [SendAck(mavlink.MAV_MISSION_ACCEPTED, mission_type)]
        self._upload = []
        self._upload_type = mission_type
        self._upload_count = count
        self._last_s = now_s
        self._retries = 0
        return [SendRequest(0, mission_type)]

    def handle_item(self, item: MissionItem, now_s: float) -> list:
        mt = item.mission_type
        self.refused = None
        if (self._upload is None and mt == self._upload_type
                and self._acked_count is not None and 0 <= item.seq < self._acked_count):
            # An item of the upload just accepted, again. The last one: the peer
            # lost our ACK and retries; acknowledge again, as PX4 does (PX4 PR
            # #9547). An earlier one: a late copy of a re-sent item that crossed
            # our ACCEPTED on a reordering link; the peer, which may still be
            # waiting for that ACK, ignores an ACCEPTED before its last item, and
            # refusing the copy failed an upload that had succeeded (20 % loss,
            # 0-30 ms jitter: 3 of 300 uploads of 12 items).
            return [SendAck(mavlink.MAV_MISSION_ACCEPTED, mt)]
        if self._upload is None or mt != self._upload_type:
            # An item nobody asked for: tell the peer the sequence is wrong.
            return [SendAck(mavlink.MAV_MISSION_INVALID_SEQUENCE, mt)]
        expected = len(self._upload)
        if item.seq != expected:
            # Duplicate or skipped item: ask again for the one we need.
            self._last_s = now_s
            return [SendRequest(expected, mt)]
        bad = mission_item_problem(item.frame, (item.param1, item.param2, item.param3, item.param4),
                                   item.x, item.y, item.z)
        if bad is not None:
            # the upload ends with the error (mission protocol): the stored mission stays as it was
            self._upload = None
            self.refused = f"mission item {item.seq}: {bad[1]}"
            return [SendAck(bad[0], mt)]
        self._upload.append(item)
        self._last_s = now_s
        self._retries = 0
        if len(self._upload) < self._upload_count:
            return [SendRequest(expected + 1, mt)]
        items = tuple(self._upload)
        self._upload = None
        bad = self.validate(mt, items) if self.validate is not None else None
        if bad is not None:
            self.refused = bad[1]
            return [SendAck(bad[0], mt)]
        self._store(mt, items)
        self._acked_count = len(items)
        return [SendAck(mavlink.MAV_MISSION_ACCEPTED, mt)]

    def handle_request_list(self, mission_type: int) -> list:
        self._acked_count = None
        return [SendCount(len(self.stored.get(mission_type, ())), mission_type)]

    def handle_request(self, seq: int, mission_type: int) -> list:
        items = self.stored.get(mission_type, ())
        if not 0 <= seq < len(items):
            return [SendAck(mavlink.MAV_MISSION_INVALID_SEQUENCE, mission_type)]
        return [SendItem(items[seq])]

    def handle_clear_all(self, mission_type: int) -> list:
        cleared = self.TYPES if mission_type == mavlink.MAV_MISSION_TYPE_ALL else (
            (mission_type,) if mission_type in self.stored else ())
        for t in cleared:
            self._store(t, ())
        if cleared:
            self._upload = None
            self._acked_count = None
        return [SendAck(mavlink.MAV_MISSION_ACCEPTED, mission_type)]

    def handle_set_current(self, seq: int) -> bool:
        """MISSION_SET_CURRENT: True if ``seq`` exists."""
        if 0 <= seq < len(self.items):
            self.current_seq = seq
            return True
        return False

    def tick(self, now_s: float) -> list:
        """Re-request the awaited item after RETRY_S; give up after MAX_RETRIES."""
        if self._upload is None or now_s - self._last_s < self.RETRY_S:
            return []
        self._last_s = now_s
        self._retries += 1
        if self._retries > self.MAX_RETRIES:
            self._upload = None
            return [SendAck(mavlink.MAV_MISSION_OPERATION_CANCELLED, self._upload_type)]
        return [SendRequest(len(self._upload), self._upload_type)]


def encode_reply(mav, target_system: int, target_component: int, reply):
    """A ``MissionServer`` reply record -> the MAVLink message addressed to the peer."""
    if isinstance(reply, SendRequest):
        return mav.mission_request_int_encode(target_system, target_component, reply.seq, reply.mission_type)
    if isinstance(reply, SendCount):
        return mav.mission_count_encode(target_system, target_component, reply.count, reply.mission_type)
    if isinstance(reply, SendItem):
        return codec.mission_item_int(mav, target_system, target_component, reply.item)
    if isinstance(reply, SendAck):
        return mav.mission_ack_encode(target_system, target_component, reply.result, reply.mission_type)
    raise TypeError(f"not a mission reply: {reply!r}")


# --- client side (the companion: an upload) ------------------------------------


def mission_result_text(result: int, n_items: int | None = None, capacity: int | None = None) -> str:
    """A MAV_MISSION_RESULT in words: its name and what it means for this upload.

    ``MAV_MISSION_NO_SPACE`` reads "no space: N items, vehicle holds M" (M from
    ``capacity`` when the caller knows it, e.g. ``energy.max_mission_items``).
    """
    entry = mavlink.enums["MAV_MISSION_RESULT"].get(int(result))
    name = entry.name if entry is not None else f"MAV_MISSION_RESULT {int(result)}"
    if result == mavlink.MAV_MISSION_NO_SPACE:
        holds = f"vehicle holds {capacity}" if capacity is not None else "more than the vehicle holds"
        items = f"{n_items} items" if n_items is not None else "the mission"
        return f"no space: {items}, {holds} ({name})"
    short = name.removeprefix("MAV_MISSION_").lower().replace("_", " ")
    desc = (entry.description or "").strip().rstrip(".") if entry is not None else ""
    return f"{short}: {desc} ({name})" if desc else f"{short} ({name})"


class MissionRejected(CommandRejected):
    """The vehicle answered the upload with a MISSION_ACK other than ACCEPTED.

    The message is the MAV_MISSION_RESULT in words (:func:`mission_result_text`),
    not a MAV_RESULT: ``str(exc)`` reads e.g. "mission upload rejected: no space:
    2500 items, vehicle holds 2000 (MAV_MISSION_NO_SPACE)".
    """

    def __init__(self, result: int, n_items: int | None = None, capacity: int | None = None) -> None:
        super().__init__(mavlink.MAVLINK_MSG_ID_MISSION_COUNT, result, "mission upload")
        self.args = (f"mission upload rejected: {mission_result_text(result, n_items, capacity)}",)


#: The vehicle's messages an upload listens to.
UPLOAD_ANSWERS = frozenset(("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"))


class MissionUploadClient(ClientTransaction):
    """Upload ``items`` (MISSION_ITEM_INT messages, ``seq`` = index) of ``mission_type``.

    Every vehicle answer (a request or an ACK, of any type) restarts the
    wait; ``timeout_s`` without one re-sends MISSION_COUNT (no request seen
    yet) or the last item sent, up to ``retries`` times in a row, then the
    upload fails with ``LinkError`` ("mission upload stalled"). A request
    outside 0..n-1 fails it with ``MissionRejected(MAV_MISSION_INVALID_SEQUENCE)``,
    an ACK other than ACCEPTED with ``MissionRejected(result)``; ACCEPTED
    ends it once the last item has been sent (an earlier one is a stale ACK
    of another transaction). ``outcome()``: the number of items uploaded.

    Parameters
    ----------
    mav : pymavlink MAVLink
        Encoder of the MISSION_COUNT (no file; the caller frames it).
    target_system, target_component : int
    items : list of MAVLink_mission_item_int_message
    mission_type : int
        MAV_MISSION_TYPE_MISSION, _FENCE or _RALLY.
    timeout_s : float
        Wait for each vehicle answer, in the caller's clock (s).
    retries : int
        Re-sends in a row before the upload fails.
    capacity : int, optional
        Items the vehicle holds, when known: a NO_SPACE rejection then names
        the count and the capacity.
    """

    def __init__(self, mav, target_system: int, target_component: int, items: list,
                 mission_type: int = mavlink.MAV_MISSION_TYPE_MISSION, timeout_s: float = 1.0, retries: int = 5,
                 capacity: int | None = None) -> None:
        self.items = list(items)
        self.n = len(self.items)
        self.mission_type = int(mission_type)
        self.timeout_s = float(timeout_s)
        self.retries = int(retries)
        self.capacity = capacity
        self._count = mav.mission_count_encode(target_system, target_component, self.n, self.mission_type)
        self.last_sent: int | None = None
        #: The last item has been sent (an ACCEPTED then ends the upload).
        self.sent_last = False
        self.misses = 0
        self._t0: float | None = None

    def start(self, now_s: float | None) -> list:
        self._t0 = now_s
        return [self._count]

    def _rejected(self, result: int) -> MissionRejected:
        named = self.n if self.capacity is not None else None
        return MissionRejected(result, named, self.capacity)

    def on_message(self, m, now_s: float | None) -> list:
        if self.done or m.get_type() not in UPLOAD_ANSWERS:
            return []
        self._t0 = now_s
        if getattr(m, "mission_type", self.mission_type) != self.mission_type:
            return []
        self.misses = 0
        if m.get_type() == "MISSION_ACK":
            if m.type == mavlink.MAV_MISSION_ACCEPTED and (self.n == 0 or self.sent_last):
                self._finish(self.n)
            elif m.type != mavlink.MAV_MISSION_ACCEPTED:
                self._finish(error=self._rejected(int(m.type)))
            # ACCEPTED before the last item was ever sent: a stale ACK of an earlier
            # transaction. After it, a late re-request of an earlier item may have
            # moved ``last_sent`` back (a reordering link), and the ACK is ours.
            return []
        seq = int(m.seq)
        if not 0 <= seq < self.n:
            self._finish(error=self._rejected(mavlink.MAV_MISSION_INVALID_SEQUENCE))
            return []
        self.last_sent = seq
        self.sent_last = self.sent_last or seq == self.n - 1
        return [self.items[seq]]

    def due(self, now_s: float | None, effect_seen: bool = False) -> bool:
        return not self.done and elapsed_s(now_s, self._t0) > self.timeout_s

    def tick(self, now_s: float | None, effect_seen: bool = False) -> list:
        if not self.due(now_s):
            return []
        self._t0 = now_s
        self.misses += 1
        if self.misses > self.retries:
            where = "no request" if self.last_sent is None else f"after item {self.last_sent}"
            self._finish(error=LinkError(f"mission upload stalled ({where})"))
            return []
        return [self._count if self.last_sent is None else self.items[self.last_sent]]
