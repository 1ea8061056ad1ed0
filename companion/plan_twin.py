"""plan.json's binary twin ``PLAN.json.npz`` (format 2.1, docs/plan-json.md).

A large plan.json (a 10 ha field: 9 MB, 36 000 way-point objects) costs a
flight ~0.4 s of CPU to parse before it starts. ``companion plan`` then also
writes, next to it, the same numbers in binary: an uncompressed NumPy ``.npz``
holding

- ``json_sha256``: the SHA-256 digest of the plan.json bytes it was
  written with;
- ``header``: the plan.json document without its arrays (UTF-8 JSON);
- the arrays: ``path`` (K, 2); the way-points' ``wp_t`` (N,), ``wp_p``,
  ``wp_v``, ``wp_a`` (N, 3), ``wp_corner`` (N,) bool; the trajectory's
  ``traj_t`` (knots) and ``traj_values`` (its ``values``, decoded); the
  sorties' way-points one after the other, ``so_count`` (S,) way-points per
  sortie, ``so_t``, ``so_p``, ``so_v``, ``so_a``.

plan.json stays complete and authoritative: the twin is read only when its
digest is the digest of the plan.json beside it (any edit of plan.json, or a
twin of another plan, and the JSON is parsed as before), and its arrays are
the JSON's numbers converted once (float64 from the same Python floats:
identical values), checked by the same rules as the JSON's. A plan with
``samples`` gets no twin.
"""

from __future__ import annotations

import base64
import hashlib
import io
import json
import zipfile
from pathlib import Path

import numpy as np

from mavcore.errors import PlanError

#: plan.json texts from this size (bytes) get a twin (the 1 ha parcel's is ~1 MB).
TWIN_MIN_BYTES = 2_000_000
SUFFIX = ".npz"
_WP = ("t", "p", "v", "a")


def twin_path(plan_path) -> str:
    """``PLAN.json`` -> ``PLAN.json.npz`` (a suffix added, never replaced: no name clash)."""
    return str(plan_path) + SUFFIX


def digest(data: bytes) -> np.ndarray:
    """(32,) uint8 SHA-256 digest of ``data``."""
    return np.frombuffer(hashlib.sha256(data).digest(), dtype=np.uint8)


def _columns(wps: list) -> dict:
    return {k: np.asarray([w[k] for w in wps], dtype=float).reshape(len(wps), *(() if k == "t" else (3,)))
            for k in _WP}


def twin_bytes(doc: dict, json_bytes: bytes) -> bytes | None:
    """The twin of the plan.json ``doc`` serialised as ``json_bytes``; None when the
    plan gets none (smaller than ``TWIN_MIN_BYTES``, or with ``samples``)."""
    if len(json_bytes) < TWIN_MIN_BYTES or "samples" in doc:
        return None
    header = dict(doc)
    arrays = {"json_sha256": digest(json_bytes), "path": np.asarray(doc["path"], dtype=float).reshape(-1, 2)}
    wps = header.pop("waypoints")
    for k, v in _columns(wps).items():
        arrays["wp_" + k] = v
    arrays["wp_corner"] = np.asarray([w["corner"] for w in wps], dtype=bool)
    del header["path"]
    tr = dict(doc["trajectory"])
    values = dict(tr["values"])
    arrays["traj_t"] = np.asarray(tr.pop("t"), dtype=float)
    arrays["traj_values"] = np.frombuffer(base64.b64decode(values.pop("base64")), dtype=values["dtype"]) \
        .astype(float).reshape(values["shape"])
    tr["values"] = values
    header["trajectory"] = tr
    sorties = header.get("sorties", [])
    cols = [_columns(s["waypoints"]) for s in sorties]
    arrays["so_count"] = np.array([len(s["waypoints"]) for s in sorties], dtype=np.int64)
    for k in _WP:
        tail = () if k == "t" else (3,)
        arrays["so_" + k] = np.concatenate([c[k] for c in cols]) if cols else np.zeros((0, *tail))
    header["sorties"] = [{k: v for k, v in s.items() if k != "waypoints"} for s in sorties]
    arrays["header"] = np.frombuffer(json.dumps(header, allow_nan=False).encode("utf-8"), dtype=np.uint8)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def read_twin(plan_path, json_bytes: bytes, lim=None, json_digest: np.ndarray | None = None) \
        -> tuple[str, dict] | None:
    """(header JSON text, arrays) of the twin of the plan.json at ``plan_path`` whose
    bytes are ``json_bytes``; None without a twin, or with one of other bytes.
    ``json_digest``: ``digest(json_bytes)`` when the caller has it already.

    Raises
    ------
    PlanError
        The twin is unreadable or not a twin (naming the ``.npz`` file).
    """
    from mavcore.inputs import read_bytes

    path = twin_path(plan_path)
    if not Path(path).exists():
        return None
    data = read_bytes(path, PlanError, "plan twin", cap="plan_bytes", lim=lim)
    try:
        # np.savez stores its entries: a compressed one (a decompression bomb) is not a twin
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            if any(i.compress_type != zipfile.ZIP_STORED or i.file_size > len(data) for i in zf.infolist()):
                raise PlanError(path, "not a plan twin (.npz): compressed or oversized entries")
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as exc:
        raise PlanError(path, f"not a plan twin (.npz): {exc}") from None
    stamp = arrays.get("json_sha256")
    if json_digest is None:
        json_digest = digest(json_bytes)
    if stamp is None or stamp.dtype != np.uint8 or not np.array_equal(stamp, json_digest):
        return None
    header = arrays.pop("header", None)
    if header is None or header.dtype != np.uint8 or header.ndim != 1:
        raise PlanError(f"{path}: key 'header'", "missing or not UTF-8 bytes")
    try:
        text = header.tobytes().decode("utf-8")
    except UnicodeDecodeError:
        raise PlanError(f"{path}: key 'header'", "not UTF-8 text") from None
    for k in ("path", "traj_t", "traj_values", "so_count", "wp_corner",
              *("wp_" + c for c in _WP), *("so_" + c for c in _WP)):
        if k not in arrays:
            raise PlanError(f"{path}: key '{k}'", "missing")
    return text, arrays
