"""MAVLink 2 message signing: the key file, outgoing signing, incoming checks.

The signature of a MAVLink 2 packet (mavlink.io, "Message Signing") is 13
bytes appended after the CRC when ``incompat_flags & 1``: link id (1 byte),
timestamp (6 bytes, little endian, units of 10 us since 2015-01-01 00:00 UTC)
and ``SHA-256(secret_key + packet up to and including the timestamp)[:6]``.

Both sides use this module: the SITL (``sitl --signing-key``) and the
companion (``companion fly/demo --signing-key``).

Key file
    Exactly 32 bytes: the raw key. Anything else is a text passphrase
    (UTF-8, surrounding white space and the line end stripped) hashed with
    SHA-256, as MAVProxy's ``signing setup PASSPHRASE`` does
    (``MAVProxy/modules/mavproxy_signing.py``: ``passphrase_to_key``), so a
    MAVProxy user with the same passphrase talks to us. A 32-character
    passphrase must therefore end with a newline (as an editor writes it).

Incoming checks (``SignatureVerifier``)
    The rules of pymavlink's ``MAVLink.check_signature`` in the order the
    specification gives: a packet is accepted only if its signature verifies
    with the key, and then only if its timestamp is newer than the last
    accepted one of its stream (link id, system id, component id), or, for
    a stream not seen before, at most one minute older than our own
    timestamp. The stream's timestamp is updated only after the signature
    verified: pymavlink updates it before checking, so one forged packet with
    a timestamp far in the future locks a legitimate stream out (tested).
"""

from __future__ import annotations

import hashlib
import struct
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError

KEY_BYTES = 32
#: Unix time of the signing epoch, 2015-01-01 00:00:00 UTC.
SIGNING_EPOCH_UNIX_S = 1420070400
#: Signature block: link id, 48-bit timestamp, 48-bit signature.
SIGNATURE_BYTES = 13
#: A new stream may start at most this far behind our timestamp (10 us units: one minute).
NEW_STREAM_WINDOW = 6_000_000
IFLAG_SIGNED = 0x01
_TS48 = struct.Struct("<IH")


def key_from_file_bytes(data: bytes, source: str) -> bytes:
    """The 32-byte secret key held by a key file's contents (see the module docstring).

    Raises
    ------
    InputError
        Empty, or neither 32 raw bytes nor a text passphrase.
    """
    if len(data) == KEY_BYTES:
        return bytes(data)
    try:
        text = data.decode("utf-8").strip()
    except UnicodeDecodeError:
        raise InputError(source, f"a signing key file holds 32 raw bytes or a text passphrase "
                                 f"(got {len(data)} bytes that are not text)") from None
    if not text:
        raise InputError(source, "empty signing key file (32 raw bytes or a text passphrase)")
    if any(c.isspace() for c in text) or "\0" in text:
        raise InputError(source, "the signing passphrase must be one word (MAVProxy's signing setup "
                                 "takes one)")
    return passphrase_to_key(text)


def passphrase_to_key(passphrase: str) -> bytes:
    """SHA-256 of the passphrase's UTF-8 bytes (MAVProxy's ``passphrase_to_key``)."""
    return hashlib.sha256(passphrase.encode("utf-8")).digest()


def load_signing_key(path: str | Path, option: str = "--signing-key") -> bytes:
    """Read a key file (``option PATH`` names it in errors).

    Raises
    ------
    InputError
        Missing, unreadable, or not a key (one line naming the option and file).
    """
    from ..inputs import name, open_regular

    source = f"{option} {name(path)}"
    try:
        f = open_regular(path, InputError, "key file")
    except InputError as exc:
        raise InputError(source, exc.problem) from None
    try:
        with f:
            data = f.read(4097)
    except OSError as exc:
        raise InputError(source, f"cannot read: {exc.strerror or exc}") from None
    if len(data) > 4096:
        raise InputError(source, "too long for a signing key file (32 raw bytes or a passphrase)")
    return key_from_file_bytes(data, source)


def signing_timestamp(unix_time_s: float) -> int:
    """A signing timestamp (10 us units since 2015-01-01 UTC) for a Unix time."""
    return max(0, int((unix_time_s - SIGNING_EPOCH_UNIX_S) * 100_000))


