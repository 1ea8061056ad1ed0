"""Mission upload over the MAVLink mission protocol (MISSION_INT variant).

Sequence (https://mavlink.io/en/services/mission.html)::

    companion                         vehicle
    MISSION_COUNT(n)          ->
                              <-      MISSION_REQUEST_INT(0)   (or legacy MISSION_REQUEST)
    MISSION_ITEM_INT(0)       ->
    ...                               ...
                              <-      MISSION_ACK(MAV_MISSION_ACCEPTED)

A lost MISSION_COUNT is re-sent; a lost item is re-requested by the vehicle
(or re-sent by us when its request stops coming). Messages that are not part
of the protocol are passed to ``conn.handler`` meanwhile, so a lockstep
vehicle keeps being answered.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

from mavcore.errors import CommandRejected, LinkError


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


def upload_mission(conn, items: list, timeout_s: float = 1.0, retries: int = 5,
                   mission_type: int = mavlink.MAV_MISSION_TYPE_MISSION, capacity: int | None = None) -> int:
    """Upload ``items`` (MISSION_ITEM_INT messages with seq 0..n-1) to the vehicle.

    Parameters
    ----------
    conn : companion.link.connection.Connection
        Open link.
    items : list of MAVLink_mission_item_int_message
        From ``codec.encode_mission_item_int``, ``seq`` = index.
    timeout_s : float
        Wall-clock wait for each vehicle message before a retry.
    retries : int
        Retries per step before giving up.
    mission_type : int
        MAV_MISSION_TYPE_MISSION, or MAV_MISSION_TYPE_FENCE for a geofence.
    capacity : int, optional
        Items the vehicle holds, if known (named in a NO_SPACE rejection).

    Returns
    -------
    int
        Number of items uploaded.

    Raises
    ------
    MissionRejected
        MISSION_ACK with a result other than MAV_MISSION_ACCEPTED.
    LinkError
        The vehicle stopped answering.
    """
    n = len(items)
    ts, tc = conn.target_system, conn.target_component

    def send_count() -> None:
        conn.send(conn.mav.mission_count_encode(ts, tc, n, mission_type))

    def relevant(m) -> bool:
        t = m.get_type()
        return (t in ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK")
                and getattr(m, "mission_type", mission_type) == mission_type)

    send_count()
    last_sent: int | None = None
    misses = 0
    while True:
        try:
            m = conn.wait_for(relevant, timeout_s, "mission protocol message")
        except LinkError:
            misses += 1
            if misses > retries:
                raise LinkError(f"{conn.url}: mission upload stalled "
                                f"({'no request' if last_sent is None else f'after item {last_sent}'})") from None
            if last_sent is None:
                send_count()
            else:
                conn.send(items[last_sent])
            continue
        misses = 0
        if m.get_type() == "MISSION_ACK":
            if m.type == mavlink.MAV_MISSION_ACCEPTED and (n == 0 or last_sent == n - 1):
                return n
            if m.type != mavlink.MAV_MISSION_ACCEPTED:
                raise MissionRejected(int(m.type), n, capacity)
            continue  # a stale ACK from an earlier transaction
        seq = int(m.seq)
        if not 0 <= seq < n:
            raise MissionRejected(mavlink.MAV_MISSION_INVALID_SEQUENCE, n, capacity)
        conn.send(items[seq])
        last_sent = seq
