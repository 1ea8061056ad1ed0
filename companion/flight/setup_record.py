"""The flight's setup, written into the flight itself (so a .tlog is self-describing).

At connection the companion sends its setup (mission name and file hashes,
plan source, ``--cut``, control mode, runner settings, software version) as
a JSON document in chunked STATUSTEXT messages (MAVLink 2 ``id`` and
``chunk_seq``, severity DEBUG, text prefixed ``cs:``). The vehicle ignores
them (a ground station shows them as debug text); the .tlog records them, and
``companion replay`` reads them back to rebuild the same flight. Pure.
"""

from __future__ import annotations

import json

#: STATUSTEXT id of the setup record ("CS" in ASCII).
SETUP_TEXT_ID = 0x4353
PREFIX = "cs:"
_CHUNK = 50 - len(PREFIX)
MAV_SEVERITY_DEBUG = 7


def setup_chunks(setup: dict) -> list[tuple[bytes, int]]:
    """(text, chunk_seq) pairs: the compact JSON of ``setup`` cut into STATUSTEXT texts.

    The last chunk is shorter than a full one (an empty one if needed), which
    marks the end as MAVLink's chunked STATUSTEXT convention does.
    """
    doc = json.dumps(setup, separators=(",", ":"), sort_keys=True)
    parts = [doc[i:i + _CHUNK] for i in range(0, len(doc), _CHUNK)]
    if not parts or len(parts[-1]) == _CHUNK:
        parts.append("")
    if len(parts) > 256:
        raise ValueError("setup record too long for 256 STATUSTEXT chunks")
    return [((PREFIX + p).encode("ascii"), k) for k, p in enumerate(parts)]


def parse_setup(texts) -> dict | None:
    """The setup from (text, id, chunk_seq) triples of the companion's STATUSTEXTs, or None.

    Raises ValueError when chunks are missing or the JSON is malformed.
    """
    chunks = {}
    end = None
    for text, tid, seq in texts:
        if tid != SETUP_TEXT_ID or not text.startswith(PREFIX):
            continue
        body = text[len(PREFIX):]
        chunks[int(seq)] = body
        if len(body) < _CHUNK:
            end = int(seq)
    if not chunks:
        return None
    if end is None or any(k not in chunks for k in range(end + 1)):
        raise ValueError("incomplete setup record")
    return json.loads("".join(chunks[k] for k in range(end + 1)))
