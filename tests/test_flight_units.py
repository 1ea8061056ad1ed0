"""The flight loop's pure pieces: reference window, bounded log, error
statistics, take-off heading, outcome monitor, link health, flown coverage."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.bundled import missions_dir
from companion.control.observer import heading_from_accel_mag
from companion.flight.coverage import PathCoverage
from companion.flight.health import LinkHealth
from companion.flight.log import ErrorStats, FlightLog
from companion.flight.monitor import FlightMonitor, MonitorConfig
from companion.trajectory.reference import TrajectoryWindow
from mavcore.codec import px4_custom_mode


@pytest.fixture(scope="module")
def plan():
    from mavcore.mission import load_mission
    from companion.planner import plan_mission

    return plan_mission(load_mission(missions_dir() / "flat-rectangle" / "mission.yaml"))


def test_trajectory_window_equals_direct_sampling_and_holds_one_window(plan):
    traj = plan.trajectory
    dt = 0.004
    w = TrajectoryWindow(traj, dt, plan.target_enu_m, window_frames=100)
    n = w.n_frames
    assert n == int(math.floor(traj.duration_s / dt + 1e-9)) + 2
    ks = [0, 1, 99, 100, 101, 5000, n // 2, 17, n - 1, n + 50, -3]   # forward, back, past both ends
    for k in ks:
        kc = min(max(k, 0), n - 1)
        t = min(traj.t0 + kc * dt, traj.tf)
        ref = traj.sample(np.array([t]))
        s = w.sample(k)
        np.testing.assert_allclose(s.p, ref.p[0], atol=1e-12)
        np.testing.assert_allclose(s.v, ref.v[0], atol=1e-12)
        np.testing.assert_allclose(s.snap, ref.snap[0], atol=1e-9)
        np.testing.assert_allclose(s.s, ref.pointing[0], atol=1e-12)
        assert len(w._buf) <= 100         # never more than one window in memory


def test_flight_log_is_bounded_and_evenly_decimated():
    log = FlightLog(max_rows=64)
    ncol = len(FlightLog.COLUMNS)
    for k in range(10_000):
        if log.wants():
            log.append((float(k),), (0.0,) * (ncol - 1))
        else:
            log.n_offered += 1
    a = log.array()
    assert 32 <= a.shape[0] <= 64
    t = a[:, 0]
    # evenly spaced: every kept row is a multiple of the stride, none missing in between
    assert np.all(t % log.stride == 0)
    np.testing.assert_array_equal(np.diff(t), log.stride)
    assert t[0] == 0.0


def test_error_stats_match_numpy_after_settling():
    rng = np.random.default_rng(1)
    t = np.arange(0, 50, 0.004)
    e = rng.random(t.size)
    st = ErrorStats(settle_s=5.0)
    st.start(10.0)
    for ti, ei in zip(t, e):
        st.add(ti, ei)
    sel = t >= 15.0
    assert st.n == np.count_nonzero(sel)
    assert st.max_m == pytest.approx(e[sel].max())
    assert st.rms_m == pytest.approx(math.sqrt(np.mean(e[sel] ** 2)))


def _R(yaw, pitch, roll):
    """Body FLU -> world ENU, ZYX (yaw about up, then pitch, then roll)."""
    cz, sz = math.cos(yaw), math.sin(yaw)
    cy, sy = math.cos(pitch), math.sin(pitch)
    cx, sx = math.cos(roll), math.sin(roll)
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    return Rz @ Ry @ Rx


@pytest.mark.parametrize("yaw_deg", [0, 30, 90, 179, -120])
@pytest.mark.parametrize("tilt", [(0, 0), (0.2, -0.1), (-0.35, 0.3)])
def test_takeoff_heading_from_accel_and_mag_is_the_heading_of_body_x(yaw_deg, tilt):
    m_w = np.array([0.05, 0.21, -0.42])      # a field with some declination (east component)
    R = _R(math.radians(yaw_deg), *tilt)
    acc = R.T @ np.array([0, 0, 9.81])       # at rest: the specific force is up
    mag = R.T @ m_w
    x_w = R @ np.array([1.0, 0, 0])
    expected = math.atan2(x_w[1], x_w[0])
    got = heading_from_accel_mag(tuple(acc), tuple(mag), tuple(m_w))
    assert math.isclose(math.remainder(got - expected, 2 * math.pi), 0.0, abs_tol=1e-9)


OFFBOARD = px4_custom_mode(6)
LAND = px4_custom_mode(4, 6)


def test_monitor_flags_disarm_mode_change_crash_and_keeps_the_first():
    m = FlightMonitor(MonitorConfig(max_tracking_error_m=0.1, settle_s=5.0))
    assert m.on_heartbeat(0.0, False, 0, 3) is None          # not watching before arming
    m.armed(10.0, OFFBOARD)
    assert m.on_heartbeat(11.0, True, OFFBOARD, 4) is None
    v = m.on_heartbeat(12.0, True, LAND, 4)
    assert v.kind == "mode_change" and v.action == "release" and "AUTO.LAND" in v.detail
    assert m.on_heartbeat(13.0, False, LAND, 4) is None     # later violations do not replace the first
    c = m.on_statustext(14.0, 2, "CRASH: cylinder #1 at E 1 N 2 U 3")
    assert c.kind == "crash" and m.crash["t_s"] == 14.0      # but a crash is always reported
    assert m.first.kind == "mode_change" and not m.ok


def test_monitor_tracking_bound_applies_after_settling_and_not_after_landing():
    m = FlightMonitor(MonitorConfig(max_tracking_error_m=0.1, settle_s=5.0))
    m.armed(0.0, OFFBOARD)
    assert m.on_tracking(12.0, 10.0, 0.5, "sim_truth") is None      # within settle
    assert m.on_tracking(16.0, 10.0, 0.05, "sim_truth") is None
    v = m.on_tracking(16.0, 10.0, math.nan, "estimate")              # NaN is not "within"
    assert v.kind == "tracking" and v.action == "land"
    m2 = FlightMonitor(MonitorConfig(max_tracking_error_m=0.1))
    m2.armed(0.0, OFFBOARD)
    m2.landing(20.0)
    assert m2.on_tracking(30.0, 10.0, 5.0, "sim_truth") is None
    assert m2.on_heartbeat(31.0, False, LAND, 3) is None            # disarming after our LAND is expected


def test_monitor_on_ground_in_flight_after_the_climb_grace():
    m = FlightMonitor(MonitorConfig(climb_grace_s=5.0))
    m.armed(100.0, OFFBOARD)
    assert m.on_landed_state(102.0, 1) is None
    assert m.on_landed_state(106.0, 1).kind == "on_ground"


def test_link_health_silent_in_lockstep_and_on_a_clean_link_flags_jitter_and_loss():
    dt = 0.004
    rng = np.random.default_rng(0)
    # lockstep: the vehicle clock runs 20x faster than the wall clock
    h = LinkHealth(dt)
    assert all(h.observe(k * dt / 20 + 0.03 * rng.random(), k * dt) is None for k in range(2000))
    # real time, constant 50 ms delay, 1 ms jitter: healthy
    h = LinkHealth(dt)
    assert all(h.observe(k * dt + 0.05 + 0.001 * rng.random(), k * dt) is None for k in range(2000))
    # real time, 0-30 ms uniform jitter: the 95th percentile is ~28.5 ms > 12 ms
    h = LinkHealth(dt)
    verdicts = [h.observe(k * dt + 0.03 * rng.random(), k * dt) for k in range(2000)]
    assert any(v is not None and "jitter" in v for v in verdicts)
    # real time, half the frames lost
    h = LinkHealth(dt)
    verdicts = [h.observe(k * dt, k * dt) for k in range(0, 4000, 2)]
    assert any(v is not None and "lost" in v for v in verdicts)


def test_path_coverage_counts_what_was_passed_within_the_radius():
    path = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 2.5], [0.0, 2.5]])
    cov = PathCoverage(path, spacing_m=0.5, radius_m=0.5)
    n = len(cov.points)
    assert n == 1 + 20 + 5 + 20
    for x in np.arange(0.0, 10.01, 0.02):       # fly the first leg only, 0.3 m off to the side
        cov.visit(x, 0.3)
    # the first leg's 21 samples, plus the second leg's samples within 0.5 m of (10, 0.3)
    second = sum(1 for p in cov.points if p[0] == 10.0 and 0 < p[1] and math.hypot(0, p[1] - 0.3) <= 0.5)
    assert cov.fraction() == pytest.approx((21 + second) / n)
    assert cov.fraction() < 0.6


@pytest.mark.parametrize("n", [0, 1, 46, 47, 48, 94, 400])
def test_setup_record_round_trips_through_statustext_chunks(n):
    from pymavlink.dialects.v20 import common as mavlink

    from companion.flight.setup_record import SETUP_TEXT_ID, parse_setup, setup_chunks

    setup = {"mission": "x" * n, "cut_s": 8.0, "runner": {"attach": "refuse"}}
    enc = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    dec = mavlink.MAVLink(None)
    texts = []
    for text, seq in setup_chunks(setup):
        buf = enc.statustext_encode(7, text, SETUP_TEXT_ID, seq).pack(enc)   # over the wire and back
        m = dec.decode(bytearray(buf))
        texts.append((m.text, m.id, m.chunk_seq))
    assert parse_setup(reversed(texts)) == setup       # order of arrival does not matter
    with pytest.raises(ValueError):
        parse_setup(texts[1:] if len(texts) > 1 else [(texts[0][0] + "x" * 60, SETUP_TEXT_ID, 0)])


def test_link_health_trusts_a_lockstep_vehicle_until_its_frames_skip():
    dt = 0.004
    rng = np.random.default_rng(2)
    # lockstep under load: the vehicle clock about as fast as the wall clock, bursts of delay
    h = LinkHealth(dt, lockstep=True)
    assert all(h.observe(k * dt + 0.03 * rng.random(), k * dt) is None for k in range(2000))
    # the same vehicle once it has fallen back to free running (frames lost) is judged
    h = LinkHealth(dt, lockstep=True)
    verdicts = [h.observe(k * dt + 0.03 * rng.random(), k * dt) for k in range(0, 4000, 2)]
    assert any(v is not None for v in verdicts)


def test_takeoff_segments_climb_above_the_canopy_before_crossing_the_field():
    from companion.flight.core import takeoff_segments

    start, first = (10.0, 3.0, 0.2), (22.45, 8.75, 1.5)
    segs = takeoff_segments(start, first, 4.0, 1.0, 3.0)
    # up, across at the transit height, down: continuous, rest to rest
    assert [s[0] for s in segs[1:]] == [s[1] for s in segs[:-1]]
    assert segs[0][0] == start and segs[-1][1] == first
    (a0, a1, _), (b0, b1, _), (c0, c1, _) = segs
    assert a1 == (10.0, 3.0, 4.0) and b1 == (22.45, 8.75, 4.0) and c1 == first
    # no horizontal motion below the transit height
    assert a0[:2] == a1[:2] and c0[:2] == c1[:2]
    # launched under the first point: one climb, whatever the floor
    assert takeoff_segments((22.45, 8.75, 0.2), first, 4.0, 1.0, 3.0) == \
        [((22.45, 8.75, 0.2), first, pytest.approx(3.0))]
    # no floor (a field without rows): level at the first point's height, no descent
    segs = takeoff_segments(start, first, None, 1.0, 3.0)
    assert len(segs) == 2 and segs[1][1] == first
