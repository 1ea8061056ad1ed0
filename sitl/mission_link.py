"""The vehicle's mission, fence and rally storage on the link, and the
mission progress it reports.

``VehicleMission`` drives ``mavcore.services.mission.MissionServer`` (the
upload/download/clear protocol, pure) from the received MISSION_* messages,
hands the flight stack each stored list as it changes (``mission_store``:
the mission to fly, the geofence, the rally points) and reports the flown
mission's progress: MISSION_ITEM_REACHED per item completed, MISSION_CURRENT
on a change and once a second of vehicle time (PX4). Replies go to the link
a request came from; the upload's resends (``tick``) go to the uploader's
link and address. Every timeout runs on the vehicle clock (``sim.time_us``),
as PX4's mission server runs on its own clock: while lockstep holds the
clock, no item is re-requested and no upload is cancelled.

No sockets of its own: the links are passed in with each message, the
broadcast, STATUSTEXT and refusal counting are the server's (callables).
"""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

from mavcore import codec
from mavcore.services.mission import MissionServer, encode_reply

from . import mission_exec, mission_store
from .flightstack import FlightMode, SEVERITY_INFO
from .vehicle_id import COMPONENT_ID, SYSTEM_ID


class VehicleMission:
    """The MISSION_* handlers and the flight stack's mission, fence and rally points.

    Parameters
    ----------
    max_items : int
        Items one list may hold (``mission.energy.max_mission_items``).
    sim : sitl.sim.Simulation
        The vehicle clock (``time_us``).
    stack : sitl.flightstack.FlightStack
    params : mavcore.services.params.Parameters
    autopilot : mavcore.autopilot.Autopilot
    origin : codec.GeoOrigin
    home_enu_m : (3,) array
    state : callable
        ``() -> NavState`` or None before the first frame: what the flight stack knows now.
    mav : callable
        ``() -> MAVLink``: the encoder of broadcast messages.
    broadcast, say, refuse : callable
        The server's ``(msg)`` to every link, ``(severity, text)`` STATUSTEXT,
        ``(kind, why)`` refusal count and text.
    """

    def __init__(self, max_items: int, sim, stack, params, autopilot, origin, home_enu_m, state, mav,
                 broadcast, say, refuse) -> None:
        self.sim, self.stack, self.params, self.autopilot = sim, stack, params, autopilot
        self.origin, self.home_enu_m = origin, home_enu_m
        self.state, self.mav = state, mav
        self.broadcast, self.say, self.refuse = broadcast, say, refuse
        #: The storage and its protocol (``mavcore.services.mission``).
        self.server = MissionServer(max_items, validate=mission_store.validator(origin, home_enu_m))
        self._store_version = self.server.version
        self._flown_items = self.server.items       # the mission list the flight stack has
        self._current_due_us = 0
        self._peer = None                           # (link, (sysid, compid), address) of the uploader

    def handlers(self) -> dict:
        """Message type -> ``(link, msg)`` handler, for the server's receive table."""
        return {
            "MISSION_COUNT": self.on_count,
            "MISSION_ITEM_INT": self.on_item_int,
            "MISSION_ITEM": self.on_item,
            "MISSION_REQUEST_LIST": self.on_request_list,
            "MISSION_REQUEST_INT": self.on_request,
            "MISSION_REQUEST": self.on_request,
            "MISSION_CLEAR_ALL": self.on_clear,
            "MISSION_SET_CURRENT": self.on_set_current,
        }

    # ------------------------------------------------------------------ protocol
    @staticmethod
    def _send(link, peer, replies, addr=None) -> None:
        for r in replies:
            link.reply(encode_reply(link.mav, peer[0], peer[1], r), addr)

    @staticmethod
    def _src(msg):
        return msg.get_srcSystem(), msg.get_srcComponent()

    def on_count(self, link, msg) -> None:
        if not codec.addressed_to_us(msg, SYSTEM_ID, COMPONENT_ID):
            return
        self._peer = (link, self._src(msg), link.last_addr)
        replies = self.server.handle_count(int(msg.count), int(getattr(msg, "mission_type", 0)), self.now_s())
        self.sync_store()
        self._send(link, self._src(msg), replies)

    def on_item_int(self, link, msg) -> None:
        if not codec.addressed_to_us(msg, SYSTEM_ID, COMPONENT_ID):
            return
        self._item(link, msg, codec.mission_item_from_int(msg))

    def on_item(self, link, msg) -> None:
        if not codec.addressed_to_us(msg, SYSTEM_ID, COMPONENT_ID):
            return
        item = codec.mission_item_from_float(msg)
        if item is None:
            self.refuse("MISSION_ITEM", "x or y not finite or beyond the int32 of MISSION_ITEM_INT")
            return
        self._item(link, msg, item)

    def _item(self, link, msg, item) -> None:
        srv = self.server
        was = srv.uploading
        replies = srv.handle_item(item, self.now_s())
        if srv.refused is not None:
            self.refuse(msg.get_type(), srv.refused)
        stored = was and not srv.uploading and srv.version != self._store_version
        self.sync_store()      # the flight stack has the new list before the peer has the ACK
        self._send(link, self._src(msg), replies)
        if stored:
            n = len(srv.stored[item.mission_type])
            what = {mavlink.MAV_MISSION_TYPE_FENCE: "Geofence", mavlink.MAV_MISSION_TYPE_RALLY: "Rally points"}
            self.say(SEVERITY_INFO, f"{what.get(item.mission_type, 'Mission')} stored: {n} items")

    def on_request_list(self, link, msg) -> None:
        if not codec.addressed_to_us(msg, SYSTEM_ID, COMPONENT_ID):
            return
        replies = self.server.handle_request_list(int(getattr(msg, "mission_type", 0)))
        self._send(link, self._src(msg), replies)

    def on_request(self, link, msg) -> None:
        if not codec.addressed_to_us(msg, SYSTEM_ID, COMPONENT_ID):
            return
        replies = self.server.handle_request(int(msg.seq), int(getattr(msg, "mission_type", 0)))
        self._send(link, self._src(msg), replies)

    def on_clear(self, link, msg) -> None:
        if not codec.addressed_to_us(msg, SYSTEM_ID, COMPONENT_ID):
            return
        replies = self.server.handle_clear_all(int(getattr(msg, "mission_type", 0)))
        self.sync_store()
        self._send(link, self._src(msg), replies)

    def on_set_current(self, link, msg) -> None:
        if not codec.addressed_to_us(msg, SYSTEM_ID, COMPONENT_ID):
            return
        if self.server.handle_set_current(int(msg.seq)):
            m = self.stack.mission
            if m is not None:
                m.set_current(int(msg.seq))
            self.send_current()

    def now_s(self) -> float:
        """The vehicle clock (s), what the upload's timeouts run on."""
        return self.sim.time_us * 1e-6

    def tick(self) -> None:
        """Resend or abandon a stalled upload (``MissionServer.RETRY_S`` of vehicle time)."""
        if self._peer is None or not self.server.uploading:
            return
        replies = self.server.tick(self.now_s())
        if replies:
            link, peer, addr = self._peer
            self._send(link, peer, replies, addr)

    # ------------------------------------------------------------------ flight stack
    def sync_store(self) -> None:
        """A stored list changed: hand the flight stack its new mission, fence and rally points."""
        srv = self.server
        if srv.version == self._store_version:
            return
        self._store_version = srv.version
        objs = mission_store.flight_objects(srv.stored, self.origin, self.home_enu_m, self.params,
                                            self.autopilot.mission_rules)
        stack = self.stack
        stack.fence = objs.fence
        stack.rally_points = objs.rally_points
        if objs.fence is None:
            stack.fence_breached = False
        if srv.items is not self._flown_items:   # a fence or rally upload leaves the mission flying
            self._flown_items = srv.items
            stack.set_mission(objs.mission, self.state())
            self.send_current()

    def send_current(self) -> None:
        """MISSION_CURRENT to every link; the next one is due a second of vehicle time later."""
        m = self.stack.mission
        seq = m.current if m is not None else self.server.current_seq
        state = mission_store.mission_state(m, self.stack.mode is FlightMode.MISSION)
        self.broadcast(self.mav().mission_current_encode(seq, len(self.server.items), state))
        self._current_due_us = self.sim.time_us + 1_000_000

    def progress(self) -> None:
        """After a frame with a mission: MISSION_ITEM_REACHED for each item
        completed; MISSION_CURRENT on a change and once a second of vehicle
        time while a mission is stored (PX4)."""
        m = self.stack.mission
        if m.events:
            for seq in m.pop_events():
                self.broadcast(self.mav().mission_item_reached_encode(seq))
                if m.rules.reached_text and m.items[seq].command in mission_exec.ANNOUNCED_COMMANDS:
                    self.say(SEVERITY_INFO, f"Reached command #{seq}")   # ArduCopter verify_nav_wp
        if m.current_changed or self.sim.time_us >= self._current_due_us:
            m.current_changed = False
            self.send_current()
