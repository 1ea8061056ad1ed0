"""Output faults in flight, end to end over real UDP against the SITL subprocess:
the disk fills up, the output directory is deleted. Each flight must end with the
vehicle landed and disarmed (or holding, ``--on-failure hold``) as the SITL itself
reports it to a ground station (its truth, not the companion's .tlog, which is
what failed), a report on disk (in the temporary directory, named, when its own
directory is gone or full), exit code 3 naming the fault and ``completed: false``.
And the console says what report.json says (coverage of a ``--cut`` flight,
derived here from the plan's geometry)."""

from __future__ import annotations

import errno
import json
import os
import shutil
import subprocess
import tempfile
import threading
import time

import numpy as np
import pytest

from companion.cli import main
from companion.bundled import missions_dir
from companion.link import tlog as tlog_mod

pytestmark = pytest.mark.slow

MISSION = missions_dir() / "flat-rectangle" / "mission.yaml"
LAUNCH = (22.45, 8.75)         # under the plan's first way-point (tests/test_outcomes_e2e.py)
AUTO_LAND, AUTO_LOITER = (4, 6), (4, 3)
#: Wall seconds from a fault to the vehicle's mode change: the .tlog is checked
#: once a wall second (``runner.TLOG_CHECK_INTERVAL_S``), the command goes at once.
REACTION_S = 3.0


class Watch(threading.Thread):
    """A ground station (255/190) on the SITL's link: records the vehicle's own
    account (armed, height, mode, by wall time) and runs ``action()`` once
    ``when(state)`` holds."""

    def __init__(self, url: str, when, action) -> None:
        super().__init__(daemon=True)
        os.environ["MAVLINK20"] = "1"
        from pymavlink import mavutil

        self.conn = mavutil.mavlink_connection(url, source_system=255, source_component=190)
        self.when, self.action = when, action
        self.state = {"armed": False, "alt": 0.0, "mode": (0, 0)}
        self.modes: list[tuple[float, tuple]] = []     # (wall s, (main, sub)) at each change
        self.fired_at = None
        self.stop = False

    def run(self) -> None:
        c = self.conn
        next_hb = 0.0
        while not self.stop:
            if time.monotonic() >= next_hb:
                c.mav.heartbeat_send(6, 8, 0, 0, 4)
                next_hb = time.monotonic() + 0.5
            m = c.recv_match(blocking=True, timeout=0.05)
            if m is None or m.get_srcSystem() != 1 or m.get_srcComponent() != 1:
                continue
            t = m.get_type()
            if t == "HEARTBEAT":
                self.state["armed"] = bool(m.base_mode & 128)
                mode = ((m.custom_mode >> 16) & 0xFF, (m.custom_mode >> 24) & 0xFF)
                if mode != self.state["mode"]:
                    self.modes.append((time.monotonic(), mode))
                self.state["mode"] = mode
            elif t == "LOCAL_POSITION_NED":
                self.state["alt"] = -m.z
            if self.fired_at is None and self.when(self.state):
                self.fired_at = time.monotonic()
                self.action()

    def mode_after(self, t_wall: float, mode) -> float | None:
        """Wall seconds from ``t_wall`` to the vehicle entering ``mode``; None if it did not."""
        for t, m in self.modes:
            if t >= t_wall and m == mode:
                return t - t_wall
        return None

    def close(self, settle_s: float = 1.5) -> None:
        time.sleep(settle_s)          # the vehicle's last word after the companion left
        self.stop = True
        self.join(2.0)
        self.conn.close()


def _flying(state) -> bool:
    return state["armed"] and state["alt"] > 1.0


class _FullWhen:
    """The .tlog's file: every write fails with ENOSPC once ``full`` is set."""

    def __init__(self, f, full: threading.Event) -> None:
        self.f, self.full = f, full

    def write(self, b):
        if self.full.is_set():
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return self.f.write(b)

    def flush(self):
        if self.full.is_set():
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.f.flush()

    def fileno(self):
        return self.f.fileno()

    def close(self):
        self.f.close()


def _fly(sitl, tlog, report, when, action, *extra):
    watch = Watch(sitl.url, when, action)
    watch.start()
    try:
        rc = main(["fly", str(MISSION), "--connect", sitl.url, "--tlog", str(tlog), "--report", str(report),
                   "--quiet", "--cut", "30", *extra])
    finally:
        watch.close()
    return rc, watch


def _landed_by_the_failsafe(watch) -> None:
    assert watch.fired_at is not None, "the fault was never injected"
    dt = watch.mode_after(watch.fired_at, AUTO_LAND)
    assert dt is not None and dt < REACTION_S, (dt, watch.modes)
    assert not watch.state["armed"] and watch.state["alt"] < 0.3, watch.state    # on the ground, disarmed


def test_disk_full_in_flight_lands_and_reports(tmp_path, monkeypatch, capsys):
    full = threading.Event()
    real = tlog_mod.open_tlog_file
    monkeypatch.setattr(tlog_mod, "open_tlog_file", lambda p: _FullWhen(real(p), full))
    from sitl.api import SitlProcess

    report = tmp_path / "report.json"
    with SitlProcess(MISSION, lockstep=True, start=LAUNCH) as sitl:
        rc, watch = _fly(sitl, tmp_path / "flight.tlog", report, _flying, full.set)
    err = capsys.readouterr().err
    assert rc == 3 and "Traceback" not in err
    _landed_by_the_failsafe(watch)
    rep = json.loads(report.read_text())
    assert not rep["completed"] and rep["violation"]["kind"] == "output"
    assert [f["kind"] for f in rep["faults"]] == ["tlog"] and "(ENOSPC)" in rep["faults"][0]["detail"]
    assert rep["phase"] in ("takeoff", "hold", "trajectory") and rep["end_phase"] == "done"
    assert "NOT completed in phase" in err and "(ENOSPC)" in err


