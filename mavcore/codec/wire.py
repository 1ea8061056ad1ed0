"""MAVLink 2 framing shared by both ends: the X.25 CRC, the fast packer of the
per-frame messages (vehicle end), the fast splitter/decoder of received
datagrams (companion end) and PX4's ``custom_mode`` word.

In lockstep every sensor frame is one datagram (LOCAL_POSITION_NED, ODOMETRY,
DISTANCE_SENSOR, HIGHRES_IMU) answered by one HIL_ACTUATOR_CONTROLS. pymavlink
parses byte by byte and builds a generic message object per packet; doing
those few types with one precompiled ``struct.Struct`` each, after the same
framing and CRC checks, is several times cheaper. Everything else (and any
packet that does not frame or CRC-check) still goes through pymavlink. Both
directions are byte-identical to pymavlink (tests/test_sitl_codec.py,
tests/test_link.py).
"""

from __future__ import annotations

import operator
import struct

from pymavlink.dialects.v20 import common as mavlink


__all__ = ['x25_crc', 'FastMessage', 'FastDecoder', 'FAST_DECODERS', 'split_datagram', 'px4_custom_mode',
           'px4_modes_from_custom', 'FastPacker', 'PACK_HIGHRES_IMU', 'PACK_RAW_IMU', 'PACK_LOCAL_POSITION_NED',
           'PACK_ATTITUDE', 'PACK_ODOMETRY', 'PACK_ATTITUDE_QUATERNION', 'PACK_DISTANCE_SENSOR']


try:   # the CRC implementation pymavlink itself uses when fastcrc is installed
    from fastcrc import crc16 as _fastcrc16
    _mcrf4xx = _fastcrc16.mcrf4xx
except ImportError:   # pragma: no cover - pymavlink's pure Python CRC
    _mcrf4xx = None


_CRC16 = struct.Struct("<H")
_V2_HEADER = struct.Struct("<BBBBBBBHB")


def x25_crc(data: bytes) -> int:
    """MAVLink's CRC-16/MCRF4XX (X.25) of ``data`` (include the crc_extra byte)."""
    if _mcrf4xx is not None:
        return _mcrf4xx(data, 0xFFFF)
    return mavlink.x25crc(data).crc   # pragma: no cover


class FastMessage(tuple):
    """A decoded packet of one of the per-frame types: a tuple of the field
    values in wire order (arrays as lists, as pymavlink gives them) followed by
    system id, component id and the raw packet; fields read by name like a
    pymavlink message (``m.xacc``, ``m.get_type()``, ``m.get_msgbuf()``)."""

    __slots__ = ()
    # underscored: a field may be called ``id`` (HIGHRES_IMU, DISTANCE_SENSOR)
    _msgname = ""
    _msgid = -1
    _fieldnames: tuple = ()

    def get_type(self) -> str:
        return self._msgname

    def get_msgId(self) -> int:
        return self._msgid

    def get_srcSystem(self) -> int:
        return self[-3]

    def get_srcComponent(self) -> int:
        return self[-2]

    def get_msgbuf(self) -> bytes:
        return self[-1]

    def get_seq(self) -> int:
        return self[-1][4]

    def get_fieldnames(self) -> list:
        return list(self._fieldnames)

    def to_dict(self) -> dict:
        d = {"mavpackettype": self._msgname}
        d.update((k, getattr(self, k)) for k in self._fieldnames)
        return d

    def __repr__(self) -> str:
        return f"{self._msgname} {{{', '.join(f'{k} : {getattr(self, k)}' for k in self._fieldnames)}}}"


def _array_field(a: int, b: int, name: str) -> property:
    """An array field: a fresh list of the flat values a..b (built only when read)."""
    return property(lambda self: list(self[a:b]), doc=f"field {name}")


class FastDecoder:
    """struct decoder of one message type (``msg_class``: pymavlink's class).

    The message is the flat unpacked tuple (then system id, component id,
    packet); an array field (ODOMETRY's ``q`` and covariances) is a list made
    from its slice of that tuple when it is read, not at every decode.
    """

    def __init__(self, msg_class) -> None:
        self.msgid = int(msg_class.id)
        self.crc_extra = bytes((int(msg_class.crc_extra),))
        self.unpacker = msg_class.unpacker
        self.size = int(msg_class.unpacker.size)
        names = tuple(msg_class.ordered_fieldnames)
        lengths = tuple(int(k) for k in msg_class.array_lengths)
        types = dict(zip(msg_class.fieldnames, msg_class.fieldtypes))
        attrs = {"__slots__": (), "_msgname": msg_class.msgname, "_msgid": self.msgid,
                 "_fieldnames": tuple(msg_class.fieldnames)}
        i = 0
        for n, k in zip(names, lengths):
            if k and types[n] == "char":
                raise ValueError(f"FastDecoder: {msg_class.msgname}.{n} is text (not supported)")
            if k:
                attrs[n] = _array_field(i, i + k, n)
                i += k
            else:
                attrs[n] = property(operator.itemgetter(i), doc=f"field {n}")
                i += 1
        self.cls = type("Fast_" + msg_class.msgname, (FastMessage,), attrs)

    def decode(self, packet: bytes, payload: bytes, sysid: int, compid: int) -> FastMessage:
        """Message from a framed, CRC-checked packet and its payload bytes."""
        n = len(payload)
        if n != self.size:   # MAVLink 2 zero truncation, or a longer (newer) payload
            payload = payload + bytes(self.size - n) if n < self.size else payload[:self.size]
        return tuple.__new__(self.cls, self.unpacker.unpack(payload) + (sysid, compid, packet))


