"""The companion's parameter client (``mavcore.services.param_client``) against the
vehicle's server state machine (``mavcore.services.params.ParamServer``), both sides
pure (no sockets), then once over real UDP against the SITL subprocess.

Rules (https://mavlink.io/en/services/parameter.html): PARAM_SET is acknowledged by
the PARAM_VALUE the vehicle holds afterwards, the old value when it refused the new
one; without it the client sends the PARAM_SET again. INT32 values travel byte-copied
into the float32 field on PX4 and C-cast on ArduPilot: the INT32 2 is the float
2.8e-45 (bits 0x00000002) on PX4 and 2.0 on ArduPilot, worked out here with
``struct``, not with the codec under test.
"""

from __future__ import annotations

import struct

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore import autopilot as autopilots
from mavcore.autopilot import ParamCheck
from mavcore.services.param_client import ParamReadClient, ParamResult, ParamSetClient, ParamStatus
from mavcore.services.params import ParamServer, Parameters

INT32, REAL32 = mavlink.MAV_PARAM_TYPE_INT32, mavlink.MAV_PARAM_TYPE_REAL32
VEH = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
COMP = mavlink.MAVLink(None, srcSystem=1, srcComponent=mavlink.MAV_COMP_ID_ONBOARD_COMPUTER)


def wire(msg, src):
    return mavlink.MAVLink(None).parse_char(msg.pack(src))


def serve(server: ParamServer, request):
    """What the vehicle sends back to the requester for one PARAM_* request (None: silence),
    as ``sitl.params_link`` does with the server's reply."""
    m = wire(request, COMP)
    if m.get_type() == "PARAM_SET":
        r = server.set(m.param_id, m.param_value, m.param_type)
    else:
        r = server.request_read(m.param_id, m.param_index)
    return None if r.index is None else wire(server.value_message(VEH, r.index), VEH)


def px4_server():
    return ParamServer(Parameters.for_autopilot(autopilots.get("px4")), bytewise=True)


def ardupilot_server():
    return ParamServer(Parameters.for_autopilot(autopilots.get("ardupilot")), bytewise=False)


def test_set_int32_bytewise_on_px4_is_confirmed_by_its_echo():
    srv = px4_server()
    c = ParamSetClient(COMP, 1, 1, "COM_OBL_ACT", 2, INT32, timeout_s=1.0, tries=3, bytewise=True)
    (req,) = c.start(10.0)
    sent = wire(req, COMP)
    assert sent.get_type() == "PARAM_SET" and sent.param_type == INT32
    assert struct.pack("<f", sent.param_value) == struct.pack("<i", 2)      # the bytes of the int, not 2.0
    c.on_message(serve(srv, req), 10.01)
    assert c.done and c.outcome() == ParamResult("COM_OBL_ACT", ParamStatus.CONFIRMED, 2, INT32, 1)
    assert srv.params["COM_OBL_ACT"] == 2


def test_set_int32_c_cast_on_ardupilot_and_a_real():
    srv = ardupilot_server()
    c = ParamSetClient(COMP, 1, 1, "FS_GCS_ENABLE", 5, INT32, timeout_s=1.0, bytewise=False)
    (req,) = c.start(0.0)
    assert wire(req, COMP).param_value == 5.0
    c.on_message(serve(srv, req), 0.0)
    assert c.outcome().ok and c.outcome().value == 5 and srv.params["FS_GCS_ENABLE"] == 5
    # a real: confirmed at float32 precision (0.1 is not a float32; its echo is the float32 nearest)
    c = ParamSetClient(COMP, 1, 1, "GUID_TIMEOUT", 0.1, REAL32, timeout_s=1.0, bytewise=False)
    c.on_message(serve(srv, c.start(0.0)[0]), 0.0)
    assert c.outcome().ok and c.outcome().value == pytest.approx(0.1, abs=1e-7)


