"""Robust, incremental framing of .tlog bytes (pymavlink's format), pure.

A .tlog is a sequence of records: a big-endian uint64 time stamp (us since
the Unix epoch) followed by one raw MAVLink packet (v1 or v2, signature
included). ``TlogScanner`` takes the bytes in chunks of any size (``feed``,
then ``close``) and returns the valid records with their file offsets, so a
caller reads a file of any length holding one chunk at a time.

A record counts as valid when its packet frames (magic byte, length within
the data) and its CRC-16/MCRF4XX checks with the message's CRC_EXTRA (the
common dialect). Whatever does not is skipped a byte at a time until the next
valid record, and reported as a ``SkippedRegion`` (offset, bytes, kind):

- ``bad_crc``: one well-framed record whose CRC fails (a flipped bit);
- ``truncated``: the file ends inside a record;
- ``unknown_id``: one well-framed record of a message id outside the common
  dialect (its CRC cannot be checked; it is accepted as a record boundary
  only when a valid record or the end of the file follows it);
- ``garbage``: bytes that frame no record (``bad_crc+garbage``: a record
  whose CRC fails, then more such bytes; a tail of fewer than 16 bytes is
  ``truncated``).

A false start inside garbage needs the magic byte, a known message id and a
matching 16-bit CRC at once (about 1 in 10^7 per byte for MAVLink 2), so the
records before and after a damaged region are all recovered. Time stamps do
not take part in the framing: a stamp that goes back by more than
``JUMP_BACK_S`` or forward by more than ``JUMP_FORWARD_S`` from the previous
record is reported as a ``TimeJump`` and the record is kept.

Memory: the scanner holds one chunk and at most ``MAX_REPORTED`` regions and
jumps (the totals count them all).
"""

from __future__ import annotations

import bisect
import struct
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from mavcore.codec import FAST_DECODERS, x25_crc

try:   # the C implementation (codec uses it too)
    from fastcrc import crc16 as _fastcrc16
    _crc = _fastcrc16.mcrf4xx
except ImportError:   # pragma: no cover - pymavlink's pure Python CRC
    def _crc(data, _init):
        return x25_crc(data)

_STAMP = struct.Struct(">Q")
_V1, _V2 = 0xFE, 0xFD
_SIGNED = mavlink.MAVLINK_IFLAG_SIGNED
_SIG_LEN = mavlink.MAVLINK_SIGNATURE_BLOCK_LEN
#: CRC_EXTRA byte (as a 1-byte ``bytes``) of every message id of the common dialect.
#: Plausible .tlog stamps (us since the Unix epoch, or since boot): up to 2200-01-01. A
#: record stamped later is garbage in front of a packet (random stamps fall below this
#: bound once in 2500).
STAMP_MIN_US = 0
STAMP_MAX_US = 7_258_118_400 * 10**6
_CRC_EXTRA = {mid: bytes((cls.crc_extra,)) for mid, cls in mavlink.mavlink_map.items()}

#: Stamp steps reported as time jumps (s): backwards by more, or forwards by more.
JUMP_BACK_S = 0.5
JUMP_FORWARD_S = 60.0
#: Regions and jumps kept for the report (the totals count every one).
MAX_REPORTED = 100


class RawRecord(NamedTuple):
    """One valid .tlog record, not yet decoded.

    Attributes
    ----------
    stamp_us : int
        The record's time stamp (us since the Unix epoch, as written).
    offset : int
        Byte offset of the record (its stamp) in the file.
    msgid, sysid, compid : int
        MAVLink message id, source system and component.
    packet : bytes
        The raw MAVLink packet (header to CRC, signature included).
    """

    stamp_us: int
    offset: int
    msgid: int
    sysid: int
    compid: int
    packet: bytes

    def payload(self) -> bytes:
        """The payload bytes (MAVLink 2: zero-truncated as sent)."""
        p = self.packet
        h = 10 if p[0] == _V2 else 6
        return p[h:h + p[1]]


@dataclass(frozen=True)
class SkippedRegion:
    """Bytes of the file that hold no valid record.

    Attributes
    ----------
    offset : int
        First byte skipped (file offset).
    n_bytes : int
    kind : str
        ``bad_crc``, ``truncated``, ``unknown_id``, ``garbage`` or ``bad_crc+garbage``
        (module docstring).
    n_packets : int
        Well-framed packets lost in the region (1 for bad_crc, truncated and
        unknown_id, 0 for garbage).
    after_stamp_us : int or None
        Stamp of the last valid record before the region (None at the start).
    """

    offset: int
    n_bytes: int
    kind: str
    n_packets: int
    after_stamp_us: int | None

    def to_dict(self) -> dict:
        return {"offset": self.offset, "n_bytes": self.n_bytes, "kind": self.kind, "n_packets": self.n_packets,
                "after_stamp_us": self.after_stamp_us}