def enable_outgoing_signing(mav, key: bytes, link_id: int, timestamp: int) -> None:
    """Make pymavlink's ``MAVLink`` object ``mav`` sign every packet it packs.

    Only for packing: a parser that must check signatures with our rules
    (``SignatureVerifier``) is a separate ``MAVLink`` object without a key.
    """
    if len(key) != KEY_BYTES:
        raise ValueError("a signing key has 32 bytes")
    s = mav.signing
    s.secret_key = bytes(key)
    s.link_id = int(link_id) & 0xFF
    s.timestamp = int(timestamp)
    s.sign_outgoing = True
    s.allow_unsigned_callback = None


def disable_outgoing_signing(mav) -> None:
    s = mav.signing
    s.secret_key = None
    s.sign_outgoing = False
    s.allow_unsigned_callback = None


def is_signed(packet: bytes) -> bool:
    """True if ``packet`` is a MAVLink 2 packet with the signed flag."""
    return len(packet) > 2 and packet[0] == 0xFD and bool(packet[2] & IFLAG_SIGNED)


def signature_of(key: bytes, signed_part: bytes) -> bytes:
    """The 6-byte signature of a packet's bytes up to and including its timestamp."""
    return hashlib.sha256(bytes(key) + bytes(signed_part)).digest()[:6]


def sign_packet(key: bytes, unsigned_packet: bytes, link_id: int, timestamp: int) -> bytes:
    """Append a signature block to a packet packed with the signed flag already set
    (for tests and tools that build packets by hand)."""
    part = bytes(unsigned_packet) + bytes((link_id & 0xFF,)) + _TS48.pack(timestamp & 0xFFFFFFFF,
                                                                       (timestamp >> 32) & 0xFFFF)
    return part + signature_of(key, part)


@dataclass(frozen=True)
class SignatureCheck:
    """Outcome of checking one incoming packet.

    Attributes
    ----------
    verdict : str
        ``ok``; ``unsigned`` (no signature); ``bad_signature`` (does not
        verify with the key); ``replay`` (timestamp not newer than the
        stream's last accepted one); ``stale`` (a new stream more than one
        minute behind our timestamp); ``malformed`` (too short to hold one).
    timestamp : int or None
        The packet's signing timestamp (10 us units) when it has one.
    """

    verdict: str
    timestamp: int | None = None

    @property
    def ok(self) -> bool:
        return self.verdict == "ok"


_UNSIGNED = SignatureCheck("unsigned")
_MALFORMED = SignatureCheck("malformed")


class SignatureVerifier:
    """Checks signatures of incoming packets against one key (no I/O).

    Parameters
    ----------
    key : bytes
        The 32-byte secret key.
    timestamp : int
        Our current signing timestamp (``signing_timestamp(time.time())`` at
        start): new streams must be at most one minute older. It follows the
        newest accepted timestamp, as pymavlink's does.

    Notes
    -----
    Memory: one entry per stream that sent a correctly signed packet (only
    holders of the key can add one).
    """

    def __init__(self, key: bytes, timestamp: int = 0) -> None:
        if len(key) != KEY_BYTES:
            raise ValueError("a signing key has 32 bytes")
        self.key = bytes(key)
        self.timestamp = int(timestamp)
        self._streams: dict[tuple[int, int, int], int] = {}

    def check(self, packet: bytes) -> SignatureCheck:
        """Check one whole packet (header to signature, as received)."""
        if not is_signed(packet):
            return _UNSIGNED
        n = len(packet)
        if n < 12 + SIGNATURE_BYTES or n != 12 + packet[1] + SIGNATURE_BYTES:
            return _MALFORMED
        lo, hi = _TS48.unpack_from(packet, n - 12)
        ts = lo | hi << 32
        if signature_of(self.key, packet[:n - 6]) != bytes(packet[n - 6:]):
            return SignatureCheck("bad_signature", ts)
        stream = (packet[n - 13], packet[5], packet[6])
        last = self._streams.get(stream)
        if last is not None:
            if ts <= last:
                return SignatureCheck("replay", ts)
        elif ts + NEW_STREAM_WINDOW < self.timestamp:
            return SignatureCheck("stale", ts)
        self._streams[stream] = ts
        if ts > self.timestamp:
            self.timestamp = ts
        return SignatureCheck("ok", ts)
