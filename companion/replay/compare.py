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

Three modes (``OutputComparer.mode``):

- ``bitwise``: payloads byte for byte (the replaying environment is the
  recording's: ``companion.flight.environment``);
- ``drift`` (another or an unknown environment): the continuous outputs
  (``DRIFT_FIELDS``: motor commands, setpoint values) may differ by the float64
  rounding drift between machines, seen through float32 rounding
  (``docs/replay.md``, "Comparison across machines"): each value by at most
  one float32 rounding step plus ``DRIFT_REL_OF`` of its scale, and over the
  whole flight, per field, the sum of the differences by at most that
  fraction of the scale per output plus one rounding step at that scale
  (``drift_excess``). Everything else (message ids and order, integer and text
  fields, commands, modes, the replanner's announcements) stays exact;
- ``absolute``: ``tolerance`` on every float field (given by the user).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from ..flight.core import ActuatorOut
from mavcore import codec

HIL_ACTUATOR_CONTROLS_ID = mavlink.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS
_SETPOINT_ID = mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED
_ATTITUDE_TARGET_ID = mavlink.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET

#: The continuous outputs that may drift between environments, per message id (field names as
#: ``field_values`` gives them). Everything else is a discrete decision and stays exact.
DRIFT_FIELDS = {
    HIL_ACTUATOR_CONTROLS_ID: frozenset(f"controls[{i}]" for i in range(16)),
    _SETPOINT_ID: frozenset(("x", "y", "z", "vx", "vy", "vz", "afx", "afy", "afz", "yaw", "yaw_rate")),
    _ATTITUDE_TARGET_ID: frozenset(("q[0]", "q[1]", "q[2]", "q[3]", "body_roll_rate", "body_pitch_rate",
                                    "body_yaw_rate", "thrust")),
}
#: Float64 drift allowed between environments, relative to a field's scale: float64's resolution
#: 2^-52 times a conditioning allowance of 2^12 for the observer-controller chain (docs/replay.md).
DRIFT_REL = 2.0 ** -40
#: The same for the setpoints and attitude targets, which come from the trajectory's solve
#: (a min-snap system; conditioning allowance 2^20, docs/replay.md).
DRIFT_REL_TRAJECTORY = 2.0 ** -32
#: The relative drift allowed per message id of ``DRIFT_FIELDS``.
DRIFT_REL_OF = {HIL_ACTUATOR_CONTROLS_ID: DRIFT_REL, _SETPOINT_ID: DRIFT_REL_TRAJECTORY,
                _ATTITUDE_TARGET_ID: DRIFT_REL_TRAJECTORY}
#: Smallest scale of a drifting field (in its unit): commands are normalised to [0, 1].
DRIFT_SCALE_MIN = 1.0


def ulp32(x: float) -> float:
    """The float32 spacing at ``|x|`` (the step a float32 rounding can flip)."""
    m, e = math.frexp(abs(x))
    if m == 0.0:
        return 2.0 ** -149
    return 2.0 ** max(e - 24, -149)


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


def drift_allowance(a: float, b: float, rel: float = DRIFT_REL) -> float:
    """Largest |a - b| of one drifting value: one float32 rounding step plus ``rel`` of its scale."""
    m = max(abs(a), abs(b))
    return ulp32(m) + rel * max(m, DRIFT_SCALE_MIN)


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

    def __init__(self, tolerance: float = 0.0, drift: bool = False) -> None:
        if not (math.isfinite(tolerance) and tolerance >= 0.0):
            raise ValueError("tolerance must be a finite number >= 0")
        self.tolerance = float(tolerance)
        #: ``bitwise``, ``drift`` or ``absolute`` (module docstring); a tolerance wins over drift.
        self.mode = "absolute" if self.tolerance > 0.0 else ("drift" if drift else "bitwise")
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=mavlink.MAV_COMP_ID_ONBOARD_COMPUTER)
        self.n_compared = 0
        self.n_bitwise = 0
        self.n_within = 0
        self.max_abs_diff: dict = {}
        self.n_by_msgid: dict = {}          # outputs compared per message id
        self.drift_sum: dict = {}           # MESSAGE.field -> [sum |a - b|, scale, n values that differ]

    def compare(self, out, rec) -> Difference | None:
        """None when ``out`` (computed) matches ``rec`` (a ``RawRecord`` the companion sent)."""
        self.n_compared += 1
        msgid, payload = computed_payload(out, self.mav)
        if msgid != rec.msgid:
            return Difference(None, message_name(rec.msgid), message_name(msgid))
        self.n_by_msgid[msgid] = self.n_by_msgid.get(msgid, 0) + 1
        recorded = rec.payload()
        if payload == recorded:
            self.n_bitwise += 1
            return None
        first = None
        name = message_name(msgid)
        drifting = DRIFT_FIELDS.get(msgid, ()) if self.mode == "drift" else ()
        rel = DRIFT_REL_OF.get(msgid, DRIFT_REL)
        for (field, a), (_, b) in zip(field_values(msgid, recorded), field_values(msgid, payload)):
            finite = isinstance(a, float) and isinstance(b, float) and math.isfinite(a) and math.isfinite(b)
            if finite:
                key = f"{name}.{field}"
                d = abs(a - b)
                if d > self.max_abs_diff.get(key, 0.0):
                    self.max_abs_diff[key] = d
                if field in drifting and d > 0.0:
                    acc = self.drift_sum.setdefault(key, [0.0, 0.0, 0])
                    acc[0] += d
                    acc[1] = max(acc[1], abs(a), abs(b))
                    acc[2] += 1
                    if d <= drift_allowance(a, b, rel):
                        continue
            if first is None and not _same(a, b, self.tolerance):
                first = Difference(field, a, b)
        if first is None:
            self.n_within += 1
        return first

    def drift_excess(self) -> list:
        """Drift mode: the fields whose differences add up to more than float64 drift explains.

        Per ``MESSAGE.field``: ``sum |a - b|`` over the flight against the bound
        ``rel * max(m, DRIFT_SCALE_MIN) * n + ulp32(m)`` (``rel`` the message's
        ``DRIFT_REL_OF``, ``n`` outputs of that
        message compared, ``m`` the field's largest magnitude among the differing
        values: one free rounding step there). Returns dicts (``field``,
        ``mean_abs_diff``, ``bound``, ``n_outputs``, ``n_differing``), fields over
        their bound only, largest ratio first; [] in the other modes.
        """
        if self.mode != "drift":
            return []
        out = []
        for key, (total, m, n_diff) in self.drift_sum.items():
            n, bound = self._drift_bound(key, m)
            if total > bound:
                out.append({"field": key, "mean_abs_diff": total / n, "bound": bound / n, "n_outputs": n,
                            "n_differing": n_diff, "ratio": total / bound})
        out.sort(key=lambda r: -r["ratio"])
        return out

    def drift_summary(self) -> dict:
        """Drift mode: per ``MESSAGE.field`` that differed, ``[mean |a - b| per output, its bound]``."""
        out = {}
        for key, (total, m, _) in sorted(self.drift_sum.items()):
            n, bound = self._drift_bound(key, m)
            out[key] = [total / n, bound / n]
        return out

    def _drift_bound(self, key: str, m: float) -> tuple:
        """(n outputs of the field's message, the bound on the field's sum of differences)."""
        name = key.split(".", 1)[0]
        msgid, n = next(((k, v) for k, v in self.n_by_msgid.items() if message_name(k) == name), (None, 1))
        return max(n, 1), DRIFT_REL_OF.get(msgid, DRIFT_REL) * max(m, DRIFT_SCALE_MIN) * max(n, 1) + ulp32(m)
