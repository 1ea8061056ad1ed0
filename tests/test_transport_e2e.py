"""Faithfulness of the in-process transport (``companion demo --transport inproc``):
the same flight, packet for packet, as over UDP with the SITL in its own process.

Why identical and not merely close: in lockstep the vehicle clock only moves
when the companion answers a frame, both transports carry the same bytes in
the same order (``mavcore.link.pipe``), the in-process SITL starts like the UDP one
(frame 0's telemetry reaches nobody until the peer is known, then it is
re-sent, so every stream's schedule has the same phase), and replies between
frames are handled with the next frame (``Connection.frame_sync``). Nothing the
flight computes depends on wall time. What may differ is wall-clock only:
SYSTEM_TIME's Unix time, the vehicle's HEARTBEATs while its clock is stalled
(one a wall second: a loaded machine delays UDP answers), the companion's
HEARTBEATs before the vehicle clock runs, and hence MAVLink sequence numbers.
"""

from __future__ import annotations

import json

import pytest

from companion.cli import main
from companion.bundled import missions_dir
from companion.link.tlog_scan import TlogScanner

pytestmark = pytest.mark.slow

HEARTBEAT, SYSTEM_TIME = 0, 2
#: report.json keys that are wall-clock or transport by nature.
WALL_KEYS = {"wall_time_s", "real_time_factor", "tlog", "link"}


def _packets(path):
    """(msgid, sysid, compid, payload) of every record, without the wall-clock ones."""
    sc = TlogScanner()
    recs = sc.feed(path.read_bytes()) + sc.close()
    assert sc.summary.n_regions == 0
    return [(r.msgid, r.sysid, r.compid, r.payload()) for r in recs
            if r.msgid not in (HEARTBEAT, SYSTEM_TIME)]


def _fly(tmp_path, transport, mission, cut, seed):
    out = tmp_path / transport
    rc = main(["demo", "--mission", mission, "--cut", cut, "--seed", str(seed), "--transport", transport,
               "--out", str(out), "--no-plots", "--quiet"])
    rep = json.loads((out / "report.json").read_text())
    return rc, rep, _packets(out / "flight.tlog")


def _same_flight(tmp_path, mission, cut, seed):
    rc_u, rep_u, pk_u = _fly(tmp_path, "udp", mission, cut, seed)
    rc_i, rep_i, pk_i = _fly(tmp_path, "inproc", mission, cut, seed)
    assert rc_u == rc_i == 0
    assert rep_u["completed"] and rep_i["completed"]
    assert rep_i["link"]["auth"]["vehicle_address"] == "inproc:0"       # it really was in process
    assert rep_u["link"]["auth"]["vehicle_address"].startswith("127.0.0.1:")
    assert {k: v for k, v in rep_i.items() if k not in WALL_KEYS} == \
        {k: v for k, v in rep_u.items() if k not in WALL_KEYS}
    answers = [p for p in pk_u if p[2] == 191]
    assert len(answers) > 1000
    assert pk_i == pk_u       # every packet both ways, in order: telemetry and the companion's answers
    return rep_i


def test_demo_flight_is_identical_in_process_and_over_udp(tmp_path):
    rep = _same_flight(tmp_path, "flat-rectangle", "4", 7)
    assert rep["tracking"]["max_error_m"] is not None


def test_obstacle_flight_is_identical_in_process_and_over_udp(tmp_path):
    """The low crate moved into the first corridor (as tests/test_replan_e2e.py):
    rangefinder ray casts and the replanner's climb over it, both ways."""
    src = missions_dir() / "obstacle-low" / "mission.yaml"
    old = "{type: box, x: 7.0, y: 6.25,"
    text = src.read_text().replace("../flat-rectangle/", str(missions_dir() / "flat-rectangle") + "/")
    assert old in text
    path = tmp_path / "obstacle-low.yaml"
    path.write_text(text.replace(old, "{type: box, x: 17.0, y: 8.75,"))
    rep = _same_flight(tmp_path, str(path), "10", 3)
    assert rep["replanning"]["events"] >= 1
    assert rep["replanning"]["min_clearance_m"] is not None
