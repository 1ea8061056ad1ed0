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

from pymavlink.dialects.v20 import common as mavlink

_TS = struct.Struct(">Q")
_MAGIC_V1 = 0xFE
_MAGIC_V2 = 0xFD


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


def _packet_length(buf: bytes, i: int) -> int:
    """Length of the MAVLink packet starting at ``buf[i]`` (0 if not a packet start)."""
    magic = buf[i]
    if magic == _MAGIC_V2:
        if i + 3 > len(buf):
            return 0
        signed = buf[i + 2] & mavlink.MAVLINK_IFLAG_SIGNED
        return buf[i + 1] + 12 + (mavlink.MAVLINK_SIGNATURE_BLOCK_LEN if signed else 0)
    if magic == _MAGIC_V1:
        if i + 2 > len(buf):
            return 0
        return buf[i + 1] + 8
    return 0


def read_tlog(path: str | Path, skip_bad: bool = True) -> Iterator[TlogRecord]:
    """Iterate over the records of a .tlog file.

    Parameters
    ----------
    path : str or Path
    skip_bad : bool
        Skip a record whose packet does not decode (bad CRC, unknown id)
        instead of raising; a truncated tail ends the iteration quietly.

    Yields
    ------
    TlogRecord
    """
    data = Path(path).read_bytes()
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    i, n = 0, len(data)
    while i + 8 < n:
        (t_us,) = _TS.unpack_from(data, i)
        length = _packet_length(data, i + 8)
        if length == 0 or i + 8 + length > n:
            if length == 0 and skip_bad:
                i += 1  # resynchronise byte by byte on a corrupted record
                continue
            return
        packet = bytearray(data[i + 8:i + 8 + length])
        i += 8 + length
        try:
            msg = parser.decode(packet)
        except Exception:  # noqa: BLE001 - any undecodable packet is "bad"
            if skip_bad:
                continue
            raise
        yield TlogRecord(t_us, msg)
