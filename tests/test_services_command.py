"""The command protocol state machines (``mavcore.services.command``) without sockets.

From https://mavlink.io/en/services/command.html and MAV_RESULT: every command
received gets exactly one final COMMAND_ACK; without one the sender repeats the
command with ``confirmation`` incremented; IN_PROGRESS means keep waiting for
the final ACK; TEMPORARILY_REJECTED means retrying later may work; DENIED,
UNSUPPORTED and FAILED are final.
"""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore.errors import CommandRejected, LinkError
from mavcore.services.command import (
    TEMP_REJECT_WAIT_S, CommandClient, CommandReply, CommandServer, ack_message, command_long,
)

GCS = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
VEH = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM


def wire(msg, src):
    return mavlink.MAVLink(None).parse_char(msg.pack(src))


def ack(command, result):
    return wire(VEH.command_ack_encode(command, result, 0, 0, 255, 190), VEH)


def test_command_long_pads_to_seven_params_and_caps_the_confirmation():
    m = wire(command_long(GCS, 1, 1, ARM, (1,), 300), GCS)
    assert (m.param1, m.param2, m.param7, m.confirmation) == (1.0, 0.0, 0.0, 255)


def test_client_happy_path_and_in_progress():
    c = CommandClient(GCS, 1, 1, ARM, (1,), timeout_s=1.0)
    (m,) = c.start(0.0)
    assert (m.command, m.confirmation, m.param1) == (ARM, 0, 1.0)
    assert c.on_message(ack(mavlink.MAV_CMD_NAV_TAKEOFF, 0), 0.1) == [] and not c.done   # another command's ACK
    c.on_message(ack(ARM, mavlink.MAV_RESULT_IN_PROGRESS), 0.9)
    assert not c.due(1.5)                   # the wait restarted at 0.9: due only after 1.9
    assert c.due(1.91)
    c2 = CommandClient(GCS, 1, 1, ARM, (1,), timeout_s=1.0)
    c2.start(0.0)
    c2.on_message(ack(ARM, mavlink.MAV_RESULT_ACCEPTED), 0.2)
    assert c2.done and c2.outcome().result == mavlink.MAV_RESULT_ACCEPTED


def test_client_repeats_with_confirmation_then_fails():
    c = CommandClient(GCS, 1, 1, ARM, (1,), "arm", timeout_s=0.5, sends=3)
    c.start(0.0)
    assert c.tick(0.5) == []                              # strictly more than the timeout
    (m1,) = c.tick(0.51)
    (m2,) = c.tick(1.02)
    assert (m1.confirmation, m2.confirmation) == (1, 2)
    assert c.tick(1.53) == [] and c.done
    with pytest.raises(LinkError, match=r"no COMMAND_ACK for command 400 \(arm\) after 3 tries"):
        c.outcome()
    opt = CommandClient(GCS, 1, 1, ARM, timeout_s=0.5, sends=1, optional=True)
    opt.start(0.0)
    opt.tick(0.6)
    assert opt.done and opt.outcome() is None


def test_client_lost_ack_then_answer_to_the_repeat():
    c = CommandClient(GCS, 1, 1, ARM, (1,), timeout_s=1.0)
    c.start(0.0)
    assert len(c.tick(1.1)) == 1                          # the ACK was lost: repeat
    c.on_message(ack(ARM, mavlink.MAV_RESULT_ACCEPTED), 1.2)
    assert c.outcome().result == mavlink.MAV_RESULT_ACCEPTED and c.sends == 2


def test_client_temporarily_rejected_waits_and_retries_then_final_rejection():
    c = CommandClient(GCS, 1, 1, ARM, (1,), "arm", timeout_s=1.0, temp_retries=1)
    c.start(0.0)
    c.on_message(ack(ARM, mavlink.MAV_RESULT_TEMPORARILY_REJECTED), 0.1)
    assert not c.done and c.tick(0.1 + TEMP_REJECT_WAIT_S - 0.01) == []
    assert c.on_message(ack(ARM, mavlink.MAV_RESULT_ACCEPTED), 0.2) == [] and not c.done  # not awaited now
    (m,) = c.tick(0.1 + TEMP_REJECT_WAIT_S)
    assert m.confirmation == 1
    c.on_message(ack(ARM, mavlink.MAV_RESULT_TEMPORARILY_REJECTED), 0.7)   # retries spent: final
    with pytest.raises(CommandRejected) as exc:
        c.outcome()
    assert exc.value.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    d = CommandClient(GCS, 1, 1, ARM, (1,))
    d.start(0.0)
    d.on_message(ack(ARM, mavlink.MAV_RESULT_DENIED), 0.1)
    with pytest.raises(CommandRejected):
        d.outcome()


def test_client_effect_ends_it_without_an_ack():
    c = CommandClient(GCS, 1, 1, mavlink.MAV_CMD_NAV_LAND, timeout_s=1.0)
    c.start(0.0)
    assert c.due(0.1, effect_seen=True)
    assert c.tick(0.1, effect_seen=True) == [] and c.done and c.outcome() is None


def test_server_one_ack_per_command_with_the_rules_and_faults():
    def home(p, int_frame):
        return mavlink.MAV_RESULT_ACCEPTED, [VEH.home_position_encode(0, 0, 0, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0)]

    def broken(p, int_frame):
        raise RuntimeError("boom")

    def picky(p, int_frame):
        raise ValueError("bad parameter")

    srv = CommandServer({mavlink.MAV_CMD_GET_HOME_POSITION: home, mavlink.MAV_CMD_DO_SET_MODE: broken,
                         mavlink.MAV_CMD_NAV_LAND: picky, ARM: lambda p, f: (mavlink.MAV_RESULT_ACCEPTED, None)})
    r = srv.handle(mavlink.MAV_CMD_GET_HOME_POSITION, (0,) * 7)
    assert r.result == mavlink.MAV_RESULT_ACCEPTED and [m.get_type() for m in r.after] == ["HOME_POSITION"]
    assert srv.handle(12345, (0,) * 7) == CommandReply(mavlink.MAV_RESULT_UNSUPPORTED, unsupported=True)
    assert srv.handle(mavlink.MAV_CMD_DO_SET_MODE, (1, 0, 0, 0, 0, 0, 0)).result == mavlink.MAV_RESULT_FAILED
    assert srv.handle(mavlink.MAV_CMD_NAV_LAND, (0,) * 7).result == mavlink.MAV_RESULT_DENIED
    # a parameter the rules refuse (ARM's param1 is 0 or 1): DENIED with the reason, handler not run
    r = srv.handle(ARM, (math.nan,) + (0,) * 6)
    assert r.result == mavlink.MAV_RESULT_DENIED and r.refused
    m = wire(ack_message(VEH, ARM, CommandReply(mavlink.MAV_RESULT_ACCEPTED), 255, 190), VEH)
    assert (m.command, m.result, m.target_system, m.target_component) == (ARM, 0, 255, 190)
