"""Telemetry stream scheduling (MAV_CMD_SET_MESSAGE_INTERVAL), both sides, pure.

https://mavlink.io/en/services/message_interval.html: a peer sets the
interval of one message (param1 id, param2 interval in microseconds: 0 the
default rate, -1 off) and reads it back with MAV_CMD_GET_MESSAGE_INTERVAL
(answered by MESSAGE_INTERVAL). Both are commands
(``mavcore.services.command``); this module is what the vehicle does with
them and what the companion asks for.

- ``StreamSchedule`` (the SITL): each stream's interval and next due time on
  the vehicle clock (microseconds), the streams due at a frame in a fixed
  order, the split between streams sent every frame and the slower ones (a
  frame skips the scan until ``due_min``: this runs once per sensor frame).
  ``fixed`` streams (the frame marker) cannot be changed.
- ``TelemetryServer`` (the SITL, ``sitl.server``): a frame's telemetry, the
  schedule's due streams built by the vehicle's encoders (``sitl.telemetry``)
  and the frame marker last, as a list the transport hands to its links.
- ``stream_requests`` (the companion): the intervals its set-up asks for,
  each sent with a ``command.CommandClient``.

No sockets, no clock: the vehicle time is passed in.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
DENIED = mavlink.MAV_RESULT_DENIED
UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED
HEARTBEAT = mavlink.MAVLINK_MSG_ID_HEARTBEAT


def interval_us(hz: float) -> int:
    """Interval (us) of a rate; 0 Hz or less: -1 (off)."""
    return int(round(1e6 / hz)) if hz > 0 else -1


class StreamSchedule:
    """The vehicle's stream intervals and due times.

    Parameters
    ----------
    intervals_us : dict
        Message id -> interval (us; -1 off), in the order the streams go out
        within a frame.
    period_us : int
        The sensor frame period: frame times are its multiples, so an
        interval at most this long means every frame.
    defaults_us : dict
        What interval 0 ("default rate") restores, per id; an id without a
        default is turned off by 0.
    fixed_us : dict, optional
        Streams whose interval cannot change (id -> interval): a request for
        that interval (or 0) is ACCEPTED, any other DENIED.
    """

    def __init__(self, intervals_us: dict, period_us: int, defaults_us: dict, fixed_us: dict | None = None) -> None:
        self.intervals = dict(intervals_us)
        self.next_due = {mid: 0 for mid in self.intervals}
        self.order = tuple(self.intervals)
        self.period_us = int(period_us)
        self.defaults = dict(defaults_us)
        self.fixed = dict(fixed_us or {})
        #: Streams due every frame (interval at most the period), in order.
        self.every_frame: tuple = ()
        #: Earliest due time (us) of the other enabled streams.
        self.due_min = 0
        self._split()

    def _split(self) -> None:
        iv, due, period = self.intervals, self.next_due, self.period_us
        self.every_frame = tuple(m for m in self.order if 0 <= iv[m] <= period)
        slow = [due[m] for m in self.order if iv[m] > period]
        self.due_min = min(slow) if slow else math.inf

    def enabled(self) -> list:
        """Every enabled stream, in order (a frame sent again whole)."""
        iv = self.intervals
        return [m for m in self.order if iv[m] >= 0]

    def due(self, now_us: int) -> list:
        """The streams due at ``now_us``, in order; each one's next due time
        moves on by its interval (or to ``now_us`` + interval when late)."""
        due, iv, period = self.next_due, self.intervals, self.period_us
        out = []
        due_min = math.inf
        for mid in self.order:
            interval = iv[mid]
            if interval < 0:
                continue
            if now_us >= due[mid]:
                nxt = due[mid] + interval
                due[mid] = nxt if nxt > now_us else now_us + interval
                out.append(mid)
            if interval > period and due[mid] < due_min:
                due_min = due[mid]
        self.due_min = due_min
        return out

    def send_now(self, mid: int, now_us: int) -> None:
        """Make ``mid`` due at ``now_us`` (e.g. a HEARTBEAT announcing a new state)."""
        self.next_due[mid] = now_us
        self.due_min = min(self.due_min, now_us)

    def set_interval(self, mid: int, requested_us: float, now_us: int) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL -> MAV_RESULT. A changed stream is due at once."""
        if not math.isfinite(requested_us):
            return DENIED
        iv = int(requested_us)
        if mid in self.fixed:
            return ACCEPTED if iv in (0, self.fixed[mid]) else DENIED
        if mid not in self.intervals:
            return UNSUPPORTED
        if iv == 0:
            iv = self.defaults.get(mid, -1)
        elif iv < 0:
            iv = -1
        else:
            iv = max(iv, 1)
        self.intervals[mid] = iv
        self.next_due[mid] = now_us
        self._split()
        return ACCEPTED

    def get_interval(self, mid: int) -> int | None:
        """MAV_CMD_GET_MESSAGE_INTERVAL: the interval (us; -1 off), None for an unknown stream."""
        if mid in self.fixed:
            return self.fixed[mid]
        return self.intervals.get(mid)


