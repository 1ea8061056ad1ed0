"""Commands are sane: ``mavcore.link.command_rules`` on both ends.

Over real UDP to the SITL (a vehicle holding at 2 m in AUTO.LOITER after an
AUTO take-off, commanded by an allowed ground station 255/190), every hostile
command is DENIED and every hostile setpoint, actuator, mode, parameter or
mission message is ignored with a STATUSTEXT, and the vehicle's state (mode,
armed, height, parameters, message intervals, stored mission, actuator
override) is unchanged; the legal forms are still ACCEPTED. The companion's
link refuses to send the same things (``UnsafeMessage``) and sends nothing."""

from __future__ import annotations

import math
import socket

import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore.errors import UnsafeMessage
from mavcore.link import command_rules as rules
from sitl.api import SitlThread

from test_sitl_mavlink import MISSION, Client

NAN, INF = math.nan, math.inf
HOME_ALT_M = 30.0          # flat-rectangle's home.alt_m: NAV_TAKEOFF param7 is AMSL
HOLD_Z_M = 2.0
CUSTOM = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
HB = mavlink.MAVLINK_MSG_ID_HEARTBEAT
LPOS = mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED
TAKEOFF, LAND, RTL = mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
ARM, SET_MODE = mavlink.MAV_CMD_COMPONENT_ARM_DISARM, mavlink.MAV_CMD_DO_SET_MODE
INTERVAL = mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
I32 = rules.INT32_MAX


@pytest.fixture(scope="module")
def flying():
    """A SITL with the vehicle holding at 2 m, and the allowed ground station."""
    with SitlThread(MISSION, speed=4.0) as s:
        gcs = Client(s.url)
        gcs.hello()
        z0 = -gcs.recv("LOCAL_POSITION_NED", 3.0).z
        # on the ground a NaN altitude is the default (PX4, MAVSDK's takeoff()): accepted
        assert gcs.command(TAKEOFF, NAN, NAN, NAN, NAN, NAN, NAN, NAN) == mavlink.MAV_RESULT_ACCEPTED
        assert gcs.command(TAKEOFF, 0, 0, 0, NAN, NAN, NAN, HOME_ALT_M + HOLD_Z_M) == mavlink.MAV_RESULT_ACCEPTED
        assert gcs.command(ARM, 1, NAN, NAN, NAN, NAN, NAN, NAN) == mavlink.MAV_RESULT_ACCEPTED
        assert gcs.recv("HEARTBEAT", 10.0, lambda m: m.custom_mode == (4 << 16 | 3 << 24)) is not None   # LOITER
        gcs.pump(0.5)
        _URL[:] = [s.url]
        yield s.server, gcs, z0
        gcs.close()


def snapshot(server, gcs, z0) -> dict:
    """What a hostile message could change, read from the SITL; the height (over
    MAVLink) must stay at the hold height."""
    st = server.vehicle.stack
    lp = gcs.recv("LOCAL_POSITION_NED", 3.0)
    assert -lp.z - z0 == pytest.approx(HOLD_Z_M, abs=0.3)
    return {"mode": st.mode.label, "armed": st.armed, "failsafe": st.failsafe, "override": st.override_active,
            "params": tuple(server.vehicle.params.by_index(i)[1] for i in range(len(server.vehicle.params))),
            "intervals": dict(server.streams.intervals), "mission": server.missions.items}


def long_(cmd, *p):
    return ("COMMAND_LONG", cmd, tuple(p) + (0.0,) * (7 - len(p)), 0)


def int_(cmd, p1234, x, y, z, frame=mavlink.MAV_FRAME_GLOBAL):
    return ("COMMAND_INT", cmd, (*p1234, x, y, z), frame)


