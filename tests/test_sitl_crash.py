"""Crashes and mounted rangefinders as a ground station sees them: the SITL
over real UDP sockets (pymavlink's mavutil client of test_sitl_mavlink).

The field is flat-rectangle's; the vehicle starts in the third corridor at
(5.0, 3.75) heading east, a post (r = 0.25 m, 3 m) stands 2 m ahead."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from sitl.api import SitlThread
from test_sitl_mavlink import POS_ONLY, Client

ROOT = Path(__file__).resolve().parents[1]
MAPS = ROOT / "missions" / "flat-rectangle"
C15, S15 = math.cos(math.radians(15.0)), math.sin(math.radians(15.0))
R_VEH = 0.442

MISSION = f"""name: crash-test
map: {MAPS / 'map.yaml'}
dem: {MAPS / 'dem.asc'}
home: {{lat: 44.8, lon: -0.6, alt_m: 30.0}}
sim:
  start_enu_m: [5.0, 3.75]
  obstacles: [{{type: cylinder, x: 7.0, y: 3.75, radius: 0.25, height: 3.0}}]
  collision: {{vehicle_radius_m: {R_VEH}}}
  noise: {{vector_variance: 0.0, gyro_variance: 0.0, range_std_m: 0.0}}
  rangefinders:
    - {{id: 0, orientation: 0, position_flu_m: [0.2, 0.0, 0.5], hfov_deg: 0.0, vfov_deg: 0.0, max_m: 10.0, rate_hz: 25.0}}
    - {{id: 5, orientation: 100, rotation_flu_deg: [0.0, 30.0, 0.0], position_flu_m: [0.2, 0.0, 0.1],
        hfov_deg: 6.0, vfov_deg: 0.0, min_m: 0.1, max_m: 10.0, rate_hz: 25.0}}
    - {{id: 7, orientation: 24, hfov_deg: 0.0, vfov_deg: 0.0, max_m: 5.0, rate_hz: 25.0}}
"""


@pytest.fixture()
def gcs(tmp_path):
    path = tmp_path / "mission.yaml"
    path.write_text(MISSION)
    with SitlThread(path, speed=4.0) as s:
        c = Client(s.url)
        c.hello()
        yield c
        c.close()


def _ranges(gcs, ids, timeout=3.0, cond=None):
    got = {}
    gcs.recv("DISTANCE_SENSOR", timeout,
             lambda m: (m.id in ids and (cond is None or cond(m)) and got.setdefault(m.id, m) is None) or
             set(got) == set(ids))
    return got


def test_distance_sensor_fields_of_mounted_sensors(gcs):
    got = _ranges(gcs, {0, 5, 7})
    fwd, diag, up = got[0], got[5], got[7]
    # the nose sensor 0.5 m up looks east along the corridor at the post: 7.0 - 0.25 - (5.0 + 0.2)
    assert (fwd.orientation, fwd.current_distance, fwd.signal_quality) == (0, 155, 100)
    assert list(fwd.quaternion) == [1.0, 0.0, 0.0, 0.0]
    # forward and 30 deg down from 0.1 m above the ground: 0.1 / sin 30 = 0.2 m
    assert (diag.orientation, diag.current_distance, diag.min_distance, diag.max_distance) == (100, 20, 10, 1000)
    assert diag.quaternion == pytest.approx([C15, 0.0, -S15, 0.0], abs=1e-7)   # FRD: pitch -30
    assert diag.horizontal_fov == pytest.approx(math.radians(6.0)) and diag.vertical_fov == 0.0
    # looking up at the sky: no return, max + 1 cm, invalid signal
    assert (up.orientation, up.current_distance, up.signal_quality) == (24, 501, 1)
    assert fwd.covariance == 0
    # 3 cm of range noise: 9 cm^2
    assert gcs.set_param("SIM_RNG_STD", 0.03).param_value == pytest.approx(0.03)
    assert _ranges(gcs, {0}, cond=lambda m: m.covariance == 9)


def test_crash_into_the_post(gcs):
    p0 = gcs.recv("LOCAL_POSITION_NED", 3.0)
    target = [p0.x, p0.y, p0.z - 1.5]                          # NED: 1.5 m up

    def sp():
        gcs.mav.set_position_target_local_ned_send(0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, POS_ONLY,
                                                   *target, 0, 0, 0, 0, 0, 0, 0, 0)

    gcs.pump(0.3, sp)
    assert gcs.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 6, 0) == mavlink.MAV_RESULT_ACCEPTED
    assert gcs.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    gcs.pump(1.5, sp)                                           # 6 s of vehicle time: up at 1.5 m
    assert not any(t.startswith("CRASH") for t in gcs.texts)   # the take-off was not a crash
    target[1] = 9.0                                             # NED y = east: through the post
    crash = None

    def sp_until_crash():
        sp()

    end = 0
    while crash is None and end < 100:
        gcs.pump(0.1, sp_until_crash)
        crash = next((t for t in gcs.texts if t.startswith("CRASH")), None)
        end += 1
    assert crash is not None, gcs.texts
    # the centre stops r + 0.25 m west of the post's axis, at 1.5 m
    assert crash.startswith(f"CRASH: cylinder #1 at E{7.0 - 0.25 - R_VEH:.2f} N3.75 U1.5"), crash
    hb = gcs.recv("HEARTBEAT", 3.0, lambda m: m.system_status == mavlink.MAV_STATE_EMERGENCY)
    assert hb is not None
    # it falls, comes to rest on the ground and is disarmed; the status stays EMERGENCY
    hb = gcs.recv("HEARTBEAT", 5.0, lambda m: not m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
    assert hb is not None and hb.system_status == mavlink.MAV_STATE_EMERGENCY
    assert "Disarmed (crashed)" in gcs.texts
    assert gcs.recv("EXTENDED_SYS_STATE", 3.0).landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND
    lp = gcs.recv("LOCAL_POSITION_NED", 3.0)
    assert lp.y == pytest.approx(7.0 - 0.25 - R_VEH, abs=0.01) and abs(lp.z - p0.z) < 1e-6
    # it stays there: no arming, no take-off, no landing
    assert gcs.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_DENIED
    assert gcs.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan) == \
        mavlink.MAV_RESULT_DENIED
    assert gcs.command(mavlink.MAV_CMD_NAV_LAND) == mavlink.MAV_RESULT_DENIED
    assert "Arming denied: crashed" in gcs.texts
    sev = [m for m in [gcs.latest.get("STATUSTEXT")] if m is not None]
    assert sev and sev[0].severity == mavlink.MAV_SEVERITY_CRITICAL
    assert mavutil.mode_string_v10(gcs.recv("HEARTBEAT", 3.0)) == "OFFBOARD"
