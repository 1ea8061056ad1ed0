"""``companion replay`` where users meet it: exit codes, the one-line errors,
nothing written on bad input, damaged recordings replayed as far as valid."""

from __future__ import annotations

import json
import lzma
import struct
from pathlib import Path

import numpy as np
import pytest

from companion.cli import main
from companion.bundled import missions_dir
from companion.link.tlog_scan import TlogScanner

DATA = Path(__file__).parent / "data" / "replay"
MISSION = missions_dir() / "flat-rectangle" / "mission.yaml"
PLAN = DATA / "plan-flat-rectangle.json"
VEHICLE = DATA / "vehicle-cut4.tlog.xz"


@pytest.fixture(scope="module")
def vehicle_bytes() -> bytes:
    return lzma.decompress(VEHICLE.read_bytes())


def run(capsys, *argv):
    rc = main(["replay", *map(str, argv)])
    out, err = capsys.readouterr()
    return rc, out, err.strip().splitlines()


@pytest.mark.parametrize("make, argv, says", [
    (None, ["{tmp}/missing.tlog"], "no such file"),
    ("dir", ["{tmp}/d"], "is a directory"),
    ("junk", ["{tmp}/junk.tlog"], "no MAVLink records"),
    ("badxz", ["{tmp}/bad.tlog.xz"], "cannot read"),
    (None, [VEHICLE, "--plan", PLAN], "--plan: needs --mission"),
    (None, [VEHICLE, "--tolerance", "-1"], "--tolerance -1.0: must be a finite number >= 0"),
    (None, [VEHICLE, "--tolerance", "nan"], "--tolerance nan"),
    (None, [VEHICLE, "--tolerance", "1e-3", "--exact"], "--exact: cannot be combined with --tolerance"),
    (None, [VEHICLE, "--settle", "-2"], "--settle"),
    (None, [VEHICLE, "--withhold", "NOT_A_MESSAGE", "--mission", MISSION], "unknown MAVLink message"),
    (None, [VEHICLE, "--withhold", "ODOMETRY"], "--withhold: needs --mission"),
    (None, [VEHICLE, "--mission", MISSION], "--plan: the flight flew a plan file"),
    (None, [VEHICLE, "--mission", "{tmp}/nope.yaml", "--plan", PLAN], "nope.yaml"),
    (None, [VEHICLE, "--report", "{tmp}/no/such/dir/r.json"], "does not exist"),
    ("file", [VEHICLE, "--plot", "{tmp}/f"], "exists and is not a directory"),
])
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, capsys, make, argv, says):
    if make == "dir":
        (tmp_path / "d").mkdir()
    elif make == "junk":
        (tmp_path / "junk.tlog").write_bytes(np.random.default_rng(1).integers(0, 256, 4000, np.uint8).tobytes())
    elif make == "badxz":
        (tmp_path / "bad.tlog.xz").write_bytes(VEHICLE.read_bytes()[:5000])
    elif make == "file":
        (tmp_path / "f").write_text("x")
    report = tmp_path / "r.json"
    args = [str(a).replace("{tmp}", str(tmp_path)) for a in argv]
    if "--report" not in args:
        args += ["--report", str(report)]
    before = set(tmp_path.rglob("*"))
    rc, out, err = run(capsys, *args)
    assert rc == 2
    assert len(err) == 1 and err[0].startswith("companion replay: error: ") and says in err[0], err
    assert "Traceback" not in out
    assert set(tmp_path.rglob("*")) == before          # nothing written


def test_metrics_only_report(tmp_path, capsys):
    report = tmp_path / "r.json"
    rc, out, err = run(capsys, VEHICLE, "--report", report)
    assert rc == 0 and err == []
    doc = json.loads(report.read_text())
    assert doc["format"] == "companion-replay" and doc["format_version"] == "1.0"
    assert doc["comparison"] is None and doc["flight"] is None
    assert doc["setup"]["control"] == "vehicle" and doc["setup"]["cut_s"] == 4.0
    live = json.loads((DATA / "vehicle-cut4.report.json").read_text())
    assert doc["metrics"]["duration_s"] == pytest.approx(live["sim_time_s"], abs=1e-9)
    assert doc["metrics"]["n_frames"] == live["n_frames"]
    assert "ESTIMATED" in out          # no ODOMETRY in this flight: the vehicle's estimate