def test_lost_echo_is_retried_after_the_timeout_on_the_vehicle_clock():
    srv = px4_server()
    c = ParamSetClient(COMP, 1, 1, "COM_OF_LOSS_T", 0.75, REAL32, timeout_s=1.0, tries=3)
    (req,) = c.start(100.0)
    serve(srv, req)                                  # applied, but its echo is lost
    assert srv.params["COM_OF_LOSS_T"] == 0.75
    assert c.tick(101.0) == [] and not c.due(101.0)  # not before 1 s of vehicle time
    (again,) = c.tick(101.001)
    assert wire(again, COMP).param_id == "COM_OF_LOSS_T" and c.sends == 2
    c.on_message(serve(srv, again), 101.002)         # a repeat of the same value is harmless
    assert c.outcome() == ParamResult("COM_OF_LOSS_T", ParamStatus.CONFIRMED, 0.75, REAL32, 2)


def test_refused_value_is_rejected_with_the_value_the_vehicle_kept():
    srv = px4_server()
    before = srv.params["COM_OBL_ACT"]
    c = ParamSetClient(COMP, 1, 1, "COM_OBL_ACT", 7, INT32, timeout_s=1.0)   # outside [0, 2]
    c.on_message(serve(srv, c.start(0.0)[0]), 0.0)
    r = c.outcome()
    assert r.status is ParamStatus.REJECTED and r.value == before and not r.ok
    assert srv.params["COM_OBL_ACT"] == before
    # read-only: the requester still hears the value as it stands
    c = ParamSetClient(COMP, 1, 1, "SIM_LOCKSTEP", 1, INT32, timeout_s=1.0)
    c.on_message(serve(srv, c.start(0.0)[0]), 0.0)
    assert c.outcome().status is ParamStatus.REJECTED and c.outcome().value == 0


def test_silence_times_out_after_every_try_on_the_vehicle_clock():
    srv = px4_server()
    c = ParamSetClient(COMP, 1, 1, "NO_SUCH_PARAM", 1.0, REAL32, timeout_s=0.5, tries=3)
    assert serve(srv, c.start(0.0)[0]) is None       # an unknown name is not answered
    t, sends = 0.0, []
    while not c.done:                                # no wall time passes: only the clock passed in
        t += 0.125                                   # exact in binary: no rounding at the boundary
        sends += [t] * len(c.tick(t))
    assert sends == [0.625, 1.25]                    # strictly after each 0.5 s, 3 sends in all
    assert t == 1.875 and c.outcome() == ParamResult("NO_SUCH_PARAM", ParamStatus.TIMED_OUT, None, None, 3)
    # another parameter's PARAM_VALUE is not the answer
    c = ParamSetClient(COMP, 1, 1, "COM_OBL_ACT", 1, INT32, timeout_s=0.5)
    c.start(0.0)
    c.on_message(wire(srv.value_message(VEH, srv.params.index("COM_OF_LOSS_T")), VEH), 0.1)
    assert not c.done


def test_read_decodes_per_personality_and_times_out():
    for srv, bw in ((px4_server(), True), (ardupilot_server(), False)):
        name = "COM_OBL_ACT" if bw else "FS_GCS_ENABLE"
        c = ParamReadClient(COMP, 1, 1, name, timeout_s=1.0, bytewise=bw)
        c.on_message(serve(srv, c.start(0.0)[0]), 0.0)
        assert c.outcome().ok and c.outcome().value == srv.params[name] and isinstance(c.outcome().value, int)
    c = ParamReadClient(COMP, 1, 1, "NO_SUCH_PARAM", timeout_s=1.0, tries=2)
    c.start(0.0)
    assert c.tick(1.0) == [] and len(c.tick(1.01)) == 1 and c.tick(2.0) == []
    c.tick(2.02)
    assert c.outcome().status is ParamStatus.TIMED_OUT and c.sends == 2


def test_param_check_problems():
    loss = ParamCheck("COM_OF_LOSS_T", "offboard loss timeout", min=0.5, max=1.0)
    assert loss.problem(0.5) is None and loss.problem(1.0) is None
    assert loss.problem(2.0) == "expected 0.5..1" and loss.problem(None) == "not read (no PARAM_VALUE)"
    act = ParamCheck("FS_GCS_ENABLE", "GCS failsafe", allowed=(1, 5))
    assert act.problem(5) is None and act.problem(0) == "expected 1 or 5"


