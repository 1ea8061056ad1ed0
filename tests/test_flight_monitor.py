"""The flight monitor's failsafe decisions at their thresholds (issue 19: each must fail when broken).

Every threshold is taken from its documented value (``MonitorConfig``'s
docstring and defaults, ``RunnerConfig``'s defaults, the MAVLink enums) and
probed just inside and just outside, so moving it (x100, /100, < for <=) or
dropping the check makes a test fail. ``benchmarks/mutation.py`` checks that.
"""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.flight.config import RunnerConfig
from companion.flight.monitor import FlightMonitor, MonitorConfig, Violation, px4_mode_name


def mode(main: int, sub: int = 0) -> int:
    """PX4 custom_mode, by hand: main mode in bits 16-23, sub mode in bits 24-31."""
    return main * 65536 + sub * 16777216


OFFBOARD = mode(6)
POSCTL = mode(3)
EPS = 1e-6


def armed_monitor(cfg: MonitorConfig = MonitorConfig(), t_arm: float = 100.0) -> FlightMonitor:
    m = FlightMonitor(cfg)
    m.armed(t_arm, OFFBOARD)
    return m


# --------------------------------------------------------------------------- names in reports
@pytest.mark.parametrize("main,sub,name", [
    (1, 0, "MANUAL"), (2, 0, "ALTCTL"), (3, 0, "POSCTL"), (5, 0, "ACRO"), (6, 0, "OFFBOARD"),
    (7, 0, "STABILIZED"), (8, 0, "RATTITUDE"), (9, 0, "MODE9"), (0, 0, "MODE0"),
    (4, 1, "AUTO.READY"), (4, 2, "AUTO.TAKEOFF"), (4, 3, "AUTO.LOITER"), (4, 4, "AUTO.MISSION"),
    (4, 5, "AUTO.RTL"), (4, 6, "AUTO.LAND"), (4, 7, "AUTO.7"), (4, 8, "AUTO.FOLLOW_TARGET"),
    (4, 9, "AUTO.PRECLAND"), (4, 10, "AUTO.10"),
    (6, 3, "OFFBOARD"),          # a sub mode means nothing outside AUTO
])
def test_px4_mode_names_follow_px4s_numbering(main, sub, name):
    """PX4's px4_custom_mode.h: main modes 1..8, AUTO sub modes 1..6, 8, 9."""
    assert px4_mode_name(mode(main, sub)) == name


def test_mavlink_enum_values_are_the_standards():
    """The monitor's local copies of MAV_STATE / MAV_SEVERITY / MAV_LANDED_STATE values."""
    from companion.flight import monitor
    assert monitor.MAV_STATE_CRITICAL == mavlink.MAV_STATE_CRITICAL == 5
    assert monitor.MAV_STATE_EMERGENCY == mavlink.MAV_STATE_EMERGENCY == 6
    assert monitor.MAV_SEVERITY_CRITICAL == mavlink.MAV_SEVERITY_CRITICAL == 2
    assert monitor.MAV_LANDED_STATE_ON_GROUND == mavlink.MAV_LANDED_STATE_ON_GROUND == 1


# --------------------------------------------------------------------------- configuration
def test_defaults_are_the_documented_ones_and_agree_with_the_runner_config():
    c = MonitorConfig()
    assert (c.max_tracking_error_m, c.settle_s, c.climb_grace_s, c.max_nav_age_s) == (0.5, 5.0, 5.0, 1.0)
    f = RunnerConfig()
    assert f.max_nav_age_s == c.max_nav_age_s and f.max_tracking_error_m == c.max_tracking_error_m


@pytest.mark.parametrize("name", ["max_tracking_error_m", "climb_grace_s", "max_nav_age_s"])
@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_positive_bounds_reject_zero_negative_and_non_finite(name, bad):
    with pytest.raises(ValueError, match=name):
        MonitorConfig(**{name: bad})
    MonitorConfig(**{name: 1e-3})      # any small positive value is fine


@pytest.mark.parametrize("bad", [-1e-3, math.nan, math.inf])
def test_settle_may_be_zero_but_not_negative_or_non_finite(bad):
    assert MonitorConfig(settle_s=0.0).settle_s == 0.0
    with pytest.raises(ValueError, match="settle_s"):
        MonitorConfig(settle_s=bad)