def test_output_directory_deleted_in_flight_holds_and_reports_in_the_temp_dir(tmp_path, monkeypatch, capsys):
    out, tmp = tmp_path / "out", tmp_path / "tmp"
    out.mkdir()
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    from sitl.api import SitlProcess

    with SitlProcess(MISSION, lockstep=True, start=LAUNCH) as sitl:
        rc, watch = _fly(sitl, out / "flight.tlog", out / "report.json", _flying,
                         lambda: shutil.rmtree(out), "--on-failure", "hold")
    err = capsys.readouterr().err
    assert rc == 3 and "Traceback" not in err
    assert watch.fired_at is not None
    dt = watch.mode_after(watch.fired_at, AUTO_LOITER)
    assert dt is not None and dt < REACTION_S, (dt, watch.modes)
    assert watch.state["armed"] and watch.state["alt"] > 1.0     # holding in the air, under its own control
    assert not out.exists()                                      # not recreated behind the user's back
    (fallback,) = tmp.glob("companion-report-*.json")
    assert str(fallback) in err
    rep = json.loads(fallback.read_text())
    assert not rep["completed"] and rep["end_phase"] == "holding"
    assert rep["violation"]["kind"] == "output" and "disappeared" in rep["error"]
    assert [f["kind"] for f in rep["faults"]] == ["tlog", "report"]
    assert rep["report_fallback"]["path"] == str(fallback)
    assert rep["report_fallback"]["wanted"] == str(out / "report.json")


def _mount_tmpfs(where, size: str) -> bool:
    where.mkdir()
    try:
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                           capture_output=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return r.returncode == 0


def test_a_real_full_disk_in_flight_lands_and_reports(tmp_path, monkeypatch, capsys):
    """A genuine ENOSPC: a small tmpfs, filled up while the vehicle flies (skipped
    where mounting is not permitted)."""
    disk, tmp = tmp_path / "disk", tmp_path / "tmp"
    if not _mount_tmpfs(disk, "40m"):
        pytest.skip("mounting a tmpfs is not permitted here")
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))

    def fill() -> None:
        with open(disk / "filler", "wb") as f:
            try:
                while True:
                    f.write(b"\0" * (1 << 20))
                    f.flush()
            except OSError:
                pass

    try:
        from sitl.api import SitlProcess

        with SitlProcess(MISSION, lockstep=True, start=LAUNCH) as sitl:
            rc, watch = _fly(sitl, disk / "flight.tlog", disk / "report.json", _flying, fill)
        err = capsys.readouterr().err
        assert rc == 3 and "Traceback" not in err
        _landed_by_the_failsafe(watch)
        fallbacks = list(tmp.glob("companion-report-*.json"))
        rep = json.loads((fallbacks[0] if fallbacks else disk / "report.json").read_text())
        assert not rep["completed"] and rep["violation"]["kind"] == "output"
        assert "(ENOSPC)" in rep["faults"][0]["detail"]
        if fallbacks:      # the report did not fit either: named where it went
            assert rep["report_fallback"]["path"] == str(fallbacks[0]) and str(fallbacks[0]) in err
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True, timeout=10)


def test_cut_flight_console_and_report_agree_on_the_coverage_flown(tmp_path, capsys):
    """``--cut 5`` flies the way-points up to the first at or after 5 s (docs:
    ``companion fly --cut``); the coverage flown is the plan's coverage times the
    share of the coverage path's length up to that way-point."""
    from mavcore.mission import load_mission
    from companion.planner import plan_mission
    from companion.summary import coverage_text
    from sitl.api import SitlProcess

    plan = plan_mission(load_mission(MISSION))
    P = np.asarray(plan.coverage.path_xy_m, dtype=float)
    seg = np.hypot(*np.diff(P, axis=0).T)
    t = np.asarray(plan.waypoints.t_s)
    stop = np.asarray(plan.waypoints.p_enu_m)[int(np.argmax(t >= t[0] + 5.0)), :2]
    # arc length of the stop on the path (it lies on one of the path's straight pieces)
    s_stop = min(np.concatenate([[0.0], np.cumsum(seg)])[k] + np.hypot(*(stop - P[k]))
                 for k in range(len(seg))
                 if np.hypot(*(stop - P[k])) + np.hypot(*(P[k + 1] - stop)) < seg[k] + 1e-6)
    expected = plan.stats.coverage_fraction * s_stop / seg.sum()

    report = tmp_path / "report.json"
    with SitlProcess(MISSION, lockstep=True, start=LAUNCH) as sitl:
        rc = main(["fly", str(MISSION), "--connect", sitl.url, "--tlog", str(tmp_path / "f.tlog"),
                   "--report", str(report), "--quiet", "--cut", "5"])
    out = capsys.readouterr().out
    rep = json.loads(report.read_text())
    assert rc == 0 and rep["completed"], rep["violation"]
    # samples every 0.5 m count within 0.5 m: the vehicle stopping at the way-point reaches one more
    assert rep["coverage_fraction"] == pytest.approx(expected, abs=1.0 / seg.sum())
    assert rep["planned_coverage_fraction"] == plan.stats.coverage_fraction
    assert coverage_text(rep["coverage_fraction"], rep["planned_coverage_fraction"]) in out
    assert "(companion control)" in out and rep["control_in_use"] == "companion"
    assert rep["phase"] == rep["end_phase"] == "done"
