"""PX4's port convention, the default of ``sitl`` and ``companion fly``: the
vehicle sends to the companion on 14540 and to a ground station on 14550, so
both of them listen (udpin) and nobody has to send first. The legacy
convention (the SITL listening on 14540) stays behind ``--ports legacy``."""

from __future__ import annotations

from pathlib import Path

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from companion.commands.fly import CONNECT_BY_PORTS, DEFAULT_CONNECT
from sitl.api import SitlThread, free_udp_port
from sitl.cli import port_links

MISSION = Path(__file__).resolve().parents[1] / "missions" / "flat-rectangle" / "mission.yaml"


def _port(url):
    return int(url.rsplit(":", 1)[1])


def test_defaults_are_px4s_and_both_sides_agree():
    listen, gcs = port_links("px4", None, None)
    assert (_port(listen), _port(gcs)) == (14540, 14550)
    assert listen.startswith("udpout:") and gcs.startswith("udpout:")     # the vehicle sends
    assert DEFAULT_CONNECT.startswith("udpin:") and _port(DEFAULT_CONNECT) == 14540   # the companion listens
    legacy, no_gcs = port_links("legacy", None, None)
    assert legacy.startswith("udpin:") and no_gcs is None
    assert CONNECT_BY_PORTS["legacy"] == "udpout:" + legacy.split(":", 1)[1]
    assert port_links("px4", "udpin:127.0.0.1:1", "none") == ("udpin:127.0.0.1:1", None)


def test_vehicle_sends_first_to_companion_and_gcs():
    """Companion and ground station only listen; both hear the vehicle, and the
    ground-station link carries control (a command gets its ACK)."""
    p_comp, p_gcs = free_udp_port(), free_udp_port()
    comp = mavutil.mavlink_connection(f"udpin:127.0.0.1:{p_comp}", source_system=1, source_component=191)
    gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{p_gcs}", source_system=255, source_component=190)
    try:
        with SitlThread(MISSION, listen=f"udpout:127.0.0.1:{p_comp}", control_outs=(f"udpout:127.0.0.1:{p_gcs}",),
                        speed=4.0):
            for c in (comp, gcs):
                hb = c.recv_match(type="HEARTBEAT", blocking=True, timeout=5)
                assert hb is not None and hb.get_srcSystem() == 1
            gcs.mav.command_long_send(1, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0,
                                      mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
            ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=5)
            assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
    finally:
        comp.close()
        gcs.close()
