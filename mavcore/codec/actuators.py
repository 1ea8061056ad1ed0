"""HIL_ACTUATOR_CONTROLS, both ends: the companion's answer to each sensor
frame (normalised motor commands, the lockstep flag) and the vehicle's
decoding of it, including the fast path of one whole datagram.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from mavcore.link.command_rules import actuator_problem

from .wire import _CRC16, _V2_HEADER, _mcrf4xx, x25_crc

__all__ = ['HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP', 'ActuatorAnswer', 'decode_actuator_controls',
           'decode_actuator_datagram', 'encode_hil_actuator_controls', 'hil_actuator_controls_payload',
           'pack_hil_actuator_controls']


#: HIL_ACTUATOR_CONTROLS.flags bit 0: this message is a lockstep answer.
HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP = 1


@dataclass(frozen=True, slots=True)
class ActuatorAnswer:
    """A decoded HIL_ACTUATOR_CONTROLS.

    Attributes
    ----------
    time_usec : int
        The vehicle time the peer answers (lockstep: a HIGHRES_IMU's time_usec).
    motor_cmd : tuple of 4 float, or None
        Normalised motor commands clipped to [0, 1], PX4 quad-X order; None when
        controls[0..3] are all NaN (a lockstep tick without override) or
        otherwise unusable.
    lockstep : bool
        ``flags & HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP``.
    refused : str or None
        Why controls[0..3] are unusable (``command_rules.actuator_problem``:
        NaN mixed with numbers, infinite, outside [-1, 1]); None otherwise.
    """

    time_usec: int
    motor_cmd: tuple | None
    lockstep: bool
    refused: str | None = None


def decode_actuator_controls(msg) -> ActuatorAnswer | None:
    """HIL_ACTUATOR_CONTROLS -> ``ActuatorAnswer``.

    controls[0..3] all NaN: a lockstep tick without override. Values that
    break ``command_rules.actuator_problem`` (NaN mixed with numbers,
    infinite, outside MAVLink's [-1, 1]) make the command unusable
    (``motor_cmd`` None, ``refused`` says why) but the message still counts
    as a lockstep answer. Usable values are clipped to [0, 1].
    """
    c = msg.controls
    return _answer(int(msg.time_usec), c[0], c[1], c[2], c[3],
                   bool(int(msg.flags) & HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP))


def _answer(t: int, c0: float, c1: float, c2: float, c3: float, lockstep: bool) -> ActuatorAnswer:
    if -1.0 <= c0 <= 1.0 and -1.0 <= c1 <= 1.0 and -1.0 <= c2 <= 1.0 and -1.0 <= c3 <= 1.0:
        return ActuatorAnswer(t, _clip01(c0, c1, c2, c3), lockstep)
    return ActuatorAnswer(t, None, lockstep, actuator_problem(c0, c1, c2, c3))


_HIL_CLASS = mavlink.MAVLink_hil_actuator_controls_message
_HIL_ID = int(_HIL_CLASS.id)
_HIL_LEN = _HIL_CLASS.unpacker.size
_HIL_CRC_EXTRA = bytes((int(_HIL_CLASS.crc_extra),))
_HIL_PAYLOAD = struct.Struct("<QQ16fB")


def decode_actuator_datagram(data: bytes) -> ActuatorAnswer | None:
    """Fast path for a UDP datagram holding exactly one unsigned MAVLink 2
    HIL_ACTUATOR_CONTROLS (the lockstep answer, once per frame).

    Returns None for anything else (other messages, several packets, signed
    packets, bad CRC): the caller then hands the datagram to pymavlink's
    parser, so the result is always the same as the generic path.
    """
    n = len(data)
    if n < 12 or data[0] != 0xFD or data[2] != 0:
        return None
    plen = data[1]
    if n != 12 + plen or plen > _HIL_LEN or (data[7] | data[8] << 8 | data[9] << 16) != _HIL_ID:
        return None
    if data[5] == 1 and data[6] == 1:
        return None   # our own id: let the generic path drop it
    crc = data[n - 2] | data[n - 1] << 8
    if _mcrf4xx is None or _mcrf4xx(data[1:n - 2] + _HIL_CRC_EXTRA, 0xFFFF) != crc:
        return None
    payload = data[10:n - 2]
    if plen < _HIL_LEN:
        payload = payload + bytes(_HIL_LEN - plen)   # MAVLink 2 zero-truncation
    f = _HIL_PAYLOAD.unpack(payload)
    return _answer(f[0], f[2], f[3], f[4], f[5], bool(f[1] & HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP))


def _clip01(c0: float, c1: float, c2: float, c3: float) -> tuple:
    return (min(max(c0, 0.0), 1.0), min(max(c1, 0.0), 1.0), min(max(c2, 0.0), 1.0), min(max(c3, 0.0), 1.0))


_NAN16 = (float("nan"),) * 16


def encode_hil_actuator_controls(mav, time_usec: int, motor_cmd, armed: bool):
    """HIL_ACTUATOR_CONTROLS answering one lockstep sensor frame.

    Parameters
    ----------
    time_usec : int
        The ``time_usec`` of the HIGHRES_IMU being answered.
    motor_cmd : sequence of 4 floats or None
        Normalised motor commands 0..1 in PX4 quad-X order
        (``mavcore.vehicle``); None sends four NaN: a lockstep tick that
        leaves the vehicle's own controller in charge.
    armed : bool
        Sets ``MAV_MODE_FLAG_SAFETY_ARMED`` in ``mode``.
    """
    if motor_cmd is None:
        controls = _NAN16
    else:
        m0, m1, m2, m3 = motor_cmd
        controls = (float(m0), float(m1), float(m2), float(m3)) + (0.0,) * 12
    mode = mavlink.MAV_MODE_FLAG_HIL_ENABLED | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
    return mav.hil_actuator_controls_encode(int(time_usec), controls, mode, HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP)


_MODE_ARMED = mavlink.MAV_MODE_FLAG_HIL_ENABLED | mavlink.MAV_MODE_FLAG_SAFETY_ARMED
_MODE_DISARMED = mavlink.MAV_MODE_FLAG_HIL_ENABLED
_ZERO12 = (0.0,) * 12


def hil_actuator_controls_payload(time_usec: int, motor_cmd, armed: bool) -> bytes:
    """The MAVLink 2 payload (zero-truncated, as on the wire) of
    ``encode_hil_actuator_controls(mav, time_usec, motor_cmd, armed)``."""
    mode = _MODE_ARMED if armed else _MODE_DISARMED
    if motor_cmd is None:
        payload = _HIL_PAYLOAD.pack(time_usec, HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP, *_NAN16, mode)
    else:
        m0, m1, m2, m3 = motor_cmd
        payload = _HIL_PAYLOAD.pack(time_usec, HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP, m0, m1, m2, m3, *_ZERO12,
                                    mode)
    return payload.rstrip(b"\0") or b"\0"   # MAVLink 2 trailing-zero truncation


def pack_hil_actuator_controls(seq: int, system_id: int, component_id: int, time_usec: int, motor_cmd,
                               armed: bool) -> bytes:
    """The packet of ``encode_hil_actuator_controls(...)`` framed as pymavlink
    would (unsigned MAVLink 2, sequence ``seq``), without a message object:
    byte-identical to ``msg.pack(mav)`` (tested)."""
    payload = hil_actuator_controls_payload(time_usec, motor_cmd, armed)
    head = _V2_HEADER.pack(0xFD, len(payload), 0, 0, seq, system_id, component_id, _HIL_ID & 0xFFFF,
                           _HIL_ID >> 16)
    body = head + payload
    return body + _CRC16.pack(x25_crc(body[1:] + _HIL_CRC_EXTRA))
