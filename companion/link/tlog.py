"""Telemetry logs (.tlog) in pymavlink's format, written and read.

A .tlog is a sequence of records: a big-endian uint64 timestamp (microseconds
since the Unix epoch, as pymavlink/MAVProxy write it) followed by one raw
MAVLink packet (v1 or v2, signature included). The time stamp is the caller's
(the runner maps the vehicle clock onto the wall time of the flight start,
docs/tlog.md), else the wall clock. The recorder logs both
directions and flushes by wall clock at least once a second and on close, so
a crash loses at most the last second. pymavlink's ``mavutil.mavlink_connection``
reads these files; ``read_tlog`` here is a dependency-light reader for replay.
"""

from __future__ import annotations

import struct
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator


_TS = struct.Struct(">Q")


class TlogWriter:
    """Append MAVLink packets to a .tlog file.

    Parameters
    ----------
    path : str or Path
        Output file (created or truncated by ``open``).
    flush_interval_s : float
        Longest wall-clock time between flushes (<= 1 s, docs/tlog.md).

    Notes
    -----
    The constructor does no I/O; ``open`` (or ``with``) creates the file.
    """

    def __init__(self, path: str | Path, flush_interval_s: float = 0.5) -> None:
        self.path = Path(path)
        self.flush_interval_s = float(flush_interval_s)
        self._file = None
        self._next_flush = 0.0
        self.n_records = 0

    def open(self) -> "TlogWriter":
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb", buffering=1 << 16)
        self._next_flush = time.monotonic() + self.flush_interval_s
        return self

    def write(self, packet: bytes | bytearray, time_usec: int | None = None) -> None:
        """Record one raw packet; ``time_usec`` defaults to the wall clock now."""
        if self._file is None:
            return
        if time_usec is None:
            time_usec = int(time.time() * 1e6)
        self._file.write(_TS.pack(time_usec))
        self._file.write(packet)
        self.n_records += 1
        now = time.monotonic()
        if now >= self._next_flush:
            self._file.flush()
            self._next_flush = now + self.flush_interval_s

    def write_many(self, packets, time_usec: int | None = None) -> None:
        """Record several raw packets with one timestamp (default: now) in one write."""
        if self._file is None or not packets:
            return
        if time_usec is None:
            time_usec = int(time.time() * 1e6)
        ts = _TS.pack(time_usec)
        self._file.write(ts + ts.join(packets))   # ts p0 ts p1 ... ts pn
        self.n_records += len(packets)
        now = time.monotonic()
        if now >= self._next_flush:
            self._file.flush()
            self._next_flush = now + self.flush_interval_s

    def flush(self) -> None:
        if self._file is not None:
            self._file.flush()

    def tick(self) -> None:
        """Flush if the interval has passed since the last flush. ``write`` flushes
        only when it is called; a caller that may go quiet (no packet for a
        while: a silent link) calls this regularly so that nothing written
        waits in the buffer longer than ``flush_interval_s``."""
        if self._file is not None:
            now = time.monotonic()
            if now >= self._next_flush:
                self._file.flush()
                self._next_flush = now + self.flush_interval_s

    def close(self) -> None:
        if self._file is not None:
            self._file.flush()
            self._file.close()
            self._file = None

    def __enter__(self) -> "TlogWriter":
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()


@dataclass(frozen=True)
class TlogRecord:
    """One .tlog record: wall-clock timestamp (us since epoch) and the decoded message."""

    time_usec: int
    msg: object


def read_tlog(path: str | Path, skip_bad: bool = True) -> Iterator[TlogRecord]:
    """Iterate over the records of a .tlog file (read in chunks: memory does not
    grow with the file).

    Framing, CRC checks and resynchronisation are ``companion.link.tlog_scan``'s:
    a damaged region is skipped and every valid record before and after it is
    returned.

    Parameters
    ----------
    path : str or Path
    skip_bad : bool
        Skip damaged regions (bad CRC, garbage, a truncated tail) quietly;
        False: raise ValueError at the first one.

    Yields
    ------
    TlogRecord
        The per-frame telemetry types as ``codec.FastMessage`` (fields by
        name, like pymavlink's), the others as pymavlink messages.
    """
    from .tlog_scan import TlogScanner, decode_record, new_decoder

    scanner = TlogScanner()
    dec = new_decoder()

    def out(records):
        if not skip_bad and scanner.summary.n_regions:
            r = scanner.summary.regions[0]
            raise ValueError(f"{path}: {r.kind} at byte {r.offset} ({r.n_bytes} bytes)")
        for rec in records:
            msg = decode_record(rec, dec)
            if msg is None:
                if not skip_bad:
                    raise ValueError(f"{path}: undecodable packet at byte {rec.offset}")
                continue
            yield TlogRecord(rec.stamp_us, msg)

    with open(path, "rb") as f:
        while True:
            chunk = f.read(1 << 20)
            if not chunk:
                break
            yield from out(scanner.feed(chunk))
    yield from out(scanner.close())
