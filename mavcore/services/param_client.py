"""The companion's side of the MAVLink parameter protocol: read and set one
parameter, as pure state machines (no I/O, no clock).

https://mavlink.io/en/services/parameter.html:

- PARAM_REQUEST_READ by name (``param_index`` -1) is answered by one
  PARAM_VALUE; a vehicle without that parameter does not answer (PX4), so a
  reader re-sends after a timeout and then gives up;
- PARAM_SET is acknowledged by the PARAM_VALUE the vehicle holds afterwards
  (the new value, or the old one when it refused it), sent to every peer; a
  client that hears no PARAM_VALUE within its timeout sends the PARAM_SET
  again (the spec's rule: a repeat of the same value is harmless). ArduPilot
  may not echo a refused value at all (mavlink-devguide PR #140): a set that
  is never echoed ends ``TIMED_OUT``, not confirmed.

Values travel in PARAM_VALUE/PARAM_SET's float32 ``param_value``; an INT32
parameter is byte-copied into the float by PX4
(MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE) and C-cast to a float by
ArduPilot (PARAM_ENCODE_C_CAST): ``bytewise`` is the personality's
``param_bytewise`` (docs/flying-a-real-vehicle.md).

Every timeout runs on the caller's clock ``now_s`` (the companion passes the
vehicle's, ``mavcore.services.base``). ``outcome()`` is a ``ParamResult``:
``CONFIRMED`` (the vehicle holds the value asked for, or the value read),
``REJECTED`` (its echo carries another value: the one it holds) or
``TIMED_OUT`` (no PARAM_VALUE of that name after ``tries`` sends).
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from mavcore import codec

from .base import ClientTransaction, elapsed_s

PARAM_TYPE_INT32 = mavlink.MAV_PARAM_TYPE_INT32
PARAM_TYPE_REAL32 = mavlink.MAV_PARAM_TYPE_REAL32


class ParamStatus(enum.Enum):
    CONFIRMED = "confirmed"
    REJECTED = "rejected"
    TIMED_OUT = "timed_out"


@dataclass(frozen=True, slots=True)
class ParamResult:
    """How a parameter read or set ended.

    Attributes
    ----------
    name : str
    status : ParamStatus
    value : float, int or None
        The value the vehicle reported holding (decoded: an int for INT32);
        None when ``TIMED_OUT``.
    param_type : int or None
        MAV_PARAM_TYPE of the vehicle's PARAM_VALUE; None when ``TIMED_OUT``.
    sends : int
        Requests sent (1 + the retries).
    """

    name: str
    status: ParamStatus
    value: float | int | None = None
    param_type: int | None = None
    sends: int = 0

    @property
    def ok(self) -> bool:
        return self.status is ParamStatus.CONFIRMED


def wire_value(value: float | int, param_type: int, bytewise: bool) -> float:
    """The float32 field of a PARAM_SET carrying ``value``: an INT32 byte-copied
    (``bytewise``, PX4) or cast (ArduPilot); every other type as the float."""
    if param_type == PARAM_TYPE_INT32 and bytewise:
        return codec.param_to_wire(int(value), PARAM_TYPE_INT32)
    return float(value)


def _as_float32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", float(x)))[0]


def holds(asked: float | int, reported: float | int, param_type: int) -> bool:
    """The reported value is the one asked for: equal for an integer, equal at
    float32 precision (what the wire carries) for a real."""
    if param_type == PARAM_TYPE_INT32:
        return int(reported) == int(asked)
    return _as_float32(reported) == _as_float32(asked)


class _ParamClient(ClientTransaction):
    """One request re-sent after ``timeout_s`` without a PARAM_VALUE of ``name``,
    ``tries`` sends in all; the subclass says what the answer means."""

    def __init__(self, name: str, request, timeout_s: float, tries: int, bytewise: bool) -> None:
        if tries < 1:
            raise ValueError(f"tries must be >= 1, not {tries}")
        self.name = name
        self.timeout_s = float(timeout_s)
        self.tries = int(tries)
        self.bytewise = bool(bytewise)
        self._request = request
        self.sends = 0
        self._t0: float | None = None

    def _send(self, now_s) -> list:
        self.sends += 1
        self._t0 = now_s
        return [self._request]

    def start(self, now_s: float | None) -> list:
        return self._send(now_s)

    def _answered(self, m) -> ParamResult:
        raise NotImplementedError

    def on_message(self, m, now_s: float | None) -> list:
        if not self.done and m.get_type() == "PARAM_VALUE" and m.param_id == self.name:
            self._finish(self._answered(m))
        return []

    def due(self, now_s: float | None, effect_seen: bool = False) -> bool:
        return not self.done and elapsed_s(now_s, self._t0) > self.timeout_s

    def tick(self, now_s: float | None, effect_seen: bool = False) -> list:
        if not self.due(now_s):
            return []
        if self.sends >= self.tries:
            self._finish(ParamResult(self.name, ParamStatus.TIMED_OUT, sends=self.sends))
            return []
        return self._send(now_s)


class ParamReadClient(_ParamClient):
    """Read one parameter by name: PARAM_REQUEST_READ(name, -1).

    ``outcome()``: ``CONFIRMED`` with the decoded value, or ``TIMED_OUT`` (the
    vehicle has no such parameter: PX4 stays silent).
    """

    def __init__(self, mav, target_system: int, target_component: int, name: str, timeout_s: float,
                 tries: int = 2, bytewise: bool = True) -> None:
        request = mav.param_request_read_encode(target_system, target_component, name.encode(), -1)
        super().__init__(name, request, timeout_s, tries, bytewise)

    def _answered(self, m) -> ParamResult:
        return ParamResult(self.name, ParamStatus.CONFIRMED, codec.decode_param_value(m, self.bytewise),
                           int(m.param_type), self.sends)


class ParamSetClient(_ParamClient):
    """Set one parameter: PARAM_SET(name, value, type); its PARAM_VALUE echo is
    the acknowledgement.

    ``outcome()``: ``CONFIRMED`` when the echo holds ``value`` (integers exactly,
    reals at float32 precision), ``REJECTED`` with the value the vehicle kept
    when it holds another, ``TIMED_OUT`` when no echo came after ``tries`` sends.

    Parameters
    ----------
    mav : pymavlink MAVLink
        Encoder (no file; the caller frames and sends).
    target_system, target_component : int
    name : str
        The stack's parameter name (``Autopilot.wire_name``).
    value : float or int
        In the stack's units.
    param_type : int
        MAV_PARAM_TYPE (INT32 or REAL32).
    timeout_s : float
        Wait for the echo, on the caller's clock (s).
    tries : int
        Sends in all before ``TIMED_OUT``.
    bytewise : bool
        The personality's ``param_bytewise`` (PX4 True, ArduPilot False).
    """

    def __init__(self, mav, target_system: int, target_component: int, name: str, value: float | int,
                 param_type: int, timeout_s: float, tries: int = 3, bytewise: bool = True) -> None:
        self.value = int(value) if param_type == PARAM_TYPE_INT32 else float(value)
        self.param_type = int(param_type)
        request = mav.param_set_encode(target_system, target_component, name.encode(),
                                       wire_value(self.value, self.param_type, bytewise), self.param_type)
        super().__init__(name, request, timeout_s, tries, bytewise)

    def _answered(self, m) -> ParamResult:
        got = codec.decode_param_value(m, self.bytewise)
        status = ParamStatus.CONFIRMED if holds(self.value, got, self.param_type) else ParamStatus.REJECTED
        return ParamResult(self.name, status, got, int(m.param_type), self.sends)
