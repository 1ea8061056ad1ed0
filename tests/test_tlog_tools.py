"""The .tlog of a real flight read by the standard tools, and a foreign log.

One short ``companion fly`` (a subprocess) against the SITL (lockstep, real
UDP on loopback) while MAVProxy (unmodified, headless) listens on the SITL's
ground-station link and writes its own .tlog. Then:

- the companion's .tlog grows during the flight (flushed at least once a
  second), and pymavlink's ``mavlogdump.py``, ``mavflightmodes.py``,
  ``mavflighttime.py``, ``mavtogpx.py`` and ``mavutil.mavlink_connection``
  give the flight's duration, time in OFFBOARD, distance and position track,
  checked against the report and against the recording's own messages;
- MAVProxy's .tlog (vehicle messages only, no companion command) gives its
  metrics through ``companion replay`` and is refused, with exit 2 and one
  line, for a re-run (it has no setup record).

The tools print whole seconds (``time.localtime``), so their times are
checked to +-2 s (1 s of rounding at each end, the heartbeat's 1 Hz).
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.commands.demo import launch_pose
from companion.bundled import missions_dir
from companion.link.tlog import read_tlog

pytestmark = pytest.mark.slow

MISSION = missions_dir() / "flat-rectangle" / "mission.yaml"
CUT_S = 3.0
#: The corpus's small plan.json of this mission (saves planning in the test).
PLAN = Path(__file__).parent / "data" / "replay" / "plan-flat-rectangle.json"
BIN = Path(sys.executable).parent


def _tool(name: str, *args, cwd=None) -> str:
    r = subprocess.run([sys.executable, str(BIN / name), *map(str, args)], capture_output=True, text=True,
                       cwd=cwd, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stdout


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    """(tlog, report dict, sizes seen during the flight, MAVProxy's tlog)."""
    pytest.importorskip("MAVProxy.mavproxy")
    from sitl.api import SitlProcess, free_udp_port

    from companion.commands.fly import prepare
    from mavcore.mission import load_mission

    tmp = tmp_path_factory.mktemp("tools")
    mission = load_mission(MISSION)
    fp = prepare(mission, str(PLAN))
    pose = launch_pose(fp.cut(CUT_S, mission.trajectory).trajectory, fp.target_enu_m)
    gcs_port = free_udp_port()
    tlog, report, foreign = tmp / "flight.tlog", tmp / "report.json", tmp / "mavproxy.tlog"
    with SitlProcess(MISSION, lockstep=True, speed=1.0, start=pose,
                     outs=(f"udpout:127.0.0.1:{gcs_port}",)) as sitl:
        mp = subprocess.Popen([sys.executable, "-m", "MAVProxy.mavproxy", f"--master=udpin:127.0.0.1:{gcs_port}",
                               "--mav20", "--streamrate=-1", "--non-interactive",
                               "--default-modules=mode", f"--logfile={foreign}", f"--state-basedir={tmp}"],
                              stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              cwd=tmp, env=dict(os.environ, TERM="dumb"))
        try:
            deadline = time.monotonic() + 30
            while not (foreign.exists() and foreign.stat().st_size > 0) and time.monotonic() < deadline:
                time.sleep(0.1)   # MAVProxy is up and logging
            fly = subprocess.Popen([sys.executable, "-m", "companion.cli", "fly", str(MISSION), "--connect", sitl.url,
                                    "--tlog", str(tlog), "--report", str(report), "--cut", str(CUT_S), "--quiet",
                                    "--plan", str(PLAN)],
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            sizes = []
            while fly.poll() is None:
                sizes.append((time.monotonic(), tlog.stat().st_size if tlog.exists() else 0))
                time.sleep(0.1)
            out, err = fly.communicate()
            assert fly.returncode == 0, err
            time.sleep(0.5)   # MAVProxy writes what it still has
        finally:
            mp.terminate()
            try:
                mp.wait(10)
            except subprocess.TimeoutExpired:
                mp.kill()
                mp.wait(5)
    return tlog, json.loads(report.read_text()), sizes, foreign


def _landed_state_gap_s(recs) -> float:
    """The largest vehicle-clock interval between consecutive EXTENDED_SYS_STATE of a log while the
    vehicle was armed (each stamped by the latest ``time_boot_ms`` before it)."""
    t = None
    seen = []
    armed = False
    for r in recs:
        m = r.msg
        if hasattr(m, "time_boot_ms"):
            t = m.time_boot_ms * 1e-3
        if m.get_type() == "HEARTBEAT" and m.autopilot != mavlink.MAV_AUTOPILOT_INVALID:   # the vehicle's
            armed = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        if m.get_type() == "EXTENDED_SYS_STATE" and t is not None and (armed or seen):
            seen.append(t)
    assert len(seen) >= 2
    return float(np.max(np.diff(seen)))


def _vehicle_time_s(recs, mtype, field="time_usec", scale=1e-6):
    return [getattr(r.msg, field) * scale for r in recs if r.msg.get_type() == mtype]


def test_tlog_grows_during_the_flight(flight):
    tlog, rep, sizes, _ = flight
    final = tlog.stat().st_size
    growth = [t for (t, s), (_, s0) in zip(sizes[1:], sizes[:-1]) if s > s0]
    # the file grew many times while the flight ran (the process was still flying)
    assert len(growth) >= 5, "the .tlog did not grow during the flight"
    assert sizes[-1][1] < final or len(growth) >= 5
    # flushed at least once a second: from the first bytes on, no stretch of more than ~1 s
    # without growth (plus the 0.1 s poll and scheduling slack on a loaded machine)
    assert max(np.diff(growth)) < 2.0


def test_mavutil_reads_every_record_with_vehicle_clock_stamps(flight):
    from pymavlink import mavutil

    tlog, rep, _, _ = flight
    ours = list(read_tlog(tlog, skip_bad=False))
    log = mavutil.mavlink_connection(str(tlog), dialect="common")
    theirs = []
    while (m := log.recv_msg()) is not None:
        if m.get_type() != "BAD_DATA":
            theirs.append((m.get_type(), round(m._timestamp * 1e6)))
    assert [(r.msg.get_type(), r.time_usec) for r in ours] == theirs
    # stamps follow the vehicle clock: HIGHRES_IMU records are stamped exactly their time_usec apart
    imu = [(r.time_usec, r.msg.time_usec) for r in ours if r.msg.get_type() == "HIGHRES_IMU"]
    assert len(imu) == rep["n_frames"]
    d_stamp = np.diff([a for a, _ in imu])
    d_vehicle = np.diff([b for _, b in imu])
    assert np.array_equal(d_stamp, d_vehicle)
    assert (imu[-1][0] - imu[0][0]) * 1e-6 == pytest.approx(rep["sim_time_s"], abs=1e-6)


def test_mavlogdump_duration_is_the_flights(flight):
    tlog, rep, _, _ = flight
    out = _tool("mavlogdump.py", "--types", "HIGHRES_IMU", "--format", "json", tlog)
    rows = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    assert len(rows) == rep["n_frames"]
    t = [r["meta"]["timestamp"] for r in rows]
    assert t[-1] - t[0] == pytest.approx(rep["sim_time_s"], abs=1e-3)
    # and each record's stamp advances with the message's own vehicle time
    assert (rows[-1]["data"]["time_usec"] - rows[0]["data"]["time_usec"]) * 1e-6 == pytest.approx(t[-1] - t[0],
                                                                                                     abs=1e-3)


def test_mavflightmodes_time_in_offboard(flight):
    tlog, rep, _, _ = flight
    out = _tool("mavflightmodes.py", tlog)
    m = re.search(r"^OFFBOARD\s+(\d+):(\d\d):(\d\d)", out, re.M)
    assert m, out
    tool_s = int(m.group(1)) * 3600 + int(m.group(2)) * 60 + int(m.group(3))
    # independently: vehicle time from the accepted DO_SET_MODE(OFFBOARD) to the accepted NAV_LAND
    recs = list(read_tlog(tlog))
    t, t_off, t_land = None, None, None
    for r in recs:
        msg = r.msg
        if msg.get_type() == "HIGHRES_IMU":
            t = msg.time_usec * 1e-6
        elif msg.get_type() == "COMMAND_ACK" and msg.result == 0:
            if msg.command == 176 and t_off is None:
                t_off = t
            elif msg.command == 21:
                t_land = t
    assert t_off is not None and t_land is not None
    assert abs(tool_s - (t_land - t_off)) <= 2.0, (tool_s, t_land - t_off)


def test_mavflighttime_distance_and_time_moving(flight):
    """``--groundspeed 0.5``: the tool counts "in air" while the GPS ground
    speed exceeds the threshold; its default 3 m/s is above this mission's
    1 m/s cruise (it would report 0). Half the cruise speed separates the
    rows flown from hovering, climbing and landing (horizontal speed ~0)."""
    tlog, rep, _, _ = flight
    out = _tool("mavflighttime.py", "--groundspeed", "0.5", tlog)
    recs = list(read_tlog(tlog))
    gps = [r.msg for r in recs if r.msg.get_type() == "GPS_RAW_INT"]
    # the recording's own answer: vehicle time with GPS speed above 0.5 m/s
    t = np.array([g.time_usec * 1e-6 for g in gps])
    moving = np.array([g.vel * 0.01 > 0.5 for g in gps])
    expected_s = float(np.sum(np.diff(t)[moving[:-1]]))
    m = re.search(r"Total time in air: (\d+):(\d\d)", out)
    tool_s = int(m.group(1)) * 60 + int(m.group(2))
    assert expected_s > 1.0
    assert abs(tool_s - expected_s) <= 2.0, (tool_s, expected_s)
    # distance: the tool's sum of great-circle steps between the recorded fixes, computed here
    # independently (haversine), to the tool's printed 0.1 m
    dist = float(re.search(r"Total distance travelled: ([0-9.]+) meters", out).group(1))
    lat = np.radians([g.lat * 1e-7 for g in gps])
    lon = np.radians([g.lon * 1e-7 for g in gps])
    h = np.sin(np.diff(lat) / 2) ** 2 + np.cos(lat[:-1]) * np.cos(lat[1:]) * np.sin(np.diff(lon) / 2) ** 2
    ours = float(np.sum(2 * 6371e3 * np.arcsin(np.sqrt(h))))
    assert ours > 1.0
    assert abs(dist - ours) <= 0.051 + 1e-3 * ours, (dist, ours)
    # and the fixes are the true positions (ODOMETRY of the same frame) to the 1e-7 degree
    # resolution: at most half a step north and east (~5.6 mm, 5.6 mm x cos(lat))
    from mavcore.frames import geodetic2enu
    from mavcore.mission import load_mission

    home = load_mission(MISSION).home
    odo = {r.msg.time_usec: (r.msg.y, r.msg.x) for r in recs if r.msg.get_type() == "ODOMETRY"}   # ENU
    half_north = 0.5e-7 * math.pi / 180 * 6371e3
    n = 0
    for g in gps:
        if g.time_usec not in odo:
            continue
        e, nn, _ = geodetic2enu(g.lat * 1e-7, g.lon * 1e-7, home.alt_m, home.lat, home.lon, home.alt_m)
        te, tn = odo[g.time_usec]
        assert abs(nn - tn) <= half_north * 1.01 + 1e-4, (nn, tn)
        assert abs(e - te) <= half_north * math.cos(lat[0]) * 1.01 + 1e-4, (e, te)
        n += 1
    assert n >= len(gps) - 2
    # so the tool's distance is the true path's (at the fixes) to within one resolution step a fix
    truth = float(np.sum(np.hypot(*np.diff(np.array([odo[g.time_usec] for g in gps if g.time_usec in odo]),
                                                 axis=0).T)))
    assert abs(dist - truth) <= 0.051 + n * 2 * half_north, (dist, truth)


def test_mavtogpx_one_point_per_position_message(flight, tmp_path):
    tlog, rep, _, _ = flight
    local = tmp_path / "f.tlog"
    local.write_bytes(tlog.read_bytes())
    out = _tool("mavtogpx.py", local, cwd=tmp_path)
    n = int(re.search(r"with (\d+) points", out).group(1))
    gpx = (tmp_path / "f.tlog.gpx").read_text()
    assert gpx.count("<trkpt") == n
    recs = list(read_tlog(tlog))
    n_gps = sum(r.msg.get_type() == "GPS_RAW_INT" for r in recs)
    n_gpos = sum(r.msg.get_type() == "GLOBAL_POSITION_INT" for r in recs)
    # the tool keeps GPS_RAW_INT with a fix and GLOBAL_POSITION_INT once a fix was seen
    types = [r.msg.get_type() for r in recs if r.msg.get_type() in ("GPS_RAW_INT", "GLOBAL_POSITION_INT")]
    before_fix = types.index("GPS_RAW_INT")
    assert all(r.msg.fix_type >= 3 for r in recs if r.msg.get_type() == "GPS_RAW_INT")
    assert n == n_gps + n_gpos - before_fix
    # both streams at 5 Hz of vehicle time (the runner keeps them for log tools)
    for k in (n_gps, n_gpos):
        assert abs(k - 5.0 * rep["sim_time_s"]) <= 3, (k, rep["sim_time_s"])


def test_foreign_mavproxy_log_gives_metrics(flight, tmp_path):
    from companion.cli import main

    tlog, rep, _, foreign = flight
    assert foreign.stat().st_size > 0
    recs = list(read_tlog(foreign))
    assert not any(r.msg.get_srcComponent() == 191 for r in recs), "MAVProxy's link carries no companion command"
    out = tmp_path / "replay.json"
    assert main(["replay", str(foreign), "--report", str(out)]) == 0
    doc = json.loads(out.read_text())
    m = doc["metrics"]
    assert doc["setup"] is None and doc["comparison"] is None
    assert m["n_companion_messages"] == 0
    # the vehicle's own telemetry on the ground station's link tells the same flight
    modes = [c["mode"] for c in m["mode_changes"]]
    assert "OFFBOARD" in modes and "AUTO.LAND" in modes
    assert m["duration_s"] == pytest.approx(rep["sim_time_s"], abs=0.5)
    ours = json.loads(_replay_metrics(tlog, tmp_path))
    # Each log sees lift-off and touch-down at its next EXTENDED_SYS_STATE, so each flight time is late by
    # less than that message's interval at both ends: the two differ by less than the sum of the largest
    # intervals on the two links (5 Hz each: 0.4 s; more where the ground station's UDP link lost one).
    bound = _landed_state_gap_s(recs) + _landed_state_gap_s(list(read_tlog(tlog)))
    assert bound < 2.0, "the landed state reached the logs at least every second"
    assert abs(m["flight_time_s"] - ours["flight_time_s"]) <= bound + 1e-9
    assert m["distance_m"] == pytest.approx(ours["distance_m"], rel=0.05)
    # no companion setpoints on that link: the reference is the vehicle's echo of the setpoint
    assert m["tracking"]["reference_source"] in ("vehicle setpoint echo", None)
    # without ODOMETRY the figures say they are the vehicle's estimate
    stripped = tmp_path / "no-odometry.tlog"
    from companion.link.tlog_scan import TlogScanner

    sc = TlogScanner()
    kept = [r for r in sc.feed(foreign.read_bytes()) + sc.close() if r.msgid != 331]
    stripped.write_bytes(b"".join(r.stamp_us.to_bytes(8, "big") + r.packet for r in kept))
    out2 = tmp_path / "replay2.json"
    assert main(["replay", str(stripped), "--report", str(out2)]) == 0
    m2 = json.loads(out2.read_text())["metrics"]
    assert m2["position_source"].startswith("estimate:") and m2["estimated"] is True


def test_foreign_log_cannot_be_rerun(flight, tmp_path, capsys):
    from companion.cli import main

    _, _, _, foreign = flight
    out = tmp_path / "r.json"
    rc = main(["replay", str(foreign), "--mission", str(MISSION), "--report", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "no companion setup record" in err[0]
    assert not out.exists()


def _replay_metrics(tlog, tmp_path) -> str:
    from companion.cli import main

    out = tmp_path / "own.json"
    assert main(["replay", str(tlog), "--report", str(out)]) == 0
    return json.dumps(json.loads(out.read_text())["metrics"])
