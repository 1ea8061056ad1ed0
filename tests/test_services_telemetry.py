"""The stream schedule (``mavcore.services.telemetry``) without sockets.

From https://mavlink.io/en/services/message_interval.html: param2 of
SET_MESSAGE_INTERVAL is the interval in microseconds, 0 the default rate, -1
off; GET_MESSAGE_INTERVAL reports it (-1 when off). Frame times are multiples
of the sensor period, so a stream of interval I is sent at the first frame at
or after each multiple of I from when it was set.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from mavcore.services.telemetry import StreamSchedule, interval_us, stream_requests

HB, ATT, LPOS, ODO, IMU = (mavlink.MAVLINK_MSG_ID_HEARTBEAT, mavlink.MAVLINK_MSG_ID_ATTITUDE,
                           mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, mavlink.MAVLINK_MSG_ID_ODOMETRY,
                           mavlink.MAVLINK_MSG_ID_HIGHRES_IMU)
PERIOD = 4000   # 250 Hz frames


def schedule():
    defaults = {HB: interval_us(1.0), ATT: interval_us(50.0), LPOS: interval_us(50.0), ODO: interval_us(0.0)}
    return StreamSchedule(dict(defaults), PERIOD, defaults, fixed_us={IMU: PERIOD})


def frames_sent(s, mid, seconds):
    return sum(mid in s.due(k * PERIOD) for k in range(int(seconds * 1e6 / PERIOD)))


def test_rates_per_second_follow_the_intervals():
    s = schedule()
    assert interval_us(0.0) == -1 and s.intervals[ODO] == -1
    # 1 s of 250 frames: 1 HEARTBEAT, 50 ATTITUDE (every 5th frame), no ODOMETRY
    counts = [0, 0, 0]
    for k in range(250):
        due = s.due(k * PERIOD)
        counts = [c + (m in due) for c, m in zip(counts, (HB, ATT, ODO))]
    assert counts == [1, 50, 0]


def test_set_interval_every_frame_default_and_off():
    s = schedule()
    assert s.set_interval(ODO, PERIOD, 0) == mavlink.MAV_RESULT_ACCEPTED
    assert ODO in s.every_frame and frames_sent(s, ODO, 1.0) == 250
    assert s.set_interval(ODO, 1000, 0) == mavlink.MAV_RESULT_ACCEPTED       # faster than frames: every frame
    assert s.get_interval(ODO) == 1000 and ODO in s.every_frame
    assert s.set_interval(ATT, -1, 0) == mavlink.MAV_RESULT_ACCEPTED and frames_sent(s, ATT, 1.0) == 0
    assert s.get_interval(ATT) == -1
    assert s.set_interval(ATT, 0, 0) == mavlink.MAV_RESULT_ACCEPTED and s.get_interval(ATT) == 20000
    assert s.set_interval(ODO, 0, 0) == mavlink.MAV_RESULT_ACCEPTED and s.get_interval(ODO) == -1  # no default: off


def test_fixed_unknown_and_unusable_requests():
    s = schedule()
    assert s.set_interval(IMU, PERIOD, 0) == mavlink.MAV_RESULT_ACCEPTED
    assert s.set_interval(IMU, 0, 0) == mavlink.MAV_RESULT_ACCEPTED
    assert s.set_interval(IMU, 2 * PERIOD, 0) == mavlink.MAV_RESULT_DENIED
    assert s.get_interval(IMU) == PERIOD
    assert s.set_interval(12345, 1000, 0) == mavlink.MAV_RESULT_UNSUPPORTED and s.get_interval(12345) is None
    assert s.set_interval(ATT, math.nan, 0) == mavlink.MAV_RESULT_DENIED


def test_a_changed_stream_is_due_at_once_and_send_now():
    s = schedule()
    s.due(0)
    assert HB not in s.due(400_000)
    s.set_interval(HB, 500_000, 400_000)
    assert HB in s.due(400_000) and HB in s.due(900_000) and HB not in s.due(1_000_000)
    s.send_now(HB, 1_004_000)
    assert s.due_min <= 1_004_000 and HB in s.due(1_004_000)
    assert s.enabled() == [HB, ATT, LPOS]


def test_companion_requests():
    reqs = stream_requests(PERIOD, True, mute=(ATT,), low_rate=((HB, 5.0),))
    assert reqs == [(LPOS, PERIOD, False), (ODO, PERIOD, True), (ATT, -1, True), (HB, 200_000.0, True)]
    assert stream_requests(PERIOD, False) == [(LPOS, PERIOD, False)]


def test_telemetry_server_builds_the_due_streams_then_the_frame_then_the_marker():
    """``TelemetryServer.frame``: the due streams in schedule order (fast packer when there is one,
    else the encoder; an encoder with nothing to say is skipped), the frame's own messages, the
    marker last; at 250 Hz frames with HEARTBEAT 1 Hz and ATTITUDE / LOCAL_POSITION_NED 50 Hz,
    frame 0 carries all three, frames 1-4 none of them, frame 5 the two 50 Hz ones."""
    from types import SimpleNamespace

    from mavcore.services.telemetry import TelemetryServer

    quiet = SimpleNamespace(ranges=())                 # a frame without rangefinder readings
    s = schedule()
    built = []
    encoders = {HB: lambda: built.append("hb") or "HB-msg", ATT: lambda: None, LPOS: lambda: "LPOS-msg"}
    fast = {ATT: ("att-packer", lambda: ("att-args",))}
    srv = TelemetryServer(s, encoders, fast, ("imu-packer", lambda: ("imu-args",)),
                          extra=lambda frame, out: out.append(("range-packer", frame.ranges)))
    assert srv.frame(0, SimpleNamespace(ranges=("r0",))) == [
        (None, "HB-msg"), ("att-packer", ("att-args",)), (None, "LPOS-msg"), ("range-packer", ("r0",)),
        ("imu-packer", ("imu-args",))]
    assert srv.heartbeat_sent and built == ["hb"]
    srv.heartbeat_sent = False
    for k in range(1, 5):
        assert srv.frame(k * PERIOD, quiet) == [("imu-packer", ("imu-args",))]
    assert srv.frame(5 * PERIOD, quiet) == [("att-packer", ("att-args",)), (None, "LPOS-msg"),
                                           ("imu-packer", ("imu-args",))]
    assert not srv.heartbeat_sent
    encoders[LPOS] = lambda: None                    # nothing to report: skipped, the rest in order
    assert srv.frame(10 * PERIOD, quiet) == [("att-packer", ("att-args",)), ("imu-packer", ("imu-args",))]
    # every frame (interval <= period): the same list without the scan (due_min in the future)
    s.set_interval(ODO, PERIOD, 11 * PERIOD)
    encoders[ODO] = lambda: "ODO-msg"
    assert s.due_min > 12 * PERIOD
    assert srv.frame(12 * PERIOD, quiet) == [(None, "ODO-msg"), ("imu-packer", ("imu-args",))]
    # a frame sent again whole: every enabled stream, the schedule untouched
    due = dict(s.next_due)
    assert srv.whole_frame() == [(None, "HB-msg"), ("att-packer", ("att-args",)), (None, "ODO-msg"),
                                 ("imu-packer", ("imu-args",))]          # LPOS enabled, nothing to say
    assert s.next_due == due
