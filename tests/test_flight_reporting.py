"""The flight's measurements (``companion.flight.reporting.FlightRecorder``), without a flight core."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from companion.flight.reporting import FlightRecorder

PHASE_CODE = {"takeoff": 4, "trajectory": 6}
FLYING = ("takeoff", "trajectory")


class _Monitor:
    def __init__(self):
        self.tracking = []

    def on_tracking(self, t, t_traj, err, source):
        self.tracking.append((t, err))

    def on_nav_age(self, t, nav_t):
        return None


def recorder(coverage_fraction=None):
    view = SimpleNamespace(t_us=None, odom=None, truth=None, pos=None, pos_ms=None, pos_new=False, n_frames=0,
                           truth_source="estimate", nav_t=None, R=None)
    cfg = SimpleNamespace(settle_s=0.0)
    inputs = SimpleNamespace(path_xy_m=None, coverage_fraction=coverage_fraction, obstacle_clearance=None)
    mon = _Monitor()
    rec = FlightRecorder(cfg, inputs, mon, lambda v: None, view, PHASE_CODE, FLYING)
    rec.errors.start(0.0)
    return rec, view, mon


def ref(p):
    return SimpleNamespace(p=p, s=(1.0, 0.0, 0.0))


def test_a_late_fix_is_compared_with_the_reference_of_its_own_frame():
    rec, view, mon = recorder()
    for k, p in enumerate(((0.0, 0.0, 2.0), (1.0, 0.0, 2.0))):      # frames at 1.000 s and 1.004 s
        view.t_us, view.n_frames = 1_000_000 + 4000 * k, k + 1
        if k == 1:   # the fix arrives with the second frame, measured at the first (time_boot_ms 1000)
            view.pos, view.pos_ms, view.pos_new = (0.0, 0.3, 2.4), 1000, True
        rec.record(view.t_us * 1e-6, "trajectory", ref(p), None, 0.0)
    # against (0, 0, 2): sqrt(0.3^2 + 0.4^2) = 0.5 m; against the second frame's (1, 0, 2) it would be 1.118 m
    assert rec.last_err == pytest.approx(0.5) and rec.errors.max_m == pytest.approx(0.5)
    assert mon.tracking == [(pytest.approx(1.0), pytest.approx(0.5))] and not view.pos_new


def test_coverage_flown_without_a_path_is_the_plans_once_completed():
    rec, _, _ = recorder(coverage_fraction=0.8)
    assert rec.coverage_flown() is None and rec.coverage_flown(completed=True) == 0.8
    assert recorder()[0].coverage_flown(completed=True) is None