# --------------------------------------------------------------------------- stale navigation
@pytest.mark.parametrize("limit", [None, 0.2, 3.0])
def test_nav_stale_just_over_the_limit_lands_just_under_does_not(limit):
    """max_nav_age_s (default 1.0 s, RunnerConfig's too): an age of limit - 1 ms is
    fine, limit + 1 ms is ``nav_stale`` with action ``land``."""
    cfg = MonitorConfig() if limit is None else MonitorConfig(max_nav_age_s=limit)
    lim = 1.0 if limit is None else limit
    m = armed_monitor(cfg)
    t = 200.0
    assert m.on_nav_age(t, t - (lim - 1e-3)) is None
    assert m.on_nav_age(t, t - lim) is None            # exactly the limit is not "older than"
    assert m.ok
    v = m.on_nav_age(t, t - (lim + 1e-3))
    assert isinstance(v, Violation)
    assert (v.kind, v.action, v.t_s) == ("nav_stale", "land", t)
    assert v.values["age_s"] == pytest.approx(lim + 1e-3)
    assert m.first is v and not m.ok


def test_nav_age_ignored_before_arming_after_landing_and_without_a_sample():
    m = FlightMonitor()
    assert m.on_nav_age(50.0, 0.0) is None                 # not watching yet
    m.armed(100.0, OFFBOARD)
    assert m.on_nav_age(150.0, None) is None               # no sample yet
    m.landing(160.0)
    assert m.on_nav_age(170.0, 0.0) is None                # our landing: no longer a violation
    assert m.ok


# --------------------------------------------------------------------------- tracking bound
def test_tracking_bound_and_settle_time_at_their_edges():
    """Bound 0.5 m (default) applies from t_traj_start + settle_s (5 s) on."""
    m = armed_monitor()
    t0 = 110.0
    assert m.on_tracking(t0 + 5.0 - 1e-3, t0, 10.0, "estimate") is None   # still settling
    assert m.on_tracking(t0 + 5.0, t0, 0.5, "estimate") is None           # exactly at the bound: within
    assert m.on_tracking(t0 + 6.0, t0, 0.499, "estimate") is None
    assert m.ok
    v = m.on_tracking(t0 + 5.0, t0, 0.5 + 1e-3, "estimate")
    assert (v.kind, v.action) == ("tracking", "land")
    assert v.values == {"error_m": 0.501, "bound_m": 0.5, "source": "estimate"}


def test_tracking_with_no_settle_applies_at_once_and_needs_watching():
    m = FlightMonitor(MonitorConfig(settle_s=0.0))
    assert m.on_tracking(10.0, 0.0, 9.0, "sim_truth") is None     # not armed: not watching
    m.armed(10.0, OFFBOARD)
    assert m.on_tracking(10.0, 10.0, 0.6, "sim_truth").kind == "tracking"


# --------------------------------------------------------------------------- on the ground
def test_on_ground_after_exactly_the_grace_is_not_yet_a_violation():
    m = armed_monitor(MonitorConfig(climb_grace_s=5.0), t_arm=100.0)
    assert m.on_landed_state(105.0, mavlink.MAV_LANDED_STATE_ON_GROUND) is None
    assert m.on_landed_state(106.0, mavlink.MAV_LANDED_STATE_IN_AIR) is None
    v = m.on_landed_state(105.0 + 1e-3, mavlink.MAV_LANDED_STATE_ON_GROUND)
    assert (v.kind, v.action) == ("on_ground", "land")


def test_on_ground_default_grace_is_five_seconds():
    m = armed_monitor(t_arm=0.0)
    assert m.on_landed_state(4.9, 1) is None
    assert m.on_landed_state(5.1, 1).kind == "on_ground"


def test_on_ground_ignored_before_arming_and_after_our_landing():
    m = FlightMonitor()
    assert m.on_landed_state(100.0, 1) is None
    m.armed(0.0, OFFBOARD)
    m.landing(50.0)
    assert m.on_landed_state(100.0, 1) is None
    assert m.ok


# --------------------------------------------------------------------------- heartbeats
def test_emergency_ends_the_flight_once_critical_does_not():
    m = armed_monitor()
    assert m.on_heartbeat(101.0, True, OFFBOARD, mavlink.MAV_STATE_CRITICAL) is None
    v = m.on_heartbeat(102.0, True, OFFBOARD, mavlink.MAV_STATE_EMERGENCY)
    assert (v.kind, v.action, v.t_s) == ("emergency", "end", 102.0)
    assert v.values == {"system_status": mavlink.MAV_STATE_EMERGENCY}
    assert m.first is v


def test_an_emergency_before_arming_does_not_hide_one_in_flight():
    """Regression (found by mutation testing): the flag that reports EMERGENCY once was set by
    a heartbeat before our arming, so an EMERGENCY during the flight went unreported."""
    m = FlightMonitor()
    assert m.on_heartbeat(1.0, False, OFFBOARD, mavlink.MAV_STATE_EMERGENCY) is None
    m.armed(10.0, OFFBOARD)
    v = m.on_heartbeat(11.0, True, OFFBOARD, mavlink.MAV_STATE_EMERGENCY)
    assert v is not None and (v.kind, v.action) == ("emergency", "end")


