"""Damaged .tlogs: everything valid is replayed, what was skipped is reported.

The damaged files are built from a good recording of the corpus; the records
expected back are counted independently of the scanner under test: a strict
splitter (stamp, then the length the MAVLink header gives) that must consume
the good file exactly, cross-checked with pymavlink's own parser. Every case
requires 100 % of the untouched records before and after each damaged region,
nothing else, and the skipped bytes and packets to be exactly the damaged ones.
"""

from __future__ import annotations

import lzma
import struct
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.link.tlog import TlogWriter, read_tlog
from companion.link.tlog_scan import MAX_REPORTED, TlogScanner

DATA = Path(__file__).parent / "data" / "replay"


@pytest.fixture(scope="module")
def good() -> bytes:
    return lzma.decompress((DATA / "vehicle-cut4.tlog.xz").read_bytes())


@pytest.fixture(scope="module")
def split(good):
    """[(offset, n_bytes)] of every record of the good file, by the strict splitter."""
    out, i = [], 0
    while i < len(good):
        magic = good[i + 8]
        assert magic in (0xFD, 0xFE)
        if magic == 0xFD:
            n = 8 + 12 + good[i + 9] + (13 if good[i + 10] & 1 else 0)
        else:
            n = 8 + 8 + good[i + 9]
        out.append((i, n))
        i += n
    assert i == len(good)
    # pymavlink agrees on the packets (no bad data, same count)
    mav = mavlink.MAVLink(None)
    msgs = mav.parse_buffer(b"".join(good[o + 8:o + n] for o, n in out)) or []
    assert len(msgs) == len(out) and not any(m.get_type() == "BAD_DATA" for m in msgs)
    return out


def scan(data: bytes, chunk: int | None = None):
    sc = TlogScanner()
    recs = []
    if chunk is None:
        recs += sc.feed(data)
    else:
        for i in range(0, len(data), chunk):
            recs += sc.feed(data[i:i + chunk])
    recs += sc.close()
    return recs, sc.summary


def records(data: bytes, split, keep) -> list:
    """(stamp, packet) of the records of ``split`` selected by ``keep`` (indices)."""
    return [(struct.unpack(">Q", data[o:o + 8])[0], data[o + 8:o + n]) for k, (o, n) in enumerate(split) if k in keep]


def got(recs) -> list:
    return [(r.stamp_us, r.packet) for r in recs]


def test_a_good_file_scans_whole_in_any_chunking(good, split):
    recs, s = scan(good)
    assert got(recs) == records(good, split, set(range(len(split))))
    assert [r.offset for r in recs] == [o for o, _ in split]
    assert s.n_skipped_bytes == 0 and s.n_regions == 0 and s.n_time_jumps == 0 and not s.damaged
    assert s.n_bytes == len(good) and s.n_records == len(split)
    recs2, _ = scan(good, chunk=997)
    assert got(recs2) == got(recs)


