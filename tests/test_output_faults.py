"""Outputs of a flight (the .tlog, report.json): failures in flight are kept, not
raised (``TlogWriter.fault``, ``TlogWriter.check``), the report falls back to the
temporary directory, and the outputs are checked before take-off
(``check_output_paths``, ``check_writable``, ``check_free_space``). Fast, no
flight; the flights are in ``test_output_faults_e2e.py``."""

from __future__ import annotations

import errno
import json
import os
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest
from jsonschema import Draft202012Validator

from companion.cli import main
from companion.commands import fly
from mavcore.errors import InputError
from companion.link import tlog as tlog_mod
from companion.link.tlog import TlogWriter, read_tlog
from companion.progress import Progress
from companion.report import (FlightReport, ReplanningStats, temp_name, tracking_stats, write_report,
                              write_report_or_fallback)
from companion.summary import control_text, coverage_text, failure_lines, outcome_text

DOCS = Path(__file__).resolve().parents[1] / "docs"
REPORT = Draft202012Validator(json.loads((DOCS / "schemas" / "report.schema.json").read_text()))
MISSION = Path(__file__).resolve().parents[1] / "missions" / "flat-rectangle" / "mission.yaml"


def _packet(k: int, n: int = 50) -> bytes:
    """A MAVLink 2 HEARTBEAT-sized stand-in: only its length matters to the writer."""
    from pymavlink.dialects.v20 import common as mavlink

    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.seq = k % 256
    return mav.heartbeat_encode(2, 12, 0, k, 4).pack(mav)


class _DiskFull:
    """A file that takes ``capacity`` bytes and then fails every write with ENOSPC
    (what a full disk does to a process, without root or a real full disk)."""

    def __init__(self, f, capacity: int) -> None:
        self.f, self.left = f, capacity

    def write(self, b) -> int:
        if len(b) > self.left:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.left -= len(b)
        return self.f.write(b)

    def flush(self) -> None:
        self.f.flush()

    def fileno(self) -> int:
        return self.f.fileno()

    def close(self) -> None:
        self.f.close()


# --- the writer -------------------------------------------------------------------------

def test_enospc_after_n_bytes_is_kept_not_raised(tmp_path, monkeypatch):
    pkt = _packet(1)
    rec = 8 + len(pkt)                     # big-endian uint64 stamp + the packet (docs/tlog.md)
    capacity = 10 * rec + rec // 2         # room for 10 whole records, not 11
    real = tlog_mod.open_tlog_file
    monkeypatch.setattr(tlog_mod, "open_tlog_file", lambda p: _DiskFull(real(p), capacity))
    path = tmp_path / "f.tlog"
    w = TlogWriter(path).open()
    for k in range(15):
        w.write(_packet(k), 1_000_000 + k)            # never raises
    w.write_many([_packet(k) for k in range(3)], 2_000_000)
    w.close()
    assert w.n_records == 10 and w.n_bytes == 10 * rec
    assert w.n_dropped == 5 + 3
    assert w.fault == f"{path}: cannot write: {os.strerror(errno.ENOSPC)} (ENOSPC)"
    # what was accepted is on disk, whole
    assert path.stat().st_size == 10 * rec
    assert [r.time_usec for r in read_tlog(path, skip_bad=False)] == [1_000_000 + k for k in range(10)]


def test_a_healthy_tlog_passes_its_check(tmp_path):
    w = TlogWriter(tmp_path / "f.tlog").open()
    for k in range(5):
        w.write(_packet(k), k)
        assert w.check() is None
    w.close()
    assert w.fault is None and w.n_dropped == 0


@pytest.mark.parametrize("what,expected", [
    ("delete file", "disappeared"),
    ("delete directory", "disappeared"),
    ("replace", "was replaced by another file"),
    ("truncate", "stopped growing: {rec} bytes on disk of {two} written"),
])
def test_a_tlog_deleted_replaced_or_truncated_is_a_fault(tmp_path, what, expected):
    d = tmp_path / "out"
    d.mkdir()
    path = d / "f.tlog"
    w = TlogWriter(path).open()
    w.write(_packet(0), 1)
    assert w.check() is None
    if what == "delete file":
        path.unlink()
    elif what == "delete directory":
        shutil.rmtree(d)
    elif what == "replace":
        other = tmp_path / "other.tlog"
        other.write_bytes(b"x" * 100)
        os.replace(other, path)
    else:
        os.truncate(path, 0)
        w.write(_packet(1), 2)          # appended at the new end: the file stays short
    rec = 8 + len(_packet(0))           # stamp + packet
    assert expected.format(rec=rec, two=2 * rec) in (w.check() or "")
    assert w.fault.startswith(str(path))
    n = w.n_records
    w.write(_packet(1), 2)                              # later packets are dropped, quietly
    assert w.n_dropped == 1 and w.n_records == n
    w.close()


# --- report.json: names, temporaries, fallback ------------------------------------------------

def _report(**changes) -> FlightReport:
    rep = FlightReport(completed=True, control="companion", sim_time_s=30.0, wall_time_s=4.0,
                       tracking=tracking_stats([6.0, 7.0], [0.003, 0.004], 0.0), replanning=ReplanningStats(),
                       coverage_fraction=0.5, tlog="f.tlog", mission="m", phase="done",
                       planned_coverage_fraction=0.5, path_flown_fraction=1.0)
    from dataclasses import replace
    return replace(rep, **changes)


