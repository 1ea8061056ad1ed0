"""Bounded .tlog scanning (issue 19): garbage costs no Python step per byte,
and ``TlogScanner(max_garbage_bytes)`` gives up once that many bytes framed no
record; the records around garbage are the same with or without the cap."""

from __future__ import annotations

import lzma
import time
from pathlib import Path

import pytest

from companion.link.tlog_scan import TlogGarbage, TlogScanner

DATA = Path(__file__).parent / "data" / "replay"


@pytest.fixture(scope="module")
def good() -> bytes:
    return lzma.decompress((DATA / "vehicle-cut4.tlog.xz").read_bytes())


def _scan(data: bytes, cap=None, chunk: int = 1 << 16):
    sc = TlogScanner(cap)
    recs = []
    for i in range(0, len(data), chunk):
        recs += sc.feed(data[i:i + chunk])
    recs += sc.close()
    return recs, sc.summary


def test_garbage_between_records_is_skipped_and_counted(good):
    cut = len(good) // 2
    cut = next(r.offset for r in TlogScanner().feed(good) if r.offset >= cut)
    junk = bytes(100_000) + b"\xfd" * 50_000 + bytes(range(256)) * 100
    whole, _ = _scan(good)
    recs, summary = _scan(good[:cut] + junk + good[cut:], cap=len(junk))
    assert [r.packet for r in recs] == [r.packet for r in whole]
    assert summary.n_skipped_bytes == len(junk) and summary.n_regions == 1


def test_the_cap_counts_every_skipped_byte(good):
    junk = bytes(300_000)
    _scan(junk + good, cap=300_000)
    with pytest.raises(TlogGarbage, match="^300,000 bytes that are no MAVLink record .[0-9,]+ valid records"):
        _scan(junk + good, cap=299_999, chunk=1 << 20)
    with pytest.raises(TlogGarbage, match="bytes that are no MAVLink record .no valid record"):
        _scan(bytes(400_000) + good, cap=299_999, chunk=1 << 16)
    with pytest.raises(TlogGarbage, match="valid records"):
        _scan(good + junk, cap=200_000)


@pytest.mark.parametrize("fill", [b"\0", b"\xfd", b"\xfe\0\0\0", bytes(8) + b"\xfd" + bytes(7)])
def test_garbage_is_scanned_without_a_python_step_per_byte(fill):
    """16 MiB of zeros took 3-4 s at the former 4-5 MB/s; the densest false starts
    (a zero stamp before every magic byte) still need one step per 16 bytes."""
    dense = len(fill) == 16
    data = fill * (((1 if dense else 16) << 20) // len(fill))
    t0 = time.process_time()
    recs, summary = _scan(data, chunk=1 << 20)
    assert time.process_time() - t0 < (4.0 if dense else 1.0)
    assert recs == [] and summary.n_skipped_bytes == len(data)
