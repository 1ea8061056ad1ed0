"""MAVSDK-Python 4.x (the native binding from PyPI, unmodified) drives the
SITL: connect, read position/attitude/flight mode, arm, start offboard, fly
to a point, land. Real time (speed 1); about 20 s."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

mavsdk = pytest.importorskip("mavsdk")
if not hasattr(mavsdk, "Mavsdk"):   # pragma: no cover - the gRPC wrapper (mavsdk < 4)
    pytest.skip("needs the native mavsdk >= 4", allow_module_level=True)

from mavsdk import ComponentType, Configuration, Mavsdk   # noqa: E402
from mavsdk.plugins.action import Action   # noqa: E402
from mavsdk.plugins.offboard import Offboard, PositionNedYaw   # noqa: E402
from mavsdk.plugins.telemetry import FlightMode, LandedState, Telemetry   # noqa: E402

from mavcore import frames   # noqa: E402
from mission_flight import wait_until   # noqa: E402
from sitl.api import SitlThread   # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MISSION = ROOT / "missions" / "flat-rectangle" / "mission.yaml"
HOME = (44.8, -0.6, 30.0)       # the mission's home: geodetic pose of the map origin

pytestmark = pytest.mark.slow


@pytest.fixture()
def vehicle():
    with SitlThread(MISSION, speed=1.0) as sitl:
        port = sitl.listen.rsplit(":", 1)[1]
        drone = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        try:
            drone.add_any_connection(f"udpout://127.0.0.1:{port}")
            system = drone.first_autopilot(10.0)
            assert system is not None, "MAVSDK did not discover the autopilot"
            yield sitl, system
        finally:
            drone.destroy()


def test_mavsdk_offboard_flight(vehicle):
    sitl, system = vehicle
    tel, action, offboard = Telemetry(system), Action(system), Offboard(system)
    assert wait_until(lambda: tel.health().is_armable and tel.health().is_home_position_ok, 5.0)

    # position, attitude, mode as the SITL knows them (its true start point)
    start = sitl.server.vehicle.home_enu_m
    lat, lon, alt = frames.enu2geodetic(start[0], start[1], start[2], *HOME)
    pos = tel.position()
    assert pos.latitude_deg == pytest.approx(lat, abs=2e-7) and pos.longitude_deg == pytest.approx(lon, abs=2e-7)
    assert pos.absolute_altitude_m == pytest.approx(alt, abs=0.01)
    att = tel.attitude_euler()
    # the onboard estimate (sim.onboard_state: estimate), aligned from the
    # paper's noisy vectors: within about 1 deg after the first seconds
    assert att.yaw_deg == pytest.approx(90.0, abs=2.0)     # the SITL starts facing east (ENU yaw 0)
    assert abs(att.roll_deg) < 2.0 and abs(att.pitch_deg) < 2.0
    assert tel.flight_mode() == FlightMode.HOLD

    action.arm()
    assert wait_until(tel.armed, 3.0)
    p0 = tel.position_velocity_ned().position
    assert (p0.north_m, p0.east_m) == pytest.approx((start[1], start[0]), abs=0.01)
    offboard.set_position_ned(PositionNedYaw(p0.north_m, p0.east_m, p0.down_m - 2.0, 90.0))
    offboard.start()
    assert wait_until(lambda: tel.flight_mode() == FlightMode.OFFBOARD, 3.0)

    # climb 2 m, then fly 0.5 m north and 2 m east at that height (along the
    # corridor: its rows stand 1.05 m either side, the vehicle's radius is 0.442 m)
    target = (p0.north_m + 0.5, p0.east_m + 2.0, p0.down_m - 2.0)
    offboard.set_position_ned(PositionNedYaw(*target, 90.0))

    def there():
        p = tel.position_velocity_ned().position
        return math.dist((p.north_m, p.east_m, p.down_m), target) < 0.1
    assert wait_until(there, 10.0)
    assert tel.in_air()

    action.land()
    assert wait_until(lambda: tel.landed_state() == LandedState.ON_GROUND, 10.0)
    p = tel.position_velocity_ned().position
    assert (p.north_m, p.east_m) == pytest.approx(target[:2], abs=0.15)
    assert p.down_m == pytest.approx(p0.down_m, abs=0.05)
    assert wait_until(lambda: not tel.armed(), 5.0)            # auto-disarm after landing (COM_DISARM_LAND)
    assert sitl.server.stats["bad_packets"] == 0


def test_mavsdk_takes_off_and_lands_the_ardupilot_personality():
    """MAVSDK knows the stack from HEARTBEAT (MAV_AUTOPILOT_ARDUPILOTMEGA) and uses
    ArduCopter's dialect: GUIDED by its number, MAV_CMD_NAV_TAKEOFF above home."""
    with SitlThread(MISSION, speed=2.0, autopilot="ardupilot") as sitl:
        port = sitl.listen.rsplit(":", 1)[1]
        drone = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        try:
            drone.add_any_connection(f"udpout://127.0.0.1:{port}")
            system = drone.first_autopilot(10.0)
            assert system is not None, "MAVSDK did not discover the autopilot"
            tel, action = Telemetry(system), Action(system)
            assert wait_until(lambda: tel.flight_mode() == FlightMode.STABILIZED, 5.0)   # ArduCopter boots there
            z0 = float(sitl.server.vehicle.home_enu_m[2])
            action.set_takeoff_altitude(2.0)
            action.arm()
            assert wait_until(tel.armed, 3.0)
            action.takeoff()
            # GUIDED (4) by ArduCopter's number, and the climb to 2 m above home
            assert wait_until(lambda: sitl.server.vehicle.stack.custom_mode == 4, 3.0)
            assert wait_until(lambda: sitl.server.vehicle.sim.truth.pos_enu_m[2] > z0 + 1.6, 10.0)
            assert wait_until(tel.in_air, 3.0)
            action.land()
            assert wait_until(lambda: tel.landed_state() == LandedState.ON_GROUND, 15.0)
            assert sitl.server.vehicle.stack.custom_mode == 9          # LAND
        finally:
            drone.destroy()


def test_mavsdk_listens_as_with_px4s_sitl():
    """PX4's port convention (the SITL's default): the vehicle sends to the API's port,
    so MAVSDK's usual ``udpin://`` finds it without sending first."""
    from sitl.api import free_udp_port

    port = free_udp_port()
    drone = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        drone.add_any_connection(f"udpin://127.0.0.1:{port}")
        with SitlThread(MISSION, speed=1.0, listen=f"udpout:127.0.0.1:{port}"):
            system = drone.first_autopilot(10.0)
            assert system is not None, "MAVSDK did not discover the autopilot"
            tel = Telemetry(system)
            assert wait_until(lambda: tel.flight_mode() == FlightMode.HOLD, 5.0)
    finally:
        drone.destroy()