def test_the_longest_legal_name_is_written_with_a_short_temporary(tmp_path):
    name = "r" * 250 + ".json"                          # 255 bytes: NAME_MAX on Linux file systems
    assert len(temp_name(tmp_path / name).name) <= 21
    fly.check_output_paths([("--report", tmp_path / name)])
    p = write_report(_report(), tmp_path / name)
    assert json.loads(p.read_text())["completed"] is True
    assert sorted(os.listdir(tmp_path)) == [name]       # no temporary left behind


@pytest.mark.parametrize("name", ["r" * 256, "é" * 128])   # 256 bytes (é is 2 bytes in UTF-8)
def test_a_name_over_name_max_is_refused_before_anything(tmp_path, name):
    with pytest.raises(InputError, match="file name of 256 bytes is longer than the 255"):
        fly.check_output_paths([("--report", tmp_path / name)])


def test_a_non_regular_output_is_refused(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="is not a regular file"):
        fly.check_output_paths([("--tlog", fifo)])


def test_an_unwritable_directory_is_refused(tmp_path, monkeypatch):
    # a real one for any user, root included: nothing can be created in /proc/self
    if Path("/proc/self").is_dir():
        with pytest.raises(InputError, match="directory /proc/self is not writable"):
            fly.check_writable([("--report", "/proc/self/report.json")])
    # and what a read-only mount answers, without mounting one
    import tempfile

    def read_only(**kw):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS))

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    with pytest.raises(InputError, match="is not writable: Read-only file system"):
        fly.check_writable([("--tlog", tmp_path / "f.tlog")])


def test_a_writable_directory_is_left_as_it_was(tmp_path):
    fly.check_writable([("--tlog", tmp_path / "f.tlog"), ("--report", tmp_path / "r.json")])
    assert os.listdir(tmp_path) == []


def test_report_falls_back_to_the_temporary_directory_and_says_so(tmp_path):
    fb_dir = tmp_path / "tmp"
    fb_dir.mkdir()
    wanted = tmp_path / "gone" / "report.json"          # its directory was deleted in flight
    done = write_report_or_fallback(_report(), wanted, tmp_dir=str(fb_dir))
    assert done.fallback and done.path is not None and done.path.parent == fb_dir
    doc = json.loads(done.path.read_text())
    assert REPORT.is_valid(doc), list(REPORT.iter_errors(doc))
    assert doc["completed"] is False                    # a flight whose report is not where asked
    assert doc["report_fallback"] == {"path": str(done.path), "wanted": str(wanted),
                                      "reason": doc["faults"][-1]["detail"]}
    assert doc["faults"][-1]["kind"] == "report" and "No such file or directory (ENOENT)" in doc["error"]
    assert doc["phase"] == doc["end_phase"] == "done"   # it failed after landing
    # nowhere at all: the caller gets the report and the reason
    nowhere = write_report_or_fallback(_report(), wanted, tmp_dir=str(tmp_path / "also-gone"))
    assert nowhere.path is None and "fallback" in nowhere.error


# --- free space ------------------------------------------------------------------------------

def test_expected_tlog_size_is_duration_plus_overhead_at_the_recorded_rate():
    # (60 s of trajectory + 120 s take-off, hold, hover, landing) x 200 kB/s
    assert fly.expected_tlog_bytes(60.0) == 180 * 200_000 == 36_000_000


def test_free_space_is_summed_per_file_system(tmp_path):
    need = 36_000_000 + (1 << 20)

    def fs(free):
        return lambda d: SimpleNamespace(f_bavail=free // 4096, f_frsize=4096)

    outputs = [("--tlog", tmp_path / "f.tlog", 36_000_000), ("--report", tmp_path / "r.json", 1 << 20)]
    fly.check_free_space(outputs, statvfs=fs(need + 4096))
    with pytest.raises(InputError, match=r"needs about 37\.0 MB, 37\.0 MB free"):
        fly.check_free_space(outputs, statvfs=fs(need - 4096))
    # each alone would fit: together they do not
    fly.check_free_space(outputs[:1], statvfs=fs(need - 4096))


def test_fly_refuses_an_unusable_report_before_arming(tmp_path, capsys):
    report = tmp_path / ("r" * 256)
    rc = main(["fly", str(MISSION), "--report", str(report), "--tlog", str(tmp_path / "f.tlog"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "longer than the 255" in err
    assert os.listdir(tmp_path) == []


# --- what the console says is what the report says ---------------------------------------------

def test_summary_lines_are_rendered_from_the_report():
    # a --cut flight: 1.6 % of the field flown of the 97.6 % planned
    rep = _report(coverage_fraction=0.976 * 0.0164, planned_coverage_fraction=0.976, path_flown_fraction=0.0164)
    assert coverage_text(rep.coverage_fraction, rep.planned_coverage_fraction) == \
        "coverage 1.6% flown of 97.6% planned"
    assert control_text(rep) == "companion control" and outcome_text(rep) == "completed"
    deg = _report(completed=False, phase="takeoff", end_phase="done", error="frame jitter, then tracking",
                  control_in_use="vehicle",
                  control_mode_changes=({"t_s": 3.25, "from": "companion", "to": "vehicle",
                                         "reason": "frame jitter", "phase": "takeoff"},),
                  faults=({"t_s": 9.0, "kind": "tlog", "detail": "f.tlog: disappeared", "phase": "hold"},))
    assert control_text(deg) == "companion control, vehicle control from t=3.2 s (frame jitter)"
    assert outcome_text(deg) == "NOT completed in phase takeoff, ended done"
    assert failure_lines(deg) == ["NOT completed in phase takeoff: frame jitter, then tracking",
                                  "fault (tlog): f.tlog: disappeared"]
    line = Progress.format("trajectory", 0.5, 0.001, 0, 12.0, coverage=0.25, control="vehicle")
    assert line.endswith("coverage  25.0%  (vehicle control)")