# (id, command) -- each DENIED in flight from an allowed ground station
HOSTILE_COMMANDS = [
    ("takeoff-all-nan-in-flight", long_(TAKEOFF, NAN, NAN, NAN, NAN, NAN, NAN, NAN)),   # the audit's case
    ("takeoff-alt-nan-in-flight", long_(TAKEOFF, 0, 0, 0, NAN, NAN, NAN, NAN)),
    ("takeoff-alt-inf", long_(TAKEOFF, 0, 0, 0, NAN, NAN, NAN, INF)),
    ("takeoff-alt-minus-inf", long_(TAKEOFF, 0, 0, 0, NAN, NAN, NAN, -INF)),
    ("takeoff-alt-1e38", long_(TAKEOFF, 0, 0, 0, NAN, NAN, NAN, 1e38)),
    ("takeoff-yaw-inf", long_(TAKEOFF, 0, 0, 0, INF, NAN, NAN, 32.0)),
    ("takeoff-yaw-1e9", long_(TAKEOFF, 0, 0, 0, 1e9, NAN, NAN, 32.0)),
    ("takeoff-lat-91", long_(TAKEOFF, 0, 0, 0, NAN, 91.0, 0.0, 32.0)),
    ("takeoff-lon-inf", long_(TAKEOFF, 0, 0, 0, NAN, 44.8, INF, 32.0)),
    ("takeoff-pitch-inf", long_(TAKEOFF, INF, 0, 0, NAN, NAN, NAN, 32.0)),
    ("takeoff-empty-param-inf", long_(TAKEOFF, 0, -INF, 0, NAN, NAN, NAN, 32.0)),
    ("int-takeoff-relative-frame", int_(TAKEOFF, (0, 0, 0, NAN), I32, I32, 32.0,
                                        mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT)),
    ("int-takeoff-lat-91", int_(TAKEOFF, (0, 0, 0, NAN), 910_000_000, 0, 32.0)),
    ("int-takeoff-alt-nan-in-flight", int_(TAKEOFF, (0, 0, 0, NAN), I32, I32, NAN)),
    ("arm-nan", long_(ARM, NAN)),
    ("arm-2", long_(ARM, 2.0)),
    ("arm-half", long_(ARM, 0.5)),
    ("disarm-force-inf", long_(ARM, 0.0, INF)),
    ("disarm-force-magic-off-by-one", long_(ARM, 0.0, 21195.0)),
    ("set-mode-base-nan", long_(SET_MODE, NAN, 4, 6)),
    ("set-mode-main-inf", long_(SET_MODE, CUSTOM, INF, 0)),
    ("set-mode-main-fraction", long_(SET_MODE, CUSTOM, 4.5, 6)),
    ("set-mode-sub-negative", long_(SET_MODE, CUSTOM, 4, -1)),
    ("set-mode-base-1e9", long_(SET_MODE, 1e9, 4, 6)),
    ("interval-minus-1e30", long_(INTERVAL, HB, -1e30)),                   # the audit's case
    ("interval-minus-2", long_(INTERVAL, LPOS, -2.0)),
    ("interval-minus-half", long_(INTERVAL, LPOS, -0.5)),
    ("interval-1e30", long_(INTERVAL, LPOS, 1e30)),
    ("interval-nan", long_(INTERVAL, LPOS, NAN)),
    ("interval-id-nan", long_(INTERVAL, NAN, 1000)),
    ("interval-id-1e30", long_(INTERVAL, 1e30, 1000)),
    ("interval-id-fraction", long_(INTERVAL, 32.5, 1000)),
    ("interval-response-target-7", long_(INTERVAL, LPOS, 1000, 0, 0, 0, 0, 7)),
    ("int-interval-minus-1e30", int_(INTERVAL, (HB, -1e30, 0, 0), 0, 0, 0.0)),
    ("land-alt-inf", long_(LAND, 0, 0, 0, NAN, NAN, NAN, INF)),
    ("land-lat-1e9", long_(LAND, 0, 0, 0, NAN, 1e9, NAN, NAN)),
    ("land-mode-9", long_(LAND, 0, 9, 0, NAN, NAN, NAN, NAN)),
    ("rtl-param-inf", long_(RTL, INF)),
    ("request-message-nan", long_(mavlink.MAV_CMD_REQUEST_MESSAGE, NAN)),
    ("get-interval-negative-id", long_(mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, -5)),
]


