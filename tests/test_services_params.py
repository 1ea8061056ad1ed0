"""The parameter protocol state machines (``mavcore.services.params``) without sockets.

From https://mavlink.io/en/services/parameter.html: PARAM_REQUEST_READ by name
(index -1) or index gets one PARAM_VALUE carrying ``param_count`` and
``param_index``; PARAM_SET is answered with the value the vehicle holds
afterwards; an INT32 travels byte-copied in the float field with
PARAM_ENCODE_BYTEWISE (PX4), else cast (ArduPilot). PX4 does not answer a read
of a name it does not have, so a reader must time out.
"""

from __future__ import annotations

import struct

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore import autopilot as autopilots
from mavcore.services.params import ParamServer, Parameters

INT32 = mavlink.MAV_PARAM_TYPE_INT32
VEH = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)


def wire(msg, src=VEH):
    return mavlink.MAVLink(None).parse_char(msg.pack(src))


def bytewise(i: int) -> float:
    """The float whose four bytes are the int32 ``i`` (what PX4 sends), by struct, not by the codec."""
    return struct.unpack("<f", struct.pack("<i", i))[0]


@pytest.fixture
def server():
    return ParamServer(Parameters.for_autopilot(autopilots.get("px4"), initial={"SIM_LOCKSTEP": 1}), bytewise=True)


def test_read_by_name_and_index_and_unknown_is_silent(server):
    p = server.params
    i = p.index("COM_OBL_ACT")
    assert server.request_read("COM_OBL_ACT", -1).index == i
    assert server.request_read("", i).index == i
    assert server.request_read("NO_SUCH_PARAM", -1).index is None
    assert server.request_read("", len(p)).index is None
    m = wire(server.value_message(VEH, i))
    assert (m.param_id, m.param_type, m.param_count, m.param_index) == ("COM_OBL_ACT", INT32, len(p), i)
    assert struct.pack("<f", m.param_value) == struct.pack("<i", p["COM_OBL_ACT"])
    assert list(server.request_list()) == list(range(len(p)))


def test_set_answers_every_peer_with_the_value_held_afterwards(server):
    p = server.params
    r = server.set("COM_OBL_ACT", bytewise(2), INT32)
    assert (r.index, r.to_all, r.applied, r.warning) == (p.index("COM_OBL_ACT"), True, True, None)
    assert p["COM_OBL_ACT"] == 2
    r = server.set("COM_OBL_ACT", bytewise(7), INT32)                 # outside [0, 2]: kept at 2
    assert r.to_all and not r.applied and "outside [0, 2]" in r.warning and p["COM_OBL_ACT"] == 2
    r = server.set("MPC_XY_VEL_MAX", 3.5, mavlink.MAV_PARAM_TYPE_REAL32)
    assert r.applied and p["MPC_XY_VEL_MAX"] == 3.5
    r = server.set("SIM_LOCKSTEP", bytewise(0), INT32)                # read-only: the requester hears the value
    assert not r.to_all and not r.applied and "read-only" in r.warning and p["SIM_LOCKSTEP"] == 1
    r = server.set("NO_SUCH_PARAM", 1.0, mavlink.MAV_PARAM_TYPE_REAL32)
    assert r.index is None and "Unknown parameter" in r.warning


def test_cast_int32_without_bytewise():
    srv = ParamServer(Parameters.for_autopilot(autopilots.get("px4")), bytewise=False)
    assert srv.set("COM_OBL_ACT", 1.0, INT32).applied and srv.params["COM_OBL_ACT"] == 1
    m = wire(srv.value_message(VEH, srv.params.index("COM_OBL_ACT")))
    assert m.param_value == 1.0
