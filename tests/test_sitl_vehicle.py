"""The simulated vehicle (``sitl.vehicle.Vehicle``) stepped on its own, without a server or a link."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from mavcore.mission import load_mission
from sitl.collision import CrashEvent
from sitl.flightstack import FlightMode
from sitl.vehicle import Vehicle

MISSION = Path(__file__).resolve().parent.parent / "missions" / "flat-rectangle" / "mission.yaml"


def vehicle(seed: int = 7, sensor_hz: int = 250) -> Vehicle:
    return Vehicle(load_mission(MISSION), seed=seed, physics_hz=1000, sensor_hz=sensor_hz, start=None,
                   autopilot="px4", lockstep=True)


def test_disarmed_it_steps_one_sensor_period_a_frame_and_stays_on_the_ground():
    v = vehicle(sensor_hz=200)
    f0 = v.start()
    assert v.frame is f0 and v.frames == 0
    home = tuple(v.home_enu_m)
    for _ in range(50):
        frame = v.step()
    # 200 Hz: 5000 us a frame; 50 frames after frame 0
    assert v.time_us == f0.time_us + 50 * 5000 and frame.time_us == v.time_us and v.frames == 50
    assert v.setpoint is None and not v.stack.armed
    assert v.sim.plant.landed and v.sim.plant.p[2] == pytest.approx(home[2], abs=1e-6)
    s = v.state()                      # the flight stack's view: where it stands, level
    assert s.landed and math.dist(s.pos_enu_m, home) < 0.05 and s.tilt_rad < 0.01
    # motors off: the battery gave the avionics' power over the 50 frames stepped (0.25 s)
    p_w = v.battery.cfg.avionics_power_w
    assert p_w > 0 and v.battery.consumed_wh == pytest.approx(p_w * 0.25 / 3600.0, rel=1e-3)


def test_armed_in_takeoff_it_climbs_and_the_same_seed_flies_the_same_frames():
    def fly(seed):
        v = vehicle(seed)
        v.start()
        v.step()
        now, st = v.time_us, v.state()
        v.stack.takeoff(now, st, None)
        assert v.stack.arm(now, st).accepted
        for _ in range(750):            # 3 s of vehicle time
            v.step()
        return v

    a, b = fly(7), fly(7)
    assert a.stack.armed and a.stack.mode in (FlightMode.TAKEOFF, FlightMode.LOITER)
    assert a.sim.plant.p[2] > a.home_enu_m[2] + 1.0 and not a.sim.plant.landed
    assert a.setpoint is not None                   # the onboard controller flew the stack's setpoint
    assert tuple(a.sim.plant.p) == tuple(b.sim.plant.p) and a.time_us == b.time_us
    # the rotors' power on top of the avionics' (3 s of frames after the first)
    assert a.battery.consumed_wh > 1.5 * a.battery.cfg.avionics_power_w * 3.0 / 3600.0


def test_a_crash_is_told_to_the_flight_stack_once():
    v = vehicle()
    v.start()
    v.step()
    assert not v.check_crash()                     # nothing hit
    v.sim.crash = CrashEvent(v.time_us, "terrain", None, tuple(v.sim.plant.p), (0.0, 0.0, -3.0))
    assert v.check_crash() and v.stack.crashed     # the stack hears of it (STATUSTEXT, EMERGENCY) ...
    assert not v.check_crash()                     # ... once