class TelemetryServer:
    """The vehicle's side of telemetry: what a sensor frame sends, in order.

    ``frame(now_us, frame)`` returns the frame's telemetry as a list of
    ``(packer, payload)`` pairs: ``packer`` a ``mavcore.codec`` fast packer and
    ``payload`` its argument tuple, or ``packer`` None and ``payload`` a
    pymavlink message. Order: the streams due at ``now_us`` in schedule order
    (``StreamSchedule.due``; until ``due_min`` only the every-frame ones, the
    same list without the scan), then ``extra`` (the messages of the
    frame's rangefinder readings), then the frame marker (the lockstep
    frame's end). ``heartbeat_sent`` turns True when a HEARTBEAT was built (the
    caller resets it: its wall-clock keep-alive restarts).

    Parameters
    ----------
    schedule : StreamSchedule
    encoders : dict
        Message id -> ``() -> message or None`` (None: nothing to send now).
    fast : dict
        Message id -> ``(packer, () -> payload)``: preferred over ``encoders``.
    marker : (packer, () -> payload)
        The frame marker (HIGHRES_IMU, RAW_IMU).
    extra : callable, optional
        ``(frame, out)``: appends ``(packer, payload)`` pairs to ``out`` after the
        streams: the messages of the frame's rangefinder readings, asked only
        of a frame that has some (``frame.ranges``).
    """

    def __init__(self, schedule: StreamSchedule, encoders: dict, fast: dict, marker: tuple, extra=None) -> None:
        self.schedule = schedule
        self.encoders = encoders
        self.fast = fast
        self.marker = marker
        self._marker_pack, self._marker_args = marker
        self.extra = extra
        self.heartbeat_sent = False

    def _append(self, out: list, mids) -> None:
        fast, encoders = self.fast, self.encoders
        for mid in mids:
            f = fast.get(mid)
            if f is not None:
                out.append((f[0], f[1]()))
                continue
            if mid == HEARTBEAT:
                self.heartbeat_sent = True
            msg = encoders[mid]()
            if msg is not None:
                out.append((None, msg))

    def frame(self, now_us: int, frame) -> list:
        """The telemetry of the frame at ``now_us`` (the schedule moves on). Once per sensor
        frame: the loop of ``_append`` is written out here (one call less per frame)."""
        out: list = []
        sch = self.schedule
        fast = self.fast
        for mid in (sch.due(now_us) if now_us >= sch.due_min else sch.every_frame):
            f = fast.get(mid)
            if f is not None:
                out.append((f[0], f[1]()))
            else:
                self._append(out, (mid,))
        if self.extra is not None and frame.ranges:
            self.extra(frame, out)
        out.append((self._marker_pack, self._marker_args()))
        return out

    def whole_frame(self) -> list:
        """Every enabled stream once and the marker (a frame sent again to a late peer);
        the schedule does not move."""
        out: list = []
        self._append(out, self.schedule.enabled())
        out.append((self._marker_pack, self._marker_args()))
        return out


# --- client side (the companion) ------------------------------------------------


def stream_requests(period_us: int, request_truth: bool, mute=(), low_rate=()) -> list:
    """The SET_MESSAGE_INTERVAL requests of a companion's set-up, in order:
    ``(message id, interval us, optional)``.

    LOCAL_POSITION_NED every frame (``period_us``; required), ODOMETRY (the
    truth, where the vehicle has it) every frame when ``request_truth``, the
    ``mute`` ids off (-1), and ``low_rate`` ``(id, hz)`` pairs at 1e6 / hz us.
    Only the first is required: a vehicle may lack the others.
    """
    out = [(mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, period_us, False)]
    if request_truth:
        out.append((mavlink.MAVLINK_MSG_ID_ODOMETRY, period_us, True))
    out += [(mid, -1, True) for mid in mute]
    out += [(mid, 1e6 / hz, True) for mid, hz in low_rate]
    return out