def _send(gcs, case) -> int | None:
    kind, cmd, p, frame = case
    if kind == "COMMAND_LONG":
        gcs.mav.command_long_send(1, 1, cmd, 0, *p)
    else:
        gcs.mav.command_int_send(1, 1, frame, cmd, 0, 0, p[0], p[1], p[2], p[3], int(p[4]), int(p[5]), p[6])
    ack = gcs.recv("COMMAND_ACK", 3.0, lambda m: m.command == cmd)
    return None if ack is None else ack.result


@pytest.mark.parametrize("case", HOSTILE_COMMANDS, ids=[c[0] for c in HOSTILE_COMMANDS])
def test_a_hostile_command_is_denied_and_changes_nothing(case, flying):
    server, gcs, z0 = flying
    before = snapshot(server, gcs, z0)
    n = sum(server.stats["refused"].values())
    assert _send(gcs, case[1]) == mavlink.MAV_RESULT_DENIED
    assert sum(server.stats["refused"].values()) == n + 1       # denied by the rules, not by chance
    gcs.pump(0.05)
    assert snapshot(server, gcs, z0) == before


def _target(mav, frame=mavlink.MAV_FRAME_LOCAL_NED, mask=0xDF8, pos=(0.0, 0.0, -2.0), vel=(0.0,) * 3,
            yaw=0.0):
    return mav.set_position_target_local_ned_encode(0, 1, 1, frame, mask, *pos, *vel, 0.0, 0.0, 0.0, yaw, 0.0)


def _item(mav, seq=0, frame=mavlink.MAV_FRAME_GLOBAL_INT, p4=NAN, x=448_000_000, y=-6_000_000, z=32.0):
    return mav.mission_item_int_encode(1, 1, seq, frame, mavlink.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, p4, x, y, z, 0)


# (id, kind refused, builder(mav) -> message); sent by the allowed controller
HOSTILE_MESSAGES = [
    ("setpoint-x-inf", "SET_POSITION_TARGET_LOCAL_NED", lambda m: _target(m, pos=(INF, 0.0, -2.0))),
    ("setpoint-z-1e30", "SET_POSITION_TARGET_LOCAL_NED", lambda m: _target(m, pos=(0.0, 0.0, -1e30))),
    ("setpoint-vx-1e4", "SET_POSITION_TARGET_LOCAL_NED", lambda m: _target(m, mask=0xDC0, vel=(1e4, 0.0, 0.0))),
    ("setpoint-yaw-inf", "SET_POSITION_TARGET_LOCAL_NED", lambda m: _target(m, mask=0x9F8, yaw=INF)),   # yaw used
    ("setpoint-frame-99", "SET_POSITION_TARGET_LOCAL_NED", lambda m: _target(m, frame=99)),
    ("actuators-1e30", "HIL_ACTUATOR_CONTROLS",
     lambda m: m.hil_actuator_controls_encode(0, [1e30] * 4 + [0.0] * 12, 0, 0)),
    ("actuators-inf", "HIL_ACTUATOR_CONTROLS",
     lambda m: m.hil_actuator_controls_encode(0, [INF, 0.5, 0.5, 0.5] + [0.0] * 12, 0, 0)),
    ("actuators-nan-mixed", "HIL_ACTUATOR_CONTROLS",
     lambda m: m.hil_actuator_controls_encode(0, [0.5, NAN, 0.5, 0.5] + [0.0] * 12, 0, 0)),
    ("actuators-2", "HIL_ACTUATOR_CONTROLS", lambda m: m.hil_actuator_controls_encode(0, [2.0] * 16, 0, 0)),
    ("set-mode-unknown", "SET_MODE", lambda m: m.set_mode_encode(1, CUSTOM, 77 << 16)),
    ("set-mode-no-custom-flag", "SET_MODE", lambda m: m.set_mode_encode(1, 0, 4 << 16 | 6 << 24)),
    ("mission-lat-91", "MISSION_ITEM_INT", lambda m: _item(m, x=910_000_000)),
    ("mission-lon-200", "MISSION_ITEM_INT", lambda m: _item(m, y=2_000_000_000)),
    ("mission-alt-inf", "MISSION_ITEM_INT", lambda m: _item(m, z=INF)),
    ("mission-alt-nan", "MISSION_ITEM_INT", lambda m: _item(m, z=NAN)),
    ("mission-param4-inf", "MISSION_ITEM_INT", lambda m: _item(m, p4=INF)),
    ("mission-frame-99", "MISSION_ITEM_INT", lambda m: _item(m, frame=99)),
    ("legacy-mission-item-x-inf", "MISSION_ITEM",
     lambda m: m.mission_item_encode(1, 1, 0, mavlink.MAV_FRAME_GLOBAL, 16, 0, 1, 0, 0, 0, NAN, INF, -0.6, 32.0, 0)),
]