@dataclass(frozen=True)
class TimeJump:
    """A record whose stamp jumps from the previous record's (kept: only reported).

    Attributes
    ----------
    offset : int
        File offset of the record after the jump.
    from_stamp_us, to_stamp_us : int
    """

    offset: int
    from_stamp_us: int
    to_stamp_us: int

    @property
    def jump_s(self) -> float:
        return (self.to_stamp_us - self.from_stamp_us) * 1e-6

    def to_dict(self) -> dict:
        return {"offset": self.offset, "from_stamp_us": self.from_stamp_us, "to_stamp_us": self.to_stamp_us,
                "jump_s": self.jump_s}


@dataclass
class ScanSummary:
    """What ``TlogScanner`` found so far (totals over the whole file).

    Attributes
    ----------
    n_bytes : int
        Bytes scanned.
    n_records : int
        Valid records returned.
    n_skipped_bytes, n_skipped_packets : int
        Totals over every skipped region (``unknown_id`` ones included).
    n_regions, n_time_jumps : int
    regions : list of SkippedRegion
        The first ``MAX_REPORTED``.
    time_jumps : list of TimeJump
        The first ``MAX_REPORTED``.
    first_stamp_us, last_stamp_us : int or None
        Stamps of the first and last valid records.
    """

    n_bytes: int = 0
    n_records: int = 0
    n_skipped_bytes: int = 0
    n_skipped_packets: int = 0
    n_regions: int = 0
    n_time_jumps: int = 0
    regions: list = field(default_factory=list)
    time_jumps: list = field(default_factory=list)
    first_stamp_us: int | None = None
    last_stamp_us: int | None = None

    @property
    def damaged(self) -> bool:
        """Anything other than unknown-id records was skipped, or a stamp jumped."""
        return self.n_time_jumps > 0 or any(r.kind != "unknown_id" for r in self.regions) \
            or self.n_regions > len(self.regions)

    def to_dict(self) -> dict:
        return {"n_bytes": self.n_bytes, "n_records": self.n_records, "n_skipped_bytes": self.n_skipped_bytes,
                "n_skipped_packets": self.n_skipped_packets, "n_regions": self.n_regions,
                "n_time_jumps": self.n_time_jumps, "regions": [r.to_dict() for r in self.regions],
                "time_jumps": [j.to_dict() for j in self.time_jumps]}


class TlogGarbage(ValueError):
    """More bytes that frame no valid record than the scanner's cap (``max_garbage_bytes``).

    Attributes
    ----------
    n_bytes : int
        Such bytes so far (all runs together).
    n_records : int
        Valid records so far.
    """

    def __init__(self, n_bytes: int, n_records: int) -> None:
        found = "no valid record" if n_records == 0 else f"{n_records:,} valid records"
        super().__init__(f"{n_bytes:,} bytes that are no MAVLink record ({found})")
        self.n_bytes, self.n_records = n_bytes, n_records