def test_truncated_mid_packet(good, split):
    k = len(split) // 2
    o, n = split[k]
    data = good[:o + n // 2]
    recs, s = scan(data)
    assert got(recs) == records(good, split, set(range(k)))
    assert s.n_skipped_bytes == n // 2 and s.n_skipped_packets == 1
    assert [(r.offset, r.kind) for r in s.regions] == [(o, "truncated")]


def test_garbage_between_records(good, split):
    rng = np.random.default_rng(7)
    junk = rng.integers(0, 256, 1000, dtype=np.uint8)
    junk[::37] = 0xFD                       # plenty of false packet starts
    junk[5::41] = 0xFE
    k = 300
    o = split[k][0]
    data = good[:o] + junk.tobytes() + good[o:]
    recs, s = scan(data, chunk=4096)
    assert got(recs) == records(good, split, set(range(len(split))))   # 100 % before and after
    assert s.n_skipped_bytes == 1000 and s.n_skipped_packets == 0
    assert [(r.offset, r.n_bytes, r.kind) for r in s.regions] == [(o, 1000, "garbage")]


def test_bad_crc(good, split):
    k = 1234
    o, n = split[k]
    data = bytearray(good)
    data[o + 8 + 12] ^= 0x10                # a bit of the payload
    recs, s = scan(bytes(data))
    assert got(recs) == records(good, split, set(range(len(split))) - {k})
    assert [(r.offset, r.n_bytes, r.kind, r.n_packets) for r in s.regions] == [(o, n, "bad_crc", 1)]


def test_garbage_over_records(good, split):
    """150 bytes overwritten from the middle of a record: the records they touch are lost, no other."""
    rng = np.random.default_rng(11)
    k = 2000
    a = split[k][0] + split[k][1] // 2
    data = bytearray(good)
    data[a:a + 150] = rng.integers(0, 256, 150, dtype=np.uint8).tobytes()
    hit = {j for j, (o, n) in enumerate(split) if o < a + 150 and o + n > a}
    assert len(hit) >= 2
    recs, s = scan(bytes(data), chunk=1500)
    assert got(recs) == records(good, split, set(range(len(split))) - hit)
    first, last = min(hit), max(hit)
    span = split[last][0] + split[last][1] - split[first][0]
    assert s.n_skipped_bytes == span
    assert s.regions[0].offset == split[first][0]


@pytest.mark.parametrize("jump_s", [3600.0, -3600.0])
def test_time_jump_keeps_every_record(good, split, jump_s):
    k = 500
    data = bytearray(good)
    for o, _ in split[k:]:
        t = struct.unpack_from(">Q", data, o)[0]
        struct.pack_into(">Q", data, o, int(t + jump_s * 1e6))
    recs, s = scan(bytes(data))
    assert len(recs) == len(split) and s.n_skipped_bytes == 0
    assert [r.packet for r in recs] == [good[o + 8:o + n] for o, n in split]
    assert s.n_time_jumps == 1 and s.time_jumps[0].offset == split[k][0]
    assert s.time_jumps[0].jump_s == pytest.approx(jump_s, abs=0.1)


def test_several_damages_and_any_chunking(good, split):
    rng = np.random.default_rng(3)
    data = bytearray(good)
    bad = {100, 4000}
    for k in bad:
        o, _ = split[k]
        data[o + 8 + 11] ^= 0xFF
    o = split[7000][0]
    data[o:o] = bytes(rng.integers(0, 256, 333, dtype=np.uint8))
    cut = split[-1][0] + 20
    data = bytes(data[:cut + 333])
    expect = records(good, split, set(range(len(split) - 1)) - bad)
    for chunk in (None, 1, 16, 777, 65536):
        if chunk == 1:
            data1 = data[:60000]        # byte by byte is slow: the first records only
            recs, s = scan(data1, chunk=1)
            ref, _ = scan(data1)
            assert got(recs) == got(ref)
            continue
        recs, s = scan(data, chunk=chunk)
        assert got(recs) == expect
        assert s.n_skipped_packets == 3 and s.n_regions == 4
        assert s.n_skipped_bytes == sum(split[k][1] for k in bad) + 333 + 20


def test_unknown_message_id_is_a_record_boundary(good, split):
    # a well-framed MAVLink 2 packet of an id outside the common dialect
    payload = b"\x01\x02\x03"
    pkt = bytes([0xFD, len(payload), 0, 0, 0, 1, 1, 0x50, 0xC3, 0x00]) + payload + b"\x12\x34"
    o = split[10][0]
    data = good[:o] + struct.pack(">Q", 1) + pkt + good[o:]
    recs, s = scan(data)
    assert got(recs) == records(good, split, set(range(len(split))))
    assert [(r.kind, r.n_packets, r.n_bytes) for r in s.regions] == [("unknown_id", 1, 8 + len(pkt))]
    assert not s.damaged


@pytest.mark.parametrize("data", [b"", b"\x00" * 5, bytes(range(256)) * 40,
                                  np.random.default_rng(5).integers(0, 256, 50000, dtype=np.uint8).tobytes()])
def test_no_records_no_traceback(data):
    recs, s = scan(data, chunk=1000)
    assert recs == []
    assert s.n_skipped_bytes == len(data)


def test_regions_reported_are_bounded(good, split):
    data = bytearray(good)
    for k in range(0, 3 * MAX_REPORTED, 3):
        data[split[k][0] + 8 + 11] ^= 0xFF
    recs, s = scan(bytes(data))
    assert s.n_regions == MAX_REPORTED and len(s.regions) == MAX_REPORTED
    data2 = bytearray(data)
    for k in range(3 * MAX_REPORTED, 6 * MAX_REPORTED, 3):
        data2[split[k][0] + 8 + 11] ^= 0xFF
    _, s2 = scan(bytes(data2))
    assert s2.n_regions == 2 * MAX_REPORTED and len(s2.regions) == MAX_REPORTED


def test_mavlink1_and_signed_packets(tmp_path):
    from pymavlink.dialects.v10 import common as v1

    m1 = v1.MAVLink(None, srcSystem=3, srcComponent=4)
    p1 = m1.heartbeat_encode(2, 12, 0, 0, 3).pack(m1)
    m2 = mavlink.MAVLink(None, srcSystem=5, srcComponent=6)
    m2.signing.secret_key = bytes(range(32))
    m2.signing.link_id = 1
    m2.signing.timestamp = 1
    m2.signing.sign_outgoing = True
    p2 = m2.heartbeat_encode(2, 12, 0, 0, 3).pack(m2)
    assert p1[0] == 0xFE and p2[0] == 0xFD and p2[2] & 1
    path = tmp_path / "mixed.tlog"
    with TlogWriter(path) as w:
        w.write(p1, 10)
        w.write(p2, 20)
    recs, s = scan(path.read_bytes())
    assert [(r.stamp_us, r.sysid, r.compid, r.msgid, r.packet) for r in recs] == [(10, 3, 4, 0, p1), (20, 5, 6, 0, p2)]
    assert [r.msg.get_type() for r in read_tlog(path)] == ["HEARTBEAT", "HEARTBEAT"]


def test_read_tlog_recovers_around_damage(good, split, tmp_path):
    data = bytearray(good)
    data[split[50][0] + 8 + 12] ^= 1
    path = tmp_path / "d.tlog"
    path.write_bytes(bytes(data))
    assert len(list(read_tlog(path))) == len(split) - 1
    with pytest.raises(ValueError, match="bad_crc"):
        list(read_tlog(path, skip_bad=False))