@pytest.mark.parametrize("case", HOSTILE_MESSAGES, ids=[c[0] for c in HOSTILE_MESSAGES])
def test_a_hostile_message_is_ignored_with_a_statustext(case, flying):
    _, kind, build = case
    server, gcs, z0 = flying
    client = gcs
    if kind == "HIL_ACTUATOR_CONTROLS":
        client = _companion(server)
    before = snapshot(server, gcs, z0)
    n = server.stats["refused"][kind]
    if kind == "MISSION_ITEM_INT":
        gcs.mav.mission_count_send(1, 1, 1, 0)
        assert gcs.recv("MISSION_REQUEST_INT", 3.0).seq == 0
    client.mav.send(build(client.mav))
    if kind == "MISSION_ITEM_INT":
        ack = gcs.recv("MISSION_ACK", 3.0)
        assert ack is not None and ack.type != mavlink.MAV_MISSION_ACCEPTED
    client.pump(0.1)
    assert server.stats["refused"][kind] == n + 1
    assert snapshot(server, gcs, z0) == before


_COMPANION: list = []
_URL: list = []


def _companion(server):
    """The allowed companion (1/191), one per module (a controller is bound to its address)."""
    if not _COMPANION:
        c = Client(_URL[0], sysid=1, compid=191)
        c.mav.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        c.pump(0.1)
        _COMPANION.append(c)
    return _COMPANION[0]


@pytest.mark.parametrize("kind, value", [("PARAM_SET NaN", NAN), ("PARAM_SET inf", INF),
                                         ("PARAM_SET 1e9", 1e9), ("PARAM_SET -1", -1.0)])
def test_a_hostile_parameter_is_refused_with_a_statustext(kind, value, flying):
    server, gcs, z0 = flying
    before = snapshot(server, gcs, z0)
    said = sum(t.startswith("Param rejected: MPC_XY_VEL_MAX") for t in gcs.texts)
    m = gcs.set_param("MPC_XY_VEL_MAX", value)               # the PARAM_VALUE as it stands comes back
    assert m is not None and m.param_value == pytest.approx(server.vehicle.params["MPC_XY_VEL_MAX"])
    gcs.pump(0.1)
    assert sum(t.startswith("Param rejected: MPC_XY_VEL_MAX") for t in gcs.texts) == said + 1
    assert snapshot(server, gcs, z0) == before


