"""companion.report and companion.progress."""

from __future__ import annotations

import io
import json
import math

import pytest

from companion.progress import Progress
from companion.report import FlightReport, ReplanningStats, tracking_stats, write_report


def test_tracking_stats_hand_worked():
    t = [0.0, 1.0, 5.0, 6.0, 7.0]
    e = [9.0, 9.0, 0.003, 0.004, float("nan")]
    st = tracking_stats(t, e, t_start_s=0.0, settle_s=5.0)
    assert st.max_error_m == pytest.approx(0.004)
    assert st.rms_error_m == pytest.approx(math.sqrt((0.003 ** 2 + 0.004 ** 2) / 2))
    assert st.n_samples == 2
    empty = tracking_stats([0.0], [1.0], 0.0, 5.0)
    assert empty.max_error_m is None and empty.n_samples == 0


def test_report_json_has_design_keys_and_no_nan(tmp_path):
    rep = FlightReport(completed=True, control="companion", sim_time_s=10.0, wall_time_s=1.0,
                       tracking=tracking_stats([6.0], [0.002], 0.0),
                       replanning=ReplanningStats(0, None, 0.0), coverage_fraction=float("nan"), tlog="x.tlog")
    p = write_report(rep, tmp_path / "r.json")
    d = json.loads(p.read_text())
    for k in ("completed", "control", "sim_time_s", "wall_time_s", "tracking", "replanning",
              "coverage_fraction", "tlog"):
        assert k in d
    assert set(d["tracking"]) >= {"max_error_m", "rms_error_m", "settle_s"}
    assert set(d["replanning"]) >= {"events", "min_clearance_m", "max_lateral_deviation_m"}
    assert d["coverage_fraction"] is None          # NaN is not JSON
    assert not (tmp_path / "r.json.part").exists()


def test_progress_tty_rewrites_plain_prints_lines():
    s = io.StringIO()
    p = Progress(s, tty=True)
    p.update("takeoff", 0.0, None, 0, 1.0)
    p.update("trajectory", 0.5, 0.0021, 1, 60.0)
    p.close()
    out = s.getvalue()
    assert out.count("\r") == 2 and out.endswith("\n") and "2.1 mm" in out and "50.0%" in out
    s = io.StringIO()
    p = Progress(s, tty=False, plain_interval_s=100.0)
    for i in range(50):
        p.update("trajectory", i / 50, 0.001, 0, float(i))
    p.update("landing", 1.0)
    assert "\r" not in s.getvalue() and len(s.getvalue().splitlines()) == 2
