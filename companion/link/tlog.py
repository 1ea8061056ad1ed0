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

import errno
import os
import struct
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator


_TS = struct.Struct(">Q")


def open_tlog_file(path: Path):
    """The writer's file (binary, buffered): the one place a .tlog is opened for
    writing, so tests can wrap it (a disk that fills up, a failing device).

    Created or truncated, and opened for appending (O_APPEND): a file that
    somebody truncates behind our back then ends short of what was written
    (``TlogWriter.check``: stopped growing) instead of growing a hole back
    to our offset."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND, 0o666)
    try:
        return open(fd, "wb", buffering=1 << 16)
    except BaseException:
        os.close(fd)
        raise


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

    After ``open``, writing never raises: the first failure (ENOSPC, EIO, a
    file that ``check`` finds deleted, replaced or not growing) is kept in
    ``fault`` (one line naming the file), the file is let go, and later
    packets are counted in ``n_dropped``. The flight loop reads ``fault``
    and treats it like a lost link (``FlightCore.output_fault``): a flight
    must never fall out of the sky because its recording failed.
    """

    def __init__(self, path: str | Path, flush_interval_s: float = 0.5) -> None:
        self.path = Path(path)
        self.flush_interval_s = float(flush_interval_s)
        self._file = None
        self._next_flush = 0.0
        self.n_records = 0
        #: Bytes handed to the file (timestamps and packets).
        self.n_bytes = 0
        #: Packets not recorded after a fault.
        self.n_dropped = 0
        #: The first write failure, one line naming the file; None while all is well.
        self.fault: str | None = None
        self._ident = None

    def open(self) -> "TlogWriter":
        """Create (truncate) the file. Raises OSError: the caller reports it as bad input."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open_tlog_file(self.path)
        try:
            st = os.fstat(self._file.fileno())
            self._ident = (st.st_dev, st.st_ino)
        except (OSError, AttributeError, ValueError):   # a wrapped file without a descriptor
            self._ident = None
        self._next_flush = time.monotonic() + self.flush_interval_s
        return self

    def _fail(self, what: str) -> None:
        """Keep the first fault and let the file go (closing it may fail as well)."""
        if self.fault is None:
            self.fault = f"{self.path}: {what}"
        f, self._file = self._file, None
        if f is not None:
            try:
                f.close()
            except (OSError, ValueError):
                pass

    def _os_fail(self, exc: OSError) -> None:
        name = errno.errorcode.get(exc.errno, "") if exc.errno else ""
        self._fail(f"cannot write: {exc.strerror or exc}" + (f" ({name})" if name else ""))

    def write(self, packet: bytes | bytearray, time_usec: int | None = None) -> None:
        """Record one raw packet; ``time_usec`` defaults to the wall clock now."""
        if self._file is None:
            if self.fault is not None:
                self.n_dropped += 1
            return
        if time_usec is None:
            time_usec = int(time.time() * 1e6)
        try:
            self._file.write(_TS.pack(time_usec) + packet)
        except OSError as exc:
            self.n_dropped += 1
            self._os_fail(exc)
            return
        self.n_records += 1
        self.n_bytes += _TS.size + len(packet)
        self.tick()

    def write_many(self, packets, time_usec: int | None = None) -> None:
        """Record several raw packets with one timestamp (default: now) in one write."""
        if not packets:
            return
        if self._file is None:
            if self.fault is not None:
                self.n_dropped += len(packets)
            return
        if time_usec is None:
            time_usec = int(time.time() * 1e6)
        ts = _TS.pack(time_usec)
        buf = ts + ts.join(packets)    # ts p0 ts p1 ... ts pn
        try:
            self._file.write(buf)
        except OSError as exc:
            self.n_dropped += len(packets)
            self._os_fail(exc)
            return
        self.n_records += len(packets)
        self.n_bytes += len(buf)
        self.tick()

    def flush(self) -> None:
        if self._file is not None:
            try:
                self._file.flush()
            except OSError as exc:
                self._os_fail(exc)

    def tick(self) -> None:
        """Flush if the interval has passed since the last flush. ``write`` flushes
        only when it is called; a caller that may go quiet (no packet for a
        while: a silent link) calls this regularly so that nothing written
        waits in the buffer longer than ``flush_interval_s``."""
        if self._file is not None:
            now = time.monotonic()
            if now >= self._next_flush:
                self.flush()
                self._next_flush = now + self.flush_interval_s

    def check(self) -> str | None:
        """Flush, then check that what was written is on disk: the path still
        names our file (not deleted, its directory not deleted, not replaced
        by another file) and holds every byte written (not truncated: a file
        that stopped growing). Returns ``fault``. A few system calls: the
        runner calls it about once a wall second."""
        if self._file is None:
            return self.fault
        self.flush()
        if self._file is None:
            return self.fault
        try:
            size = os.fstat(self._file.fileno()).st_size
        except (OSError, AttributeError, ValueError):
            size = None
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            self._fail("disappeared during the flight (the file or its directory was deleted)")
            return self.fault
        except OSError as exc:
            self._fail(f"cannot be checked: {exc.strerror or exc}")
            return self.fault
        if self._ident is not None and (st.st_dev, st.st_ino) != self._ident:
            self._fail("was replaced by another file during the flight")
        elif size is not None and size < self.n_bytes:
            self._fail(f"stopped growing: {size} bytes on disk of {self.n_bytes} written")
        return self.fault

    def close(self) -> None:
        if self._file is not None:
            self.flush()
        if self._file is not None:
            f, self._file = self._file, None
            try:
                f.close()
            except OSError as exc:
                self._file = None
                self._os_fail(exc)

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