def test_the_legal_forms_are_still_accepted(flying):
    server, gcs, z0 = flying
    assert gcs.command(ARM, 1, NAN) == mavlink.MAV_RESULT_ACCEPTED                    # already armed
    assert gcs.command(SET_MODE, CUSTOM, 4, 3) == mavlink.MAV_RESULT_ACCEPTED         # LOITER again
    for iv in (-1, 0, 20_000):
        assert gcs.command(INTERVAL, LPOS, iv) == mavlink.MAV_RESULT_ACCEPTED
    assert gcs.command(INTERVAL, LPOS, 0, 0, 0, 0, 0, NAN) == mavlink.MAV_RESULT_ACCEPTED
    assert gcs.command(mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, LPOS) == mavlink.MAV_RESULT_ACCEPTED
    gcs.mav.command_int_send(1, 1, mavlink.MAV_FRAME_GLOBAL_INT, INTERVAL, 0, 0, LPOS, 0, 0, 0, 0, 0, 0)
    assert gcs.recv("COMMAND_ACK", 3.0, lambda m: m.command == INTERVAL).result == mavlink.MAV_RESULT_ACCEPTED
    m = gcs.set_param("MPC_XY_VEL_MAX", 4.0)
    assert m.param_value == pytest.approx(4.0) and server.vehicle.params["MPC_XY_VEL_MAX"] == pytest.approx(4.0)
    # a take-off in flight below the vehicle (1 m AMSL-above-home, it holds at 2 m):
    # PX4 accepts it and does not descend
    assert gcs.command(TAKEOFF, 0, 0, 0, NAN, NAN, NAN, HOME_ALT_M + 1.0) == mavlink.MAV_RESULT_ACCEPTED
    gcs.pump(1.0)
    assert any(t.startswith("Already higher than takeoff altitude") for t in gcs.texts)
    assert -gcs.recv("LOCAL_POSITION_NED", 3.0).z - z0 == pytest.approx(HOLD_Z_M, abs=0.2)
    gcs.mav.command_int_send(1, 1, mavlink.MAV_FRAME_GLOBAL, TAKEOFF, 0, 0, 0, 0, 0, NAN, I32, I32,
                             HOME_ALT_M + HOLD_Z_M)
    assert gcs.recv("COMMAND_ACK", 3.0, lambda m: m.command == TAKEOFF).result == mavlink.MAV_RESULT_ACCEPTED
    # a good mission item is stored
    gcs.mav.mission_count_send(1, 1, 1, 0)
    assert gcs.recv("MISSION_REQUEST_INT", 3.0).seq == 0
    gcs.mav.send(_item(gcs.mav))
    assert gcs.recv("MISSION_ACK", 3.0).type == mavlink.MAV_MISSION_ACCEPTED
    assert len(server.missions.items) == 1
    for c in _COMPANION:
        c.close()
    _COMPANION.clear()


# --- the rules themselves, and the companion's side ----------------------------------------


@pytest.mark.parametrize("case", HOSTILE_COMMANDS, ids=[c[0] for c in HOSTILE_COMMANDS])
def test_the_table_names_the_parameter(case):
    kind, cmd, p, frame = case[1]
    why = rules.command_problem(cmd, p, int_frame=None if kind == "COMMAND_LONG" else frame, landed=False)
    assert why is not None and why.startswith(rules.command_name(cmd)), why


def test_nan_altitude_is_the_default_only_on_the_ground():
    p = (0, 0, 0, NAN, NAN, NAN, NAN)
    assert rules.command_problem(TAKEOFF, p, landed=True) is None
    assert "param7" in rules.command_problem(TAKEOFF, p, landed=False)


def test_interval_bounds_are_the_int32_of_message_interval():
    assert rules.command_problem(INTERVAL, (LPOS, I32, 0, 0, 0, 0, 0)) is None
    assert rules.command_problem(INTERVAL, (LPOS, I32 + 1.0, 0, 0, 0, 0, 0)) is not None
    assert rules.command_problem(INTERVAL, (LPOS, -1.0, 0, 0, 0, 0, 0)) is None
    assert rules.command_problem(INTERVAL, (2 ** 24, 1000, 0, 0, 0, 0, 0)) is not None   # beyond 24-bit ids


@pytest.fixture()
def companion_link():
    """A companion ``Connection`` to a UDP socket standing for the vehicle."""
    from companion.link import Connection

    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(0.2)
    conn = Connection(f"udpout:127.0.0.1:{vehicle.getsockname()[1]}").open()
    yield conn, vehicle
    conn.close()
    vehicle.close()


