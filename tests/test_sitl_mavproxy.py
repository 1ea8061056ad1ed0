"""MAVProxy (from PyPI, installed with --no-deps, unmodified) headless against
the SITL: connect, read the mode, list the parameters, download a mission that
was uploaded with pymavlink, see the geofence status without a breach. Driven through its stdin; real time (speed 1)."""

from __future__ import annotations

from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

pytest.importorskip("MAVProxy.mavproxy")

from mission_flight import MavProxy   # noqa: E402
from sitl.api import SitlThread   # noqa: E402
from sitl.flightstack import PARAM_SPECS   # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MISSION = ROOT / "missions" / "flat-rectangle" / "mission.yaml"

pytestmark = pytest.mark.slow

WAYPOINTS = [(448000000 + 1000 * i, -6000000 - 500 * i, 2.5 + i) for i in range(3)]


def upload_with_pymavlink(url: str) -> None:
    # 255/190: a ground station the SITL accepts control from by default (sitl.auth)
    c = mavutil.mavlink_connection(url, source_system=255, source_component=190)
    c.mav = mavlink.MAVLink(c, srcSystem=255, srcComponent=190)
    try:
        c.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        assert c.recv_match(type="HEARTBEAT", blocking=True, timeout=5) is not None
        c.mav.mission_count_send(1, 1, len(WAYPOINTS), 0)
        for _ in WAYPOINTS:
            r = c.recv_match(type="MISSION_REQUEST_INT", blocking=True, timeout=5)
            lat, lon, alt = WAYPOINTS[r.seq]
            c.mav.mission_item_int_send(1, 1, r.seq, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                        mavlink.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0, lat, lon, alt, 0)
        ack = c.recv_match(type="MISSION_ACK", blocking=True, timeout=5)
        assert ack is not None and ack.type == mavlink.MAV_MISSION_ACCEPTED
    finally:
        c.close()


def test_mavproxy_mode_params_mission(tmp_path):
    with SitlThread(MISSION, speed=1.0) as sitl:
        upload_with_pymavlink(sitl.url)
        mp = MavProxy(sitl.url, tmp_path)
        try:
            mp.expect(r"Detected vehicle 1:1")
            mp.expect(r"Mode LOITER")                                   # PX4 AUTO.LOITER, read from HEARTBEAT
            n = int(mp.expect(r"Received (\d+) parameters").group(1))   # the whole list, fetched on connect
            assert n == len(PARAM_SPECS)
            mp.send("param show COM_OF_LOSS_T")
            assert float(mp.expect(r"COM_OF_LOSS_T\s+(\S+)").group(1)) == pytest.approx(1.0)
            mp.send("param show COM_OBL_ACT")                           # INT32, byte-wise as PX4
            assert mp.expect(r"COM_OBL_ACT\s+(\S+)").group(1) == "0"
            mp.send("wp list")
            assert int(mp.expect(r"Requesting (\d+) waypoints").group(1)) == len(WAYPOINTS)
            for lat, lon, alt in WAYPOINTS:
                m = mp.expect(r"(?:^|> )16 6 (\S+) (\S+) (\S+)")
                assert (float(m.group(1)), float(m.group(2)), float(m.group(3))) == \
                    pytest.approx((lat * 1e-7, lon * 1e-7, alt), abs=1e-7)
            # SYS_STATUS carries the geofence bit (present, healthy): MAVProxy's fence module
            # reports the fence and no breach (issue 17: a spurious "fence breach" at connect)
            assert any("fence present" in line for line in mp.out)
            assert not any("fence breach" in line for line in mp.out)
        finally:
            mp.close()


# Generous waits below: a loaded machine slows MAVProxy (a passing run takes about 20 s).
def test_mavproxy_flies_the_ardupilot_personality(tmp_path):
    """MAVProxy knows ArduCopter's mode names (mavutil.mode_mapping_acm): it
    reads STABILIZE at boot, lists ArduPilot's parameters (integers as a C
    cast), switches to GUIDED, arms, takes off with MAV_CMD_NAV_TAKEOFF and
    lands with the LAND mode."""
    from mavcore.autopilot import ARDUCOPTER

    with SitlThread(MISSION, speed=2.0, autopilot="ardupilot") as sitl:
        mp = MavProxy(sitl.url, tmp_path, modules="param,mode,cmdlong,arm")
        try:
            mp.expect(r"Detected vehicle 1:1", timeout_s=30)
            mp.expect(r"Mode STABILIZE", timeout_s=30)
            n = int(mp.expect(r"Received (\d+) parameters", timeout_s=30).group(1))
            assert n == len(ARDUCOPTER.param_specs)
            mp.send("param show DISARM_DELAY")                          # INT32, C cast as ArduPilot
            assert float(mp.expect(r"DISARM_DELAY\s+(\S+)", timeout_s=30).group(1)) == 10.0     # byte-wise: 1.4e-44
            mp.send("param set DISARM_DELAY 0")     # no auto-disarm while a loaded machine is slow to take off
            mp.send("mode guided")
            mp.expect(r"Mode GUIDED", timeout_s=30)
            mp.send("arm throttle")
            mp.expect(r"(?:^|> )ARMED$", timeout_s=30)     # from HEARTBEAT; any mode's prompt may lead the line
            mp.send("takeoff 2")
            mp.expect(r"Takeoff complete", timeout_s=60)
            mp.send("mode land")
            mp.expect(r"Landing detected", timeout_s=60)
        finally:
            mp.close()
