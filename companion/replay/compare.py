"""Compare what the companion computes with what it sent (pure).

An output is identical when its MAVLink 2 payload is byte for byte the
recorded one: same message id, every field on the wire equal, float32 fields
bit for bit (so -0.0 differs from 0.0 and NaN payloads count). With a
tolerance ``tol > 0`` a payload that differs is decoded and passes when every
float field is within ``tol`` (its own unit) or NaN on both sides, and every
integer and text field is equal.

``field_values`` decodes a payload into named fields (arrays split as
``controls[2]``) with pymavlink's message definitions; the sequence number,
signature and CRC are not compared (the runner's link numbers packets).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from ..flight.core import ActuatorOut
from ..link import codec

HIL_ACTUATOR_CONTROLS_ID = mavlink.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS


@dataclass(frozen=True)
class Difference:
    """The first field that differs between a computed and a recorded output.

    ``field`` is None when the message types differ (``recorded_value`` and
    ``computed_value`` are then the type names).
    """

    field: str | None
    recorded_value: object
    computed_value: object


def message_name(msgid: int) -> str:
    cls = mavlink.mavlink_map.get(msgid)
    return cls.msgname if cls is not None else f"MSG{msgid}"


def computed_payload(out, mav) -> tuple[int, bytes]:
    """(message id, MAVLink 2 payload as sent) of a ``FlightCore`` output
    (``ActuatorOut`` or a pymavlink message; ``mav`` packs the latter)."""
    if type(out) is ActuatorOut:
        return HIL_ACTUATOR_CONTROLS_ID, codec.hil_actuator_controls_payload(out.time_usec, out.motor_cmd,
                                                                             out.armed)
    buf = out.pack(mav)
    return out.get_msgId(), bytes(buf[10:10 + buf[1]])


def field_values(msgid: int, payload: bytes) -> list:
    """[(name, value), ...] of a payload in the message's declared field
    order; arrays of numbers expand to ``name[i]``, text stays one value."""
    cls = mavlink.mavlink_map[msgid]
    size = cls.unpacker.size
    payload = payload[:size] + bytes(max(0, size - len(payload)))
    flat = cls.unpacker.unpack(payload)
    by_name = {}
    i = 0
    for name, n in zip(cls.ordered_fieldnames, cls.array_lengths):
        fmt_is_text = cls.fieldtypes[cls.fieldnames.index(name)] == "char"
        if n and not fmt_is_text:
            by_name[name] = [(f"{name}[{k}]", flat[i + k]) for k in range(n)]
            i += n
        else:
            v = flat[i]
            if isinstance(v, bytes):
                v = v.rstrip(b"\0").decode("ascii", "replace")
            by_name[name] = [(name, v)]
            i += 1
    out = []
    for name in cls.fieldnames:
        out += by_name[name]
    return out


def _same(a, b, tol: float) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        a, b = float(a), float(b)
        if math.isnan(a) or math.isnan(b):
            return math.isnan(a) and math.isnan(b)
        if tol == 0.0:
            return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)
        return abs(a - b) <= tol
    return a == b


class OutputComparer:
    """Compares computed outputs with recorded packets (module docstring).

    Parameters
    ----------
    tolerance : float
        0: float32 fields bit for bit; > 0: absolute tolerance on float fields.

    ``max_abs_diff`` holds, per ``MESSAGE.field``, the largest |difference|
    of a float field seen in outputs whose payload differed.
    """

    def __init__(self, tolerance: float = 0.0) -> None:
        if not (math.isfinite(tolerance) and tolerance >= 0.0):
            raise ValueError("tolerance must be a finite number >= 0")
        self.tolerance = float(tolerance)
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=mavlink.MAV_COMP_ID_ONBOARD_COMPUTER)
        self.n_compared = 0
        self.n_bitwise = 0
        self.n_within = 0
        self.max_abs_diff: dict = {}

    def compare(self, out, rec) -> Difference | None:
        """None when ``out`` (computed) matches ``rec`` (a ``RawRecord`` the companion sent)."""
        self.n_compared += 1
        msgid, payload = computed_payload(out, self.mav)
        if msgid != rec.msgid:
            return Difference(None, message_name(rec.msgid), message_name(msgid))
        recorded = rec.payload()
        if payload == recorded:
            self.n_bitwise += 1
            return None
        first = None
        name = message_name(msgid)
        for (field, a), (_, b) in zip(field_values(msgid, recorded), field_values(msgid, payload)):
            if isinstance(a, float) and isinstance(b, float) and not (math.isnan(a) or math.isnan(b)):
                key = f"{name}.{field}"
                d = abs(a - b)
                if d > self.max_abs_diff.get(key, 0.0):
                    self.max_abs_diff[key] = d
            if first is None and not _same(a, b, self.tolerance):
                first = Difference(field, a, b)
        if first is None:
            self.n_within += 1
        return first
