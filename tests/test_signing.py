"""MAVLink 2 signing (mavcore/link/signing.py): key files as MAVProxy makes
them, signatures checked against pymavlink's own signer and verifier, replay
and lock-out rules."""

from __future__ import annotations

import hashlib

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore.errors import InputError
from mavcore.link.signing import (NEW_STREAM_WINDOW, SignatureVerifier, enable_outgoing_signing, is_signed,
                                  key_from_file_bytes, load_signing_key, sign_packet, signing_timestamp)

KEY = bytes(range(100, 132))
OTHER = bytes(range(1, 33))
T0 = signing_timestamp(1.7e9)


def signed_packets(key, n=3, sysid=1, compid=191, link_id=0, timestamp=T0):
    """``n`` HEARTBEATs signed by pymavlink (an implementation independent of ours)."""
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.signing.secret_key, mav.signing.sign_outgoing = key, True
    mav.signing.link_id, mav.signing.timestamp = link_id, timestamp
    return [bytes(mav.heartbeat_encode(18, 8, 0, 0, 4).pack(mav)) for _ in range(n)]


def test_key_file_raw_and_passphrase_as_mavproxy(tmp_path):
    from MAVProxy.modules.mavproxy_signing import SigningModule

    raw = tmp_path / "raw.key"
    raw.write_bytes(KEY)
    assert load_signing_key(raw) == KEY
    pw = tmp_path / "pass.txt"
    pw.write_text("vine-rows-2022\n")
    # MAVProxy's own conversion (``signing setup vine-rows-2022``), called unbound
    assert load_signing_key(pw) == SigningModule.passphrase_to_key(None, "vine-rows-2022")
    assert load_signing_key(pw) == hashlib.sha256(b"vine-rows-2022").digest()


@pytest.mark.parametrize("data, words", [
    (b"", "empty"), (b"  \n", "empty"), (bytes(range(200, 240)), "not text"), (b"two words\n", "one word"),
])
def test_bad_key_files_are_one_line_errors(tmp_path, data, words):
    f = tmp_path / "k"
    f.write_bytes(data)
    with pytest.raises(InputError) as exc:
        load_signing_key(f)
    assert words in str(exc.value) and "--signing-key" in str(exc.value) and "\n" not in str(exc.value)


def test_missing_directory_or_huge_key_file(tmp_path):
    for p in (tmp_path / "nope", tmp_path):
        with pytest.raises(InputError, match="--signing-key"):
            load_signing_key(p)
    big = tmp_path / "big"
    big.write_bytes(b"a" * 5000)
    with pytest.raises(InputError, match="too long"):
        load_signing_key(big)
    assert key_from_file_bytes(b"  pass\r\n", "k") == hashlib.sha256(b"pass").digest()


def test_verifier_accepts_pymavlink_signatures_and_rejects_others():
    v = SignatureVerifier(KEY, T0)
    good = signed_packets(KEY)
    assert [v.check(p).verdict for p in good] == ["ok", "ok", "ok"]
    assert v.check(good[1]).verdict == "replay"                       # an old timestamp again
    assert v.check(signed_packets(OTHER)[0]).verdict == "bad_signature"
    plain = mavlink.MAVLink(None, 1, 191)
    unsigned = bytes(plain.heartbeat_encode(18, 8, 0, 0, 4).pack(plain))
    assert not is_signed(unsigned) and v.check(unsigned).verdict == "unsigned"
    tampered = bytearray(signed_packets(KEY, timestamp=T0 + 100)[0])
    tampered[12] ^= 1                                                  # payload byte
    assert v.check(bytes(tampered)).verdict == "bad_signature"
    assert v.check(good[0][:-3]).verdict == "malformed"


def test_new_stream_at_most_one_minute_old():
    v = SignatureVerifier(KEY, T0)
    assert v.check(signed_packets(KEY, 1, sysid=7, timestamp=T0 - NEW_STREAM_WINDOW - 1)[0]).verdict == "stale"
    assert v.check(signed_packets(KEY, 1, sysid=8, timestamp=T0 - NEW_STREAM_WINDOW + 10)[0]).verdict == "ok"


def test_forged_future_timestamp_does_not_lock_a_stream_out():
    """pymavlink records a stream's timestamp before checking the signature, so
    one forged packet (wrong key) dated far ahead locks the real sender out;
    here the timestamp counts only once the signature verified."""
    v = SignatureVerifier(KEY, T0)
    assert v.check(signed_packets(KEY, 1, timestamp=T0)[0]).ok
    forged = signed_packets(OTHER, 1, timestamp=T0 + 10**12)[0]     # same stream (link 0, 1/191)
    assert v.check(forged).verdict == "bad_signature"
    assert v.check(signed_packets(KEY, 1, timestamp=T0 + 5)[0]).ok


def test_our_signer_verified_by_pymavlink_and_outgoing_helper():
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    enable_outgoing_signing(mav, KEY, 3, T0)
    p = bytes(mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav))
    assert is_signed(p) and p[-13] == 3
    rx = mavlink.MAVLink(None)
    rx.signing.secret_key = KEY
    m = rx.parse_buffer(p)[0]
    assert m.get_signed()
    # sign_packet (for hand-built packets) gives what pymavlink gives
    unsigned_flagged = bytearray(p[:-13])
    assert sign_packet(KEY, bytes(unsigned_flagged), 3, T0) == p
