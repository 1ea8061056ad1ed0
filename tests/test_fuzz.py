"""Bounded fuzzing (benchmarks/fuzz_link.py has the long run): the fuzzer
itself, the companion's receive path on a real socket, and the SITL during a
signed companion flight with a lockstep racer. All traffic on loopback."""

from __future__ import annotations

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore.link.signing import SignatureVerifier

import fuzz_link   # benchmarks/ (pyproject: pytest pythonpath)


def _parse(data: bytes) -> list:
    rx = mavlink.MAVLink(None)
    rx.robust_parsing = True
    try:
        return rx.parse_buffer(data) or []
    except Exception:
        return []


def test_fuzzer_is_seeded_and_each_kind_is_what_it_says():
    f1, f2 = fuzz_link.Fuzzer(np.random.default_rng(5)), fuzz_link.Fuzzer(np.random.default_rng(5))
    assert [f1.datagram() for _ in range(200)] == [f2.datagram() for _ in range(200)]
    by_kind: dict = {}
    f = fuzz_link.Fuzzer(np.random.default_rng(9))
    for _ in range(1500):
        k, d = f.datagram()
        by_kind.setdefault(k, []).append(d)
    assert set(by_kind) == set(fuzz_link.KINDS)
    good = lambda d: [m for m in _parse(d) if m.get_type() not in ("BAD_DATA", "UNKNOWN")]   # noqa: E731
    # valid packets parse; broken ones do not
    assert sum(bool(good(d)) for d in by_kind["random_fields"]) > 0.9 * len(by_kind["random_fields"])
    assert not any(good(d) for d in by_kind["bad_crc"])
    assert all(d[0] == 0xFE for d in by_kind["mavlink1"] if len(d) > 20)
    assert max(len(d) for d in by_kind["oversized"]) > 1500
    assert all(d[2] & 1 for d in by_kind["bad_signature"] if d[0] == 0xFD)
    v = SignatureVerifier(bytes(32))
    assert not any(v.check(d).ok for d in by_kind["bad_signature"])
    ctl = [m for d in by_kind["spoofed_ids_control"] for m in good(d)]
    assert ctl and all((m.get_srcSystem(), m.get_srcComponent()) == (1, 191) for m in ctl)
    # the racer reads a frame's time from the bytes as pymavlink does
    mav = mavlink.MAVLink(None, 1, 1)
    frame = bytes(mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav)
                  + mav.highres_imu_encode(123456789, *([0.5] * 13), 0, 0).pack(mav))
    assert fuzz_link.imu_time_usec(frame) == _parse(frame)[-1].time_usec == 123456789
    foreign = [m for d in by_kind["foreign_control"] for m in good(d)]
    assert foreign and all(m.get_srcSystem() >= 2 for m in foreign)


def test_fuzz_companion_connection_receive_path():
    """2000 hostile datagrams from 8 other ports (a fifth spoof the vehicle, 1/1,
    some with far timestamps) interleaved with 200 vehicle frames: no crash,
    every vehicle frame through, nothing from the fuzzer accepted."""
    r = fuzz_link.run_connection_campaign(2000, 200, seed=11)
    assert r["crashes"] == 0
    assert r["datagrams"] == 2000
    assert r["vehicle_frames_received"] == r["vehicle_frames_sent"] == 200
    assert r["foreign_frames_accepted"] == 0
    link = r["link"]
    assert link["foreign_address"] > 0 and link["foreign_id"] > 0     # the spoofing reached the filter
    assert link["accepted"] == 201                                     # the heartbeat + the frames


@pytest.mark.slow
def test_fuzz_sitl_during_a_signed_flight(tmp_path):
    """The SITL (signing on, the companion its only controller) takes 1500
    hostile datagrams from 16 ports and a racer answering every frame with a
    spoofed lockstep command of zeros, during a companion flight: no crash,
    no foreign control accepted, the flight completes and tracks."""
    f = fuzz_link.run_flight_campaign(1500, True, 3.0, 1000.0, seed=4, workdir=tmp_path, settle_s=1.0,
                                      pregenerate=True)
    assert f["crashes"] == 0, f
    assert f["datagrams"] == 1500 and set(f["by_kind"]) >= set(fuzz_link.KINDS)
    assert f["accepted_foreign_control"] == 0 and f["sitl_rebound"] == 0
    assert f["accepted_control_from_companion"] > 1000           # every frame's answer
    assert f["racer_answers"] > 0 and f["sitl_ignored_control"]["unsigned"] >= f["racer_answers"] // 2
    assert f["completed"], f.get("error")
    assert f["n_tracking_samples"] > 0 and f["max_error_m"] < 0.05
    assert f["companion_link"]["dropped"] == 0                   # the vehicle's own stream was all good
    assert f["report_link"]["auth"]["accepted"] == f["companion_link"]["accepted"]   # report.json's link.auth
