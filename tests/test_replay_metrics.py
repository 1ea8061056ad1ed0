"""Flight metrics from a recording alone, on a synthetic flight worked by hand.

The flight (vehicle time, 50 Hz frames, ENU): on the ground at the origin
until 6 s, straight up to 2 m (6-8 s), 10 m east (8-18 s), 10 m north
(18-28 s), hover (28-30 s), straight down (30-32 s). Armed 5-35 s; modes
AUTO.LOITER (0-5 s), OFFBOARD (5-30 s), AUTO.LAND (30-40 s); landed state
TAKEOFF at 6 s, IN_AIR at 7 s, LANDING at 30 s, ON_GROUND at 33 s. So:
path 24 m (20 m horizontal), 27 s in the air, 30 s armed, 40 s of frames.
The companion's setpoints are the true position offset by (3, -4, 0) mm
(error 5 mm), with one 50 mm sample at 20 s inside the window and a 1 m
one at 10 s before it (the window starts 5 s after lift-off, 6 + 5 = 11 s).
"""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore import frames
from companion.link.tlog import TlogWriter
from companion.replay import replay_chunks
from companion.replay.metrics import REPLAN_PREFIX

HOME = (44.80, -0.60, 30.0)
DT_US = 20_000
T_END_US = 40_000_000


def path_enu(t: float) -> tuple:
    if t < 6.0:
        return (0.0, 0.0, 0.0)
    if t < 8.0:
        return (0.0, 0.0, t - 6.0)
    if t < 18.0:
        return (t - 8.0, 0.0, 2.0)
    if t < 28.0:
        return (10.0, t - 18.0, 2.0)
    if t < 30.0:
        return (10.0, 10.0, 2.0)
    if t < 32.0:
        return (10.0, 10.0, 2.0 - (t - 30.0))
    return (10.0, 10.0, 0.0)


def mode_at(t: float):
    if t < 5.0:
        return 4 << 16 | 3 << 24, False        # AUTO.LOITER
    if t < 30.0:
        return 6 << 16, True                   # OFFBOARD
    return 4 << 16 | 6 << 24, t < 35.0         # AUTO.LAND


def landed_at(t: float) -> int:
    if t < 6.0 or t >= 33.0:
        return mavlink.MAV_LANDED_STATE_ON_GROUND
    if t < 7.0:
        return mavlink.MAV_LANDED_STATE_TAKEOFF
    if t < 30.0:
        return mavlink.MAV_LANDED_STATE_IN_AIR
    return mavlink.MAV_LANDED_STATE_LANDING


def offset_at(t_ms: int) -> tuple:
    if t_ms == 20_000:
        return (0.030, -0.040, 0.0)            # 50 mm, inside the window
    if t_ms == 10_000:
        return (1.0, 0.0, 0.0)                 # before the window: not counted
    return (0.003, -0.004, 0.0)                # 5 mm