def damage(data: bytes, recs, kinds) -> bytes:
    buf = bytearray(data)
    for kind, k in sorted(kinds, key=lambda x: -recs[x[1]].offset):
        o = recs[k].offset
        if kind == "crc":
            buf[o + 8 + 12] ^= 0x04
        elif kind == "garbage":
            buf[o:o] = b"\xfd\x09garbage\xfe" * 20
        elif kind == "jump":
            for r in recs[k:]:
                struct.pack_into(">Q", buf, r.offset, r.stamp_us + 3_600_000_000)
    return bytes(buf)


def records(data: bytes):
    sc = TlogScanner()
    return sc.feed(data) + sc.close()


def test_damaged_log_metrics_say_what_was_skipped(tmp_path, capsys, vehicle_bytes):
    recs = records(vehicle_bytes)
    bad = damage(vehicle_bytes, recs, [("crc", 2000), ("garbage", 5000)])
    path = tmp_path / "d.tlog"
    path.write_bytes(bad[:-7])                       # and a torn last record
    report = tmp_path / "r.json"
    rc, out, err = run(capsys, path, "--report", report)
    assert rc == 0
    # a packet with a bad CRC, 200 bytes of garbage (no packet in it), a record torn 7 bytes short
    n_bytes = (8 + len(recs[2000].packet)) + 200 + (8 + len(recs[-1].packet) - 7)
    assert f"skipped: {n_bytes} bytes, 2 packets" in out
    scan = json.loads(report.read_text())["scan"]
    assert scan["n_skipped_packets"] == 2 and scan["n_regions"] == 3 and scan["n_skipped_bytes"] == n_bytes
    assert [r["kind"] for r in scan["regions"]] == ["bad_crc", "garbage", "truncated"]
    assert scan["n_records"] == len(recs) - 2
    assert scan["regions"][0]["offset"] == recs[2000].offset


def test_time_jump_replays_identically(tmp_path, capsys, vehicle_bytes):
    recs = records(vehicle_bytes)
    path = tmp_path / "j.tlog"
    path.write_bytes(damage(vehicle_bytes, recs, [("jump", 3000)]))
    report = tmp_path / "r.json"
    rc, out, err = run(capsys, path, "--mission", MISSION, "--plan", PLAN, "--report", report)
    assert rc == 0, err
    doc = json.loads(report.read_text())
    assert doc["comparison"]["identical"] and doc["scan"]["n_time_jumps"] == 1
    assert "time stamp jumps: 1" in out


def test_lost_companion_packet_diverges_and_says_the_log_is_damaged(tmp_path, capsys, vehicle_bytes):
    recs = records(vehicle_bytes)
    k = next(i for i, r in enumerate(recs) if r.compid == 191 and r.msgid == 93 and i > 4000)  # HIL_ACTUATOR_CONTROLS
    path = tmp_path / "c.tlog"
    path.write_bytes(damage(vehicle_bytes, recs, [("crc", k)]))
    rc, out, err = run(capsys, path, "--mission", MISSION, "--plan", PLAN)
    assert rc == 4
    assert err[0].startswith("companion replay: DIVERGED at t=")
    assert any("the recording is damaged (1 packets" in e for e in err)


def test_plot_writes_the_figures(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    rc, out, err = run(capsys, VEHICLE, "--plot", tmp_path / "figs")
    assert rc == 0
    names = sorted(p.name for p in (tmp_path / "figs").iterdir())
    assert names == ["attitude.png", "directions.png", "errors.png", "path3d.png", "position.png"]
    assert all((tmp_path / "figs" / n).stat().st_size > 10_000 for n in names)


def test_exact_compares_bit_for_bit_whatever_the_environment(tmp_path, capsys):
    report = tmp_path / "r.json"
    rc, out, err = run(capsys, VEHICLE, "--mission", MISSION, "--plan", PLAN, "--exact", "--report", report)
    c = json.loads(report.read_text())["comparison"]
    assert c["mode"] == "bitwise" and c["environment"] is None and c["drift"] == {}
    # (whether it passes depends on this machine: the corpus was recorded on another one)
    assert rc == (0 if c["identical"] else 4)
    assert "float32 fields bit for bit" in out