class TlogScanner:
    """Incremental .tlog framing (see the module docstring).

    ``feed(chunk)`` returns the records completed by ``chunk``; ``close()``
    returns the last ones and reports a truncated tail. ``summary`` holds the
    totals. Pure: bytes in, records out.
    """

    def __init__(self, max_garbage_bytes: int | None = None) -> None:
        self.max_garbage_bytes = max_garbage_bytes
        self.summary = ScanSummary()
        self._buf = b""
        self._base = 0            # file offset of self._buf[0]
        self._bad_start = None    # file offset where the current bad run began
        self._bad_kind = None     # ("bad_crc"|"unknown_id"|"truncated", end offset) of a framed record there
        self._last_stamp = None
        self._closed = False

    # --- public ------------------------------------------------------------------

    def feed(self, data: bytes) -> list:
        """Records completed by ``data`` (the next bytes of the file), in file order."""
        if self._closed:
            raise ValueError("TlogScanner: feed() after close()")
        if not data:
            return []
        self.summary.n_bytes += len(data)
        buf = self._buf + bytes(data) if self._buf else bytes(data)
        out, used = self._scan(buf, final=False)
        self._buf = buf[used:]
        self._base += used
        self._check_garbage(self._base + len(self._buf))
        return out

    def close(self) -> list:
        """The last records; whatever is left is a truncated record or garbage."""
        if self._closed:
            return []
        self._closed = True
        out, used = self._scan(self._buf, final=True)
        rest = len(self._buf) - used
        if rest:
            self._bad_begin(self._base + used)
            self._close_bad(self._base + len(self._buf), eof=True)
        elif self._bad_start is not None:
            self._close_bad(self._base + used, eof=True)
        self._buf = b""
        return out

    def _check_garbage(self, end_offset: int) -> None:
        """``TlogGarbage`` once more bytes than ``max_garbage_bytes`` were skipped in all."""
        cap = self.max_garbage_bytes
        if cap is None:
            return
        start = self._bad_start
        if start is None and self.summary.n_records == 0:
            start = 0
        run = 0 if start is None else end_offset - start
        if self.summary.n_skipped_bytes + run > cap:
            raise TlogGarbage(self.summary.n_skipped_bytes + run, self.summary.n_records)

    # --- framing -----------------------------------------------------------------

    def _scan(self, buf: bytes, final: bool):
        """(records, bytes consumed) of ``buf``; stops before an incomplete record unless ``final``."""
        out = []
        n = len(buf)
        i = 0
        base = self._base
        extras = _CRC_EXTRA
        crc = _crc
        unpack = _STAMP.unpack_from
        summary = self.summary
        append = out.append
        new_record = tuple.__new__          # RawRecord without its Python-level __new__ (per record)
        cand = _candidates(buf).tolist()
        n_cand = len(cand)
        search = bisect.bisect_right
        while i + 16 <= n:   # stamp (8) + the shortest packet (v1, empty payload: 8)
            h = _header(buf, i) if buf[i] <= _STAMP_TOP else None
            if h is None:                      # no record starts here: on to the next candidate
                self._mark_framed(i, None, 0)
                k = search(cand, i)
                i = min(cand[k] if k < n_cand else n, max(n - 15, i + 1))
                continue
            if h is _MORE:
                break
            end, crc_end, msgid, ids, odd_flags = h
            if end > n:
                if final:
                    self._mark_framed(i, "truncated", end)
                    k = search(cand, i)          # the bytes up to the next candidate start no record
                    i = min(cand[k] if k < n_cand else n, max(n - 15, i + 1))
                    continue
                break
            extra = extras.get(msgid)
            if extra is None or odd_flags:
                ok = self._unknown_boundary(buf, i, end, final)
                if ok is None:
                    break
                i = self._skip_unknown(i, end) if ok else self._skip_byte(i)
                continue
            if crc(buf[i + 9:crc_end - 2] + extra, 0xFFFF) != (buf[crc_end - 2] | buf[crc_end - 1] << 8):
                self._mark_framed(i, "bad_crc", end)
                k = search(cand, i)
                i = min(cand[k] if k < n_cand else n, max(n - 15, i + 1))
                continue
            (stamp,) = unpack(buf, i)
            if not STAMP_MIN_US <= stamp <= STAMP_MAX_US:
                # A 16-bit CRC passes on one random frame in 65536: a packet-looking
                # run of garbage is also told by a time stamp no log can carry.
                self._mark_framed(i, None, 0)
                k = search(cand, i)
                i = min(cand[k] if k < n_cand else n, max(n - 15, i + 1))
                continue
            sysid, compid = buf[ids], buf[ids + 1]
            # a valid record
            if self._bad_start is not None:
                self._close_bad(base + i)
            last = self._last_stamp
            if last is None:
                summary.first_stamp_us = stamp
            elif stamp < last - JUMP_BACK_S * 1e6 or stamp > last + JUMP_FORWARD_S * 1e6:
                summary.n_time_jumps += 1
                if len(summary.time_jumps) < MAX_REPORTED:
                    summary.time_jumps.append(TimeJump(base + i, last, stamp))
            self._last_stamp = stamp
            append(new_record(RawRecord, (stamp, base + i, msgid, sysid, compid, buf[i + 8:end])))
            i = end
        summary.n_records += len(out)
        if out:
            summary.last_stamp_us = self._last_stamp
        return out, i

    def _unknown_boundary(self, buf: bytes, i: int, end: int, final: bool):
        """Whether a framed record of unknown id at ``i`` ends where a valid one
        (or the file) begins: True/False, None when more data is needed."""
        if end == len(buf):
            return True if final else None
        return _valid_at(buf, end, final)

    # --- damage bookkeeping ----------------------------------------------------------

    def _skip_byte(self, i: int) -> int:
        self._mark_framed(i, None, 0)
        return i + 1

    def _skip_unknown(self, i: int, end: int) -> int:
        """A framed record of unknown id at ``i`` (ending at ``end``): its own region."""
        if self._bad_start is not None:
            self._close_bad(self._base + i)
        self._mark_framed(i, "unknown_id", end)
        self._close_bad(self._base + end)
        return end

    def _bad_begin(self, offset: int) -> None:
        if self._bad_start is None:
            self._bad_start = offset
            self._bad_kind = None

    def _mark_framed(self, i: int, kind: str | None, end: int) -> None:
        """Byte ``i`` of the buffer is skipped; ``kind`` says whether a framed
        (but invalid) record starts there (noted only at the start of a run)."""
        off = self._base + i
        if self._bad_start is None:
            self._bad_start = off
            self._bad_kind = None if kind is None or kind == "garbage" else (kind, self._base + end)

    def _close_bad(self, end_offset: int, eof: bool = False) -> None:
        start = self._bad_start
        if start is None:
            return
        n = end_offset - start
        kind, n_packets = "garbage", 0
        framed = self._bad_kind
        if framed is not None:
            k, rec_end = framed
            if k == "truncated" and eof:
                kind, n_packets = "truncated", 1
            elif rec_end == end_offset and k in ("bad_crc", "unknown_id"):
                kind, n_packets = k, 1
            elif rec_end <= end_offset and k == "bad_crc":
                # a damaged record followed by garbage
                kind, n_packets = "bad_crc+garbage", 1
        if eof and kind == "garbage" and n > 0 and framed is None:
            kind = "truncated" if n < 16 else "garbage"
            n_packets = 1 if kind == "truncated" else 0
        s = self.summary
        s.n_regions += 1
        s.n_skipped_bytes += n
        s.n_skipped_packets += n_packets
        if len(s.regions) < MAX_REPORTED:
            s.regions.append(SkippedRegion(start, n, kind, n_packets, self._last_stamp))
        self._bad_start = None
        self._bad_kind = None