def test_check_params_warns_of_each_value_outside_what_the_flight_needs():
    """``companion.flight.param_check.check_params`` driven like the core drives it: each
    read answered by the ArduPilot server (FS_GCS_ENABLE defaults to 0, off); a value
    outside the check is a warning and a STATUSTEXT, a good one is neither."""
    from companion.flight.param_check import PARAM_PREFIX, check_params

    srv = ardupilot_server()

    def read(name):
        c = ParamReadClient(COMP, 1, 1, name, timeout_s=1.0, bytewise=False)
        c.on_message(serve(srv, c.start(0.0)[0]), 0.0)
        yield None
        return c.outcome()

    said = []
    checks = autopilots.get("ardupilot").param_checks + (ParamCheck("GUID_TIMEOUT", "t", min=0.1, max=5.0),)
    gen = check_params(read, checks, COMP, said.append)
    with pytest.raises(StopIteration) as stop:
        while True:
            next(gen)
    assert stop.value.value == [{"name": "FS_GCS_ENABLE", "value": 0, "problem": "expected 1 or 5",
                                 "why": "GCS failsafe: RTL or land"}]
    assert [wire(m, COMP).text for m in said] == [f"{PARAM_PREFIX}FS_GCS_ENABLE=0 expected 1 or 5"]
    srv.set("FS_GCS_ENABLE", 5.0, INT32)
    gen = check_params(read, checks, COMP, said.append)
    with pytest.raises(StopIteration) as stop:
        while True:
            next(gen)
    assert stop.value.value == []


@pytest.mark.parametrize("autopilot,name,value,ptype", [("px4", "COM_OBL_ACT", 2, INT32),
                                                         ("ardupilot", "FS_GCS_ENABLE", 5, INT32)])
def test_set_and_read_back_over_udp_against_the_sitl_process(autopilot, name, value, ptype):
    """End to end: the client over real UDP (``companion.link.Connection``) against
    ``python -m sitl``; the INT32 in each stack's encoding is held and read back, and a
    value outside its bounds is refused with the value kept."""
    from companion.link import Connection
    from service_driver import drive
    from sitl.api import SitlProcess

    from test_sitl_mavlink import MISSION

    bw = autopilots.get(autopilot).param_bytewise
    with SitlProcess(MISSION, speed=2.0, autopilot=autopilot) as sitl:
        conn = Connection(sitl.url.replace("udpin", "udpout")).open()
        try:
            conn.wait_heartbeat(timeout_s=10.0)
            ts, tc = conn.target_system, conn.target_component
            r = drive(conn, ParamSetClient(conn.mav, ts, tc, name, value, ptype, timeout_s=1.0, bytewise=bw))
            assert r.status is ParamStatus.CONFIRMED and r.value == value
            r = drive(conn, ParamReadClient(conn.mav, ts, tc, name, timeout_s=1.0, bytewise=bw))
            assert r.ok and r.value == value
            r = drive(conn, ParamSetClient(conn.mav, ts, tc, name, 99, ptype, timeout_s=1.0, bytewise=bw))
            assert r.status is ParamStatus.REJECTED and r.value == value
        finally:
            conn.close()


def test_declared_checks_name_listed_parameters_and_judge_the_sitl_defaults():
    """Every checked name is one the personality lists (a read of it is answered); the SITL's
    PX4 defaults (COM_OF_LOSS_T 1 s, COM_OBL_ACT 0 land) pass, ArduCopter's FS_GCS_ENABLE 0
    (off, as on ArduCopter) is what docs/flying-a-real-vehicle.md asks to change."""
    for key, bad in (("px4", []), ("ardupilot", ["FS_GCS_ENABLE"])):
        ap = autopilots.get(key)
        params = Parameters.for_autopilot(ap)
        assert ap.param_checks and all(c.name in params for c in ap.param_checks)
        assert [c.name for c in ap.param_checks if c.problem(params[c.name]) is not None] == bad