def test_emergency_after_a_crash_is_reported_even_before_arming():
    m = FlightMonitor()
    assert m.on_heartbeat(1.0, False, OFFBOARD, mavlink.MAV_STATE_EMERGENCY) is None   # nothing of ours
    m2 = FlightMonitor()
    m2.on_statustext(1.0, mavlink.MAV_SEVERITY_CRITICAL, "CRASH: ground")
    v = m2.on_heartbeat(1.1, False, OFFBOARD, mavlink.MAV_STATE_EMERGENCY)
    assert m2.first.kind == "crash" and v is None          # the crash came first and stays first
    m3 = FlightMonitor()
    m3.crash = {"t_s": 1.0, "text": "CRASH"}
    v = m3.on_heartbeat(1.1, False, OFFBOARD, mavlink.MAV_STATE_EMERGENCY)
    assert v.kind == "emergency" and m3.first is v


def test_disarm_in_flight_ends_and_mode_change_releases():
    m = armed_monitor()
    assert m.on_heartbeat(101.0, True, OFFBOARD, mavlink.MAV_STATE_ACTIVE) is None
    v = m.on_heartbeat(102.0, False, OFFBOARD, mavlink.MAV_STATE_STANDBY)
    assert (v.kind, v.action) == ("disarmed", "end")
    m = armed_monitor()
    v = m.on_heartbeat(102.0, True, POSCTL, mavlink.MAV_STATE_ACTIVE)
    assert (v.kind, v.action) == ("mode_change", "release")
    assert v.values == {"expected": "OFFBOARD", "got": "POSCTL"}
    assert v.detail == "vehicle left OFFBOARD for POSCTL (not asked by us)"


def test_an_expected_mode_change_and_an_unknown_mode_are_not_violations():
    m = armed_monitor()
    m.expect_mode(POSCTL)
    assert m.on_heartbeat(101.0, True, POSCTL, mavlink.MAV_STATE_ACTIVE) is None
    m2 = FlightMonitor()
    m2.armed(0.0, None)                     # mode not known: any mode is fine
    assert m2.on_heartbeat(1.0, True, POSCTL, mavlink.MAV_STATE_ACTIVE) is None
    assert m.ok and m2.ok


def test_heartbeats_after_our_landing_are_not_violations():
    m = armed_monitor()
    m.landing(150.0)
    assert m.on_heartbeat(151.0, False, mode(4, 6), mavlink.MAV_STATE_STANDBY) is None
    assert m.ok


# --------------------------------------------------------------------------- crash text
@pytest.mark.parametrize("severity,text,crash", [
    (mavlink.MAV_SEVERITY_CRITICAL, "CRASH: cylinder", True),
    (mavlink.MAV_SEVERITY_ALERT, "crash detected", True),          # lower number: more severe
    (mavlink.MAV_SEVERITY_EMERGENCY, "Crash", True),
    (mavlink.MAV_SEVERITY_ERROR, "CRASH: cylinder", False),        # not critical
    (mavlink.MAV_SEVERITY_CRITICAL, "Failsafe: landing", False),
])
def test_crash_needs_a_critical_crash_statustext(severity, text, crash):
    m = FlightMonitor()
    v = m.on_statustext(3.0, severity, text)
    assert (v is not None) is crash
    assert (m.crash is not None) is crash
    if crash:
        assert (v.kind, v.action, v.detail) == ("crash", "end", text)
        assert m.crash == {"t_s": 3.0, "text": text}


def test_the_first_crash_is_kept_and_every_crash_is_returned():
    m = FlightMonitor()
    m.on_statustext(3.0, 2, "CRASH: one")
    v = m.on_statustext(4.0, 2, "CRASH: two")
    assert v.kind == "crash" and v.detail == "CRASH: two"
    assert m.crash == {"t_s": 3.0, "text": "CRASH: one"} and m.first.detail == "CRASH: one"


# --------------------------------------------------------------------------- bookkeeping
def test_fail_keeps_the_first_and_violation_serialises():
    m = FlightMonitor()
    assert m.ok and not m.watching
    a = m.fail(1.0, "link", "no heartbeat", n=3)
    b = m.fail(2.0, "interrupted", "SIGTERM", action="end")
    assert a.action == "land" and b.action == "end" and m.first is a and not m.ok
    d = a.to_dict()
    assert d == {"t_s": 1.0, "kind": "link", "detail": "no heartbeat", "action": "land", "values": {"n": 3}}
    d["values"]["n"] = 4
    assert a.values == {"n": 3}                             # a copy
    m.armed(5.0, OFFBOARD)
    assert m.watching