#: The types decoded without pymavlink (the per-frame telemetry of a lockstep run; ATTITUDE
#: streams at 50 Hz while the replanner flies).
FAST_DECODERS = {d.msgid: d for d in (FastDecoder(c) for c in (
    mavlink.MAVLink_highres_imu_message, mavlink.MAVLink_local_position_ned_message,
    mavlink.MAVLink_odometry_message, mavlink.MAVLink_distance_sensor_message,
    mavlink.MAVLink_attitude_message))}


def split_datagram(data: bytes, fast: bool = True) -> list:
    """The MAVLink 2 packets of one UDP datagram, in order.

    ``FastMessage`` objects for the types of ``FAST_DECODERS`` and raw
    ``bytes`` for every other packet. A well-framed unsigned packet with a
    good CRC is one item; at the first byte that does not start one
    (MAVLink 1, signed packets, garbage, bad CRC, unknown id, truncation)
    the rest of the datagram is one ``bytes`` item for pymavlink's robust
    parser, so garbage is handled exactly as before. ``fast=False`` gives
    every good packet as bytes. (A list, not a generator: it runs for every
    frame and a generator's resumptions cost more than the list.)
    """
    n = len(data)
    i = 0
    out = []
    decoders = FAST_DECODERS if fast else {}
    mmap = mavlink.mavlink_map
    crc = _mcrf4xx if _mcrf4xx is not None else (lambda b, _init: x25_crc(b))
    while i < n:
        if n - i < 12 or data[i] != 0xFD or data[i + 2] != 0:
            out.append(data[i:])
            return out
        end = i + 12 + data[i + 1]
        if end > n:
            out.append(data[i:])
            return out
        msgid = data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16
        dec = decoders.get(msgid)
        if dec is not None:
            extra = dec.crc_extra
        else:
            cls = mmap.get(msgid)
            if cls is None:
                out.append(data[i:])
                return out
            extra = bytes((cls.crc_extra,))
        if crc(data[i + 1:end - 2] + extra, 0xFFFF) != (data[end - 2] | data[end - 1] << 8):
            out.append(data[i:])
            return out
        packet = data[i:end]
        if dec is not None:
            out.append(dec.decode(packet, data[i + 10:end - 2], data[i + 5], data[i + 6]))
        else:
            out.append(packet)
        i = end
    return out


def px4_custom_mode(main_mode: int, sub_mode: int = 0) -> int:
    """PX4 ``custom_mode`` word from a main and a sub mode."""
    return (int(main_mode) & 0xFF) << 16 | (int(sub_mode) & 0xFF) << 24


def px4_modes_from_custom(custom_mode: int) -> tuple[int, int]:
    """(main_mode, sub_mode) of a PX4 ``custom_mode`` word."""
    c = int(custom_mode)
    return (c >> 16) & 0xFF, (c >> 24) & 0xFF


class FastPacker:
    """MAVLink 2 framing of one message type straight from its field tuple.

    Byte-identical to ``msg.pack(mav)`` of pymavlink (trailing-zero payload
    truncation, CRC with crc_extra) but without building the message object:
    the per-frame messages cost a third of the pymavlink path. When the link
    signs, ``pack`` uses pymavlink's packer instead.

    Parameters
    ----------
    msg_class : pymavlink MAVLink_*_message class
    """

    def __init__(self, msg_class) -> None:
        self.msg_class = msg_class
        self.msgid = int(msg_class.id)
        self.crc_extra = bytes((int(msg_class.crc_extra),))
        self.payload = msg_class.unpacker
        names = list(msg_class.fieldnames)
        # (argument index, array length) in wire order; 0 = scalar
        self.order = tuple((names.index(n), int(k)) for n, k in
                           zip(msg_class.ordered_fieldnames, msg_class.array_lengths))
        self.has_arrays = any(k for _, k in self.order)
        # scalar-only types: the wire order as one C-level getter
        idx = [i for i, _ in self.order]
        self._reorder = operator.itemgetter(*idx) if len(idx) > 1 else (lambda a, i=idx[0]: (a[i],))
        self._id_lo = self.msgid & 0xFFFF
        self._id_hi = self.msgid >> 16

    def pack(self, mav, args: tuple) -> bytes:
        """Frame ``args`` (in ``*_encode`` argument order) with ``mav``'s
        sequence number and ids; advances ``mav.seq``."""
        if mav.signing.sign_outgoing:
            buf = self.msg_class(*args).pack(mav)
        else:
            if self.has_arrays:
                flat = []
                for i, k in self.order:
                    if k:
                        flat.extend(args[i])
                    else:
                        flat.append(args[i])
            else:
                flat = self._reorder(args)
            payload = self.payload.pack(*flat).rstrip(b"\0") or b"\0"
            head = _V2_HEADER.pack(0xFD, len(payload), 0, 0, mav.seq, mav.srcSystem, mav.srcComponent,
                                   self._id_lo, self._id_hi)
            body = head + payload
            crc_in = body[1:] + self.crc_extra
            buf = body + _CRC16.pack(_mcrf4xx(crc_in, 0xFFFF) if _mcrf4xx is not None else x25_crc(crc_in))
        mav.seq = (mav.seq + 1) & 0xFF
        return buf


PACK_HIGHRES_IMU = FastPacker(mavlink.MAVLink_highres_imu_message)
PACK_RAW_IMU = FastPacker(mavlink.MAVLink_raw_imu_message)
PACK_LOCAL_POSITION_NED = FastPacker(mavlink.MAVLink_local_position_ned_message)
PACK_ATTITUDE = FastPacker(mavlink.MAVLink_attitude_message)
PACK_ODOMETRY = FastPacker(mavlink.MAVLink_odometry_message)
PACK_ATTITUDE_QUATERNION = FastPacker(mavlink.MAVLink_attitude_quaternion_message)
PACK_DISTANCE_SENSOR = FastPacker(mavlink.MAVLink_distance_sensor_message)
