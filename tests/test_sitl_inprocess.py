"""The SITL stepped by its peer's waits (``SitlServer.service`` behind
``sitl.api.SitlInProcess``): one sensor frame per lockstep answer, none without."""

from __future__ import annotations

import time

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.bundled import missions_dir
from mavcore import codec
from mavcore.link.sockets import open_pipe
from sitl.api import SitlInProcess

MISSION = missions_dir() / "flat-rectangle" / "mission.yaml"
SENSOR_HZ = 250
PERIOD_US = 1_000_000 // SENSOR_HZ          # 4000 us between HIGHRES_IMU frames


def _frame_times(pipe, parser, wait_s):
    """HIGHRES_IMU time_usec of the datagrams that one wait brings (the first
    datagram, and whatever the same SITL turn queued behind it, e.g. the
    frame after a STATUSTEXT)."""
    got = pipe.recv(wait_s)
    times = []
    while got is not None:
        msgs = parser.parse_buffer(got[0]) or []
        times += [m.time_usec for m in msgs if m.get_type() == "HIGHRES_IMU"]
        got = pipe.recv(0.0)
    return times


def test_one_frame_per_answer_and_none_without():
    sitl = SitlInProcess(MISSION, seed=1, sensor_hz=SENSOR_HZ, start=(12.0, 4.0, 0.0)).start()
    pipe = open_pipe(sitl.url, "--connect")
    parser = mavlink.MAVLink(None)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    try:
        pipe.send(mav.heartbeat_encode(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID,
                                       0, 0, mavlink.MAV_STATE_ACTIVE).pack(mav))
        # frame 0 (one sensor period after start), re-sent to the peer that waits
        times = _frame_times(pipe, parser, 1.0)
        assert times == [PERIOD_US]
        t_us = times[0]
        for k in range(20):
            pipe.send(codec.pack_hil_actuator_controls(k, 1, 191, t_us, None, True))
            times = _frame_times(pipe, parser, 1.0)
            assert times == [t_us + PERIOD_US]          # exactly one frame, one period later
            t_us = times[0]
        assert sitl.server.lockstep_engaged and sitl.server.time_us == t_us
        # an answer to an old frame releases nothing; no answer, no frame
        pipe.send(codec.pack_hil_actuator_controls(99, 1, 191, t_us - PERIOD_US, None, True))
        deadline = time.monotonic() + 0.1
        while time.monotonic() < deadline:
            assert _frame_times(pipe, parser, 0.02) == []
        assert sitl.server.time_us == t_us
    finally:
        pipe.close()
        sitl.stop()


def test_inprocess_sitl_has_one_link_and_always_lockstep():
    with pytest.raises(TypeError, match="inproc"):
        SitlInProcess(MISSION, listen="udpin:127.0.0.1:14540")
    with pytest.raises(TypeError, match="inproc"):
        SitlInProcess(MISSION, lockstep=False)