OUTGOING = [
    ("command-nan", lambda mav: mav.command_long_encode(1, 1, INTERVAL, 0, LPOS, NAN, 0, 0, 0, 0, 0)),
    ("command-inf", lambda mav: mav.command_long_encode(1, 1, ARM, 0, INF, 0, 0, 0, 0, 0, 0)),
    ("takeoff-nan-alt", lambda mav: mav.command_long_encode(1, 1, TAKEOFF, 0, 0, 0, 0, NAN, NAN, NAN, NAN)),
    ("setpoint-nan", lambda mav: _target(mav, pos=(NAN, 0.0, -2.0))),
    ("setpoint-inf-velocity", lambda mav: _target(mav, mask=0xDC0, vel=(0.0, INF, 0.0))),
    ("mission-alt-inf", lambda mav: _item(mav, z=INF)),
]


@pytest.mark.parametrize("case", OUTGOING, ids=[c[0] for c in OUTGOING])
def test_the_companion_refuses_to_send_it(case, companion_link):
    conn, vehicle = companion_link
    with pytest.raises(UnsafeMessage):
        conn.send(case[1](conn.mav))
    assert conn.n_sent == 0
    with pytest.raises(socket.timeout):
        vehicle.recvfrom(4096)


@pytest.mark.parametrize("cmd", [(0.5, NAN, 0.5, 0.5), (INF, 0.5, 0.5, 0.5), (1.5, 0.5, 0.5, 0.5)])
def test_the_companion_refuses_unusable_motor_commands(cmd, companion_link):
    conn, vehicle = companion_link
    with pytest.raises(UnsafeMessage):
        conn.send_actuators(4000, cmd, True)
    conn.send_actuators(4000, None, True)          # the NaN tick is legal
    conn.send_actuators(8000, (0.0, 0.25, 0.5, 1.0), True)
    assert conn.n_sent == 2
    assert len(vehicle.recvfrom(4096)[0]) > 0


def test_the_companion_sends_its_own_commands():
    """What the flight core sends (DO_SET_MODE, ARM, NAV_LAND, SET_MESSAGE_INTERVAL, padded with 0) passes."""
    for cmd, p in ((SET_MODE, (CUSTOM, 6, 0)), (ARM, (1,)), (ARM, (0,)), (LAND, ()), (INTERVAL, (LPOS, 4000)),
                   (INTERVAL, (HB, -1))):
        assert rules.command_problem(cmd, tuple(p) + (0.0,) * (7 - len(p))) is None


class _Core:
    """The parts of ``FlightCore`` the runner's refusal path uses."""

    def __init__(self, outbox):
        self.outbox, self.degraded, self.interrupted, self.finished = list(outbox), None, None, False

    def take_outbox(self):
        out, self.outbox = self.outbox, []
        return out

    def degrade(self, reason):
        self.degraded = reason

    def interrupt(self, reason):
        self.interrupted = reason


def test_the_runner_turns_refused_motor_commands_into_a_tick_and_hands_over(companion_link):
    from companion.runner import ActuatorOut, MissionRunner

    conn, vehicle = companion_link
    core = _Core([ActuatorOut(4000, (0.5, math.nan, 0.5, 0.5), True)])
    MissionRunner(conn, core)._send_outbox()
    data, _ = vehicle.recvfrom(4096)
    m = mavlink.MAVLink(None).parse_buffer(data)[0]
    assert m.get_type() == "HIL_ACTUATOR_CONTROLS" and all(math.isnan(c) for c in m.controls[:4])
    assert "HIL_ACTUATOR_CONTROLS" in core.degraded and core.interrupted is None


def test_the_runner_stops_the_flight_on_any_other_refused_message(companion_link):
    from companion.runner import MissionRunner

    conn, vehicle = companion_link
    core = _Core([_target(conn.mav, pos=(math.nan, 0.0, -2.0))])
    MissionRunner(conn, core)._send_outbox()
    assert conn.n_sent == 0 and "SET_POSITION_TARGET_LOCAL_NED" in core.interrupted
