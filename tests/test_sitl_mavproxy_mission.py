"""MAVProxy (from PyPI, unmodified, headless) flies the planner's exported
"QGC WPL 110" mission in AUTO on both personalities (issue 17), the way each
stack's users rehearse one (docs/mission.md "Rehearsing an exported mission
with MAVProxy"):

- ArduCopter (``sitl --autopilot ardupilot``): ``wp load`` of the file as
  exported (line 0 is the planned home, ArduPilot's item 0, never flown),
  ``fence load`` of the field's inclusion polygon, WPNAV_RADIUS set to the
  plan's acceptance radius (Copter does not read NAV_WAYPOINT param2),
  ``mode guided``, ``arm throttle``, ``mode auto``, then ``long
  MISSION_START``: with no RC the throttle is never raised, and the command
  releases the take-off (ArduCopter's ``auto_armed``). The RETURN_TO_LAUNCH
  item is flown inside AUTO; the vehicle disarms when the mission ends on
  the ground.
- PX4: the file without its home line (PX4 flies item 0 as a way-point;
  MAVProxy uploads a file as it is), ``long MISSION_START`` (AUTO.MISSION)
  while disarmed, ``arm throttle``: PX4 takes off and flies it; the RTL item
  switches to AUTO.RTL, which lands and disarms (COM_DISARM_LAND).

The mission is cut after its first row (as tests/test_sitl_mission_e2e.py
does) and flown at 3x real time, 100 Hz sensor frames. Checks: every item
reported by MISSION_ITEM_REACHED (read on a telemetry link of its own, not
MAVProxy's console), in order; the flown path (the SITL's ground truth)
against the plan's way-points (``mission_flight.check_flown_path``); the
fence never breached; the vehicle landed near home and disarmed.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("MAVProxy.mavproxy")

from companion.cli import main   # noqa: E402
from mavcore.frames import geodetic2enu   # noqa: E402
from mavcore.mission import load_mission   # noqa: E402
from mission_flight import (DO_CHANGE_SPEED, NAV_WAYPOINT, Listener, MavProxy, check_flown_path,   # noqa: E402
                            cut_wpl, fence_wpl, record_flight, wait_until, wpl_items)
from sitl.api import SitlThread   # noqa: E402
from sitl.flightstack import FlightMode   # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MISSION = ROOT / "missions" / "flat-rectangle" / "mission.yaml"

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """(the WPL text, the .plan's fence polygon as (lat, lon) rows)."""
    out = tmp_path_factory.mktemp("mavproxy_mission")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["plan", str(MISSION), "-o", str(out / "plan.json"), "--waypoints", str(out / "p.waypoints"),
                     "--qgc", str(out / "p.plan")]) == 0
    fence = json.loads((out / "p.plan").read_text())["geoFence"]["polygons"][0]["polygon"]
    return (out / "p.waypoints").read_text(), fence


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_mavproxy_flies_the_exported_mission_in_auto(autopilot, exported, tmp_path, record_property):
    wpl, fence = exported
    ardupilot = autopilot == "ardupilot"
    text = cut_wpl(wpl, keep_home=ardupilot)
    (tmp_path / "m.waypoints").write_text(text)
    (tmp_path / "fence.waypoints").write_text(fence_wpl(fence))
    items = wpl_items(text)
    first = 1 if ardupilot else 0
    radius = max(it.params[1] for it in items if it.command == NAV_WAYPOINT)
    listener = Listener()
    try:
        with SitlThread(MISSION, speed=3.0, sensor_hz=100, autopilot=autopilot, outs=(listener.url,)) as sitl:
            srv = sitl.server
            mp = MavProxy(sitl.url, tmp_path, modules="param,wp,mode,cmdlong,arm,fence")
            try:
                mp.expect(r"Detected vehicle 1:1", timeout_s=30)
                mp.expect(r"Received \d+ parameters", timeout_s=30)
                mp.send("wp load m.waypoints")
                mp.expect(rf"Sent all {len(items)} waypoints", timeout_s=30)
                mp.expect(r"MISSION_ACK: TYPE_MISSION: ACCEPTED", timeout_s=30)
                mp.send("fence load fence.waypoints")
                assert wait_until(lambda: len(srv.missions.stored[1]) == len(fence), 30.0)
                if ardupilot:
                    mp.send(f"param set WPNAV_RADIUS {radius * 100.0:.1f}")   # cm
                    mp.send("param set DISARM_DELAY 0")   # no auto-disarm while a loaded machine is slow
                    assert wait_until(lambda: abs(srv.vehicle.params["NAV_ACC_RAD"] - radius) < 1e-4, 30.0)
                    mp.send("mode guided")
                    mp.expect(r"Mode GUIDED", timeout_s=30)
                    mp.send("arm throttle")
                    assert wait_until(lambda: srv.vehicle.stack.armed, 30.0)
                    mp.send("mode auto")
                    mp.expect(r"Mode AUTO", timeout_s=30)
                    assert srv.vehicle.sim.plant.landed                     # armed in AUTO, waiting for the release
                    mp.send("long MISSION_START")
                else:
                    # MAVProxy 1.8's ``mode MISSION`` sends PX4's mode tuple as one float and fails
                    # ("required argument is not a float"); MISSION_START is PX4's documented way in
                    mp.send("long MISSION_START")
                    mp.expect(r"Mode AUTO.MISSION", timeout_s=30)
                    mp.send("arm throttle")
                assert wait_until(lambda: srv.vehicle.stack.armed and not srv.vehicle.sim.plant.landed, 30.0)
                assert srv.vehicle.stack.mode is FlightMode.MISSION
                flown = record_flight(srv, lambda: not srv.vehicle.stack.armed, 90.0)
                assert wait_until(lambda: len(listener.reached) >= len(items) - first, 3.0), listener.reached
            finally:
                mp.close()
    finally:
        listener.close()

    assert not flown.breached
    assert listener.reached[:len(items) - first] == list(range(first, len(items)))
    if ardupilot:   # ArduCopter announces each way-point reached
        wp_seqs = [it.seq for it in items if it.command == NAV_WAYPOINT and it.seq >= first]
        assert [t for t in listener.texts if t.startswith("Reached command #")] == \
            [f"Reached command #{s}" for s in wp_seqs]
        assert "Disarmed (mission complete)" in listener.texts
    # landed where it took off (home), within the return's acceptance (RTL_ACCEPT_RADIUS_M / WPNAV_RADIUS)
    assert math.dist(flown.path[-1][:2], srv.vehicle.home_enu_m[:2]) <= max(radius, 0.5) + flown.nav_err_m
    home = load_mission(MISSION).home
    wps = [(it.seq, np.array(geodetic2enu(it.lat_deg, it.lon_deg, it.alt_m, home.lat, home.lon, home.alt_m)),
            radius if ardupilot else it.params[1])
           for it in items if it.command == NAV_WAYPOINT and it.seq >= first]
    v = max(it.params[1] for it in items if it.command == DO_CHANGE_SPEED)
    for name, value in check_flown_path(flown, wps, v).items():
        record_property(name, round(float(value), 4))