#: Largest first byte of a plausible stamp (big-endian, <= STAMP_MAX_US).
_STAMP_TOP = STAMP_MAX_US >> 56


def _candidates(buf: bytes) -> np.ndarray:
    """Offsets where a record could start: a magic byte 8 bytes on and a plausible
    first stamp byte (vectorised, so garbage costs no Python step per byte)."""
    a = np.frombuffer(buf, dtype=np.uint8)
    if a.size < 9:
        return np.zeros(0, dtype=np.intp)
    magic = a[8:]
    return np.flatnonzero(((magic == _V2) | (magic == _V1)) & (a[:-8] <= _STAMP_TOP))


#: ``_header``'s answer when the buffer ends inside the header.
_MORE = ()


def _header(buf: bytes, i: int):
    """The framing of a record at ``buf[i]`` (stamp first): (end, CRC end, message id,
    offset of the system id, flags this reader cannot parse); None when no packet
    starts there; ``_MORE`` when the header runs past the buffer. Needs i + 16 <= len."""
    magic = buf[i + 8]
    if magic == _V2:
        if i + 18 > len(buf):
            return _MORE
        iflags = buf[i + 10]
        crc_end = i + 20 + buf[i + 9]
        return (crc_end + (_SIG_LEN if iflags & _SIGNED else 0), crc_end,
                buf[i + 15] | buf[i + 16] << 8 | buf[i + 17] << 16, i + 13, iflags & ~_SIGNED)
    if magic == _V1:
        end = i + 16 + buf[i + 9]
        return end, end, buf[i + 13], i + 11, 0
    return None


def _valid_at(buf: bytes, i: int, final: bool):
    """Whether a valid (CRC-checked) record starts at ``buf[i]``; None when
    the buffer ends before that can be told (and more data may come)."""
    if i + 16 > len(buf):
        return False if final else None
    h = _header(buf, i)
    if h is None:
        return False
    if h is _MORE:
        return False if final else None
    end, crc_end, msgid, _ids, odd = h
    if end > len(buf):
        return False if final else None
    extra = _CRC_EXTRA.get(msgid)
    if extra is None or odd or not STAMP_MIN_US <= _STAMP.unpack_from(buf, i)[0] <= STAMP_MAX_US:
        return False
    return _crc(buf[i + 9:crc_end - 2] + extra, 0xFFFF) == (buf[crc_end - 2] | buf[crc_end - 1] << 8)


def decode_record(rec: RawRecord, mav, decoders=FAST_DECODERS):
    """The message of a record: a ``codec.FastMessage`` for the types of
    ``decoders`` (MAVLink 2; default: the per-frame types, decoded as the live
    link decodes them), else pymavlink's (``mav``: a ``MAVLink`` object used
    as a decoder); None when pymavlink cannot decode it."""
    p = rec.packet
    if p[0] == _V2:
        dec = decoders.get(rec.msgid)
        if dec is not None:
            return dec.decode(p, p[10:10 + p[1]], rec.sysid, rec.compid)
    try:
        return mav.decode(bytearray(p))
    except Exception:  # noqa: BLE001 - pymavlink raises several types on odd packets
        return None


def new_decoder():
    """A pymavlink ``MAVLink`` object for ``decode_record`` (no file, no signing)."""
    m = mavlink.MAVLink(None)
    m.robust_parsing = True
    return m