def write_flight(path, truth=True, lpos=True, gpos=False, companion=True, echo=False, jump_at_s=None):
    v = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    c = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    with TlogWriter(path) as w:
        def put(mav, msg, t_us):
            w.write(msg.pack(mav), 1_700_000_000_000_000 + t_us)

        if companion:
            put(c, c.statustext_encode(7, b"cs:{}", 0x4353, 0), 0)  # a setup chunk: not an event
        for k in range(T_END_US // DT_US + 1):
            t_us = k * DT_US
            if jump_at_s is not None and t_us >= jump_at_s * 1e6:
                t_us -= int(jump_at_s * 1e6)                            # the vehicle clock restarts
            t = k * DT_US * 1e-6
            ms = t_us // 1000
            e, n, u = path_enu(t)
            vel = tuple((a - b) / 0.02 for a, b in zip(path_enu(t + 0.02), path_enu(t)))
            if lpos:
                put(v, v.local_position_ned_encode(ms, n, e, -u, vel[1], vel[0], -vel[2]), t_us)
            if truth:
                put(v, v.odometry_encode(t_us, 1, 12, n, e, -u, [1, 0, 0, 0], 0, 0, 0, 0, 0, 0,
                                         [math.nan] + [0] * 20, [math.nan] + [0] * 20, 0, 0, 100), t_us)
            if gpos and k % 10 == 0:
                lat, lon, alt = frames.enu2geodetic(e, n, u, *HOME)
                put(v, v.global_position_int_encode(ms, round(lat * 1e7), round(lon * 1e7), round(alt * 1000),
                                                    round(u * 1000), 0, 0, 0, 0), t_us)
            if k % 5 == 0:   # rangefinders at 10 Hz: 3 m ahead, except two readings
                d = 300
                if abs(t - 9.0) < 1e-9:
                    d = 40             # before the window
                if abs(t - 25.0) < 1e-9:
                    d = 150            # the closest in the window
                put(v, v.distance_sensor_encode(ms, 10, 1000, d, 0, 0, mavlink.MAV_SENSOR_ROTATION_NONE, 255), t_us)
                put(v, v.distance_sensor_encode(ms, 10, 1000, 20, 0, 1, mavlink.MAV_SENSOR_ROTATION_PITCH_270, 255),
                    t_us)
            put(v, v.highres_imu_encode(t_us, 0, 0, -9.81, 0, 0, 0, 0.2, 0, 0.4, 0, 0, 0, 0, 0), t_us)
            if k % 50 == 0:
                custom, armed = mode_at(t)
                put(v, v.heartbeat_encode(2, 12, 1 | (128 if armed else 0), custom, 4), t_us)
                if k == 0:
                    put(v, v.home_position_encode(*(round(x * 1e7) for x in HOME[:2]), round(HOME[2] * 1000),
                                                  0, 0, 0, [1, 0, 0, 0], 0, 0, 0), t_us)
            if k % 10 == 0:
                put(v, v.extended_sys_state_encode(0, landed_at(t)), t_us)
            if 5.0 <= t < 30.0:
                d = offset_at(ms)
                p = (e + d[0], n + d[1], u + d[2])
                if companion:
                    put(c, c.set_position_target_local_ned_encode(ms, 1, 1, 1, 0, p[1], p[0], -p[2], 0, 0, 0,
                                                                  0, 0, 0, 0, 0), t_us)
                if echo:
                    put(v, v.position_target_local_ned_encode(ms, 1, 0, p[1], p[0], -p[2], 0, 0, 0, 0, 0, 0, 0, 0),
                        t_us)
            if companion and k in (1000, 1200):
                put(c, c.statustext_encode(4, (REPLAN_PREFIX + " around an obstacle").encode(), 0, 0), t_us)
    return path


def metrics(path, settle_s=5.0):
    return replay_chunks([path.read_bytes()], settle_s=settle_s).metrics


def window_samples():
    """Setpoint times in the window: from 5 s after lift-off (6 s) to the landing (30 s)."""
    return [k * DT_US // 1000 for k in range(T_END_US // DT_US + 1) if 11.0 <= k * DT_US * 1e-6 < 30.0]


def test_hand_worked_flight(tmp_path):
    m = metrics(write_flight(tmp_path / "f.tlog"))
    assert m.duration_s == pytest.approx(40.0, abs=1e-9)
    assert m.n_frames == T_END_US // DT_US + 1
    assert m.flight_time_s == pytest.approx(27.0, abs=1e-9) and m.flight_time_source == "landed_state"
    assert m.armed_time_s == pytest.approx(30.0, abs=1e-9)
    assert m.time_in_mode_s == pytest.approx({"AUTO.LOITER": 5.0, "OFFBOARD": 25.0, "AUTO.LAND": 10.0}, abs=1e-9)
    assert [(c.t_s, c.mode, c.armed) for c in m.mode_changes] == [
        (0.0, "AUTO.LOITER", False), (5.0, "OFFBOARD", True), (30.0, "AUTO.LAND", True), (35.0, "AUTO.LAND", False)]
    assert m.position_source == "sim_truth" and not m.estimated
    assert m.distance_m == pytest.approx(24.0, abs=1e-4)
    assert m.horizontal_distance_m == pytest.approx(20.0, abs=1e-4)
    tr = m.tracking
    n = len(window_samples())
    assert tr.n_samples == n
    assert tr.max_error_m == pytest.approx(0.050, abs=1e-5)
    assert tr.rms_error_m == pytest.approx(math.sqrt(((n - 1) * 0.005 ** 2 + 0.05 ** 2) / n), abs=1e-6)
    assert tr.reference_source == "companion setpoints" and tr.position_source == "sim_truth"
    assert m.min_clearance_m == pytest.approx(1.50)
    assert m.replanning_events == 2
    texts = [e.text for e in m.events if e.source == "companion"]
    assert texts == [REPLAN_PREFIX + " around an obstacle"] * 2        # the setup chunk is not an event
    assert m.clock_jumps == 0


def test_settle_moves_the_window(tmp_path):
    m = metrics(write_flight(tmp_path / "f.tlog"), settle_s=15.0)      # from 21 s: the 50 mm sample is out
    assert m.tracking.n_samples == len([t for t in window_samples() if t >= 21_000])
    assert m.tracking.max_error_m == pytest.approx(0.005, abs=1e-5)


def test_estimate_when_no_truth(tmp_path):
    m = metrics(write_flight(tmp_path / "f.tlog", truth=False))
    assert m.position_source == "estimate:LOCAL_POSITION_NED" and m.estimated
    assert m.tracking.estimated and m.tracking.position_source == "estimate:LOCAL_POSITION_NED"
    assert m.tracking.max_error_m == pytest.approx(0.050, abs=1e-5)
    assert m.distance_m == pytest.approx(24.0, abs=1e-4)


def test_foreign_log_global_position_and_the_vehicle_echo(tmp_path):
    """Vehicle messages only (no companion), no ODOMETRY, no LOCAL_POSITION_NED: GLOBAL_POSITION_INT
    at 5 Hz put in the local frame through HOME_POSITION; the reference is the vehicle's echo."""
    m = metrics(write_flight(tmp_path / "f.tlog", truth=False, lpos=False, gpos=True, companion=False, echo=True))
    assert m.n_companion_messages == 0 and m.replanning_events == 0
    assert m.position_source == "estimate:GLOBAL_POSITION_INT" and m.estimated
    # straight legs: the 1e-7 degree steps telescope along each leg (about 1 cm a leg at most)
    assert m.distance_m == pytest.approx(24.0, abs=0.05)
    assert m.horizontal_distance_m == pytest.approx(20.0, abs=0.05)
    tr = m.tracking
    assert tr.reference_source == "vehicle setpoint echo" and tr.estimated
    # every 10th frame has a fix; the others are carried forward with the fix's velocity (0 here) for
    # at most 0.18 s: along a 1 m/s leg that is up to 0.18 m behind
    assert tr.n_samples > 0 and tr.max_error_m < 0.25
    assert m.flight_time_s == pytest.approx(27.0, abs=1e-9)


def test_clock_jump_is_not_integrated(tmp_path):
    m = metrics(write_flight(tmp_path / "f.tlog", jump_at_s=20.0))
    assert m.clock_jumps == 1
    # the restart itself is left out: 40 s of frames less the one 20 ms step across the jump
    assert m.duration_s == pytest.approx(40.0 - 0.02, abs=1e-9)
