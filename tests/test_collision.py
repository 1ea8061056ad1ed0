"""Crashes in the SITL (sitl/collision.py, the crash hooks of sitl/plant.py,
sitl/sim.py and sitl/flightstack.py) with hand-placed geometry.

Flights here are straight lines at constant velocity: a level vehicle with
every rotor at a quarter of its weight keeps its velocity exactly (no drag),
so the contact point is where the geometry says, to the contact tolerance.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore.errors import MissionError
from mavcore.geometry import Box, Cylinder, SceneGeometry
from mavcore.maps.grid import OccupancyGrid
from mavcore.mission.loader import load_mission
from mavcore.mission.schema import HomeConfig, Mission
from mavcore.mission.sim import CollisionConfig, NoiseConfig, ObstacleConfig, SimConfig, vehicle_radius_m
from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig
from sitl.collision import CollisionMonitor, CrashEvent, landing_intended
from sitl.flightstack import FlightMode, FlightStack, NavState, Parameters
from sitl.onboard import Setpoint
from sitl.sim import Simulation
from sitl.world import World

QUIET = NoiseConfig(vector_variance=0.0, gyro_variance=0.0, range_std_m=0.0)
VEH = VehicleConfig()
HOVER = VEH.mass_kg * GRAVITY_M_S2 / 4.0 / VEH.max_thrust_per_rotor_n   # normalised command
HOVER4 = (HOVER,) * 4
EPS = 1e-5   # contact tolerance of the checks (m): the search stops within 1e-6 of the surface


def _mission(obstacles=(), radius=None, **collision):
    col = CollisionConfig(vehicle_radius_m=radius, **collision)
    return Mission(name="t", map="m.yaml", dem="d.asc", home=HomeConfig(44.8, -0.6, 30.0),
                   sim=SimConfig(obstacles=tuple(obstacles), noise=QUIET, rangefinders=(), collision=col))


def _sim(obstacles=(), radius=None, grid=None, **collision):
    m = _mission(obstacles, radius, **collision)
    world = World.build(grid, None, m.sim.obstacles, m.sim.canopy_height_m)
    return Simulation(m, np.random.default_rng(0), world=world, start_enu_m=(0.0, 0.0))


def _glide(sim, p, v, frames):
    """Put the vehicle in level flight at p with velocity v (hover thrust) and
    fly ``frames`` sensor frames; returns the positions at the frame ends."""
    f = VEH.mass_kg * GRAVITY_M_S2 / 4.0
    sim.plant.set_state(p, v=v, f=(f,) * 4)
    ends = []
    for _ in range(frames):
        sim.step_frame(HOVER4)
        ends.append(sim.plant.p)
    return ends


def _settle(sim, seconds=3.0):
    for _ in range(int(seconds * 250)):
        sim.step_frame((1.0,) * 4)   # full throttle: a crashed vehicle ignores it


# --- the monitor alone -----------------------------------------------------------------


def _scene(*solids):
    return SceneGeometry(tuple(solids), None, lambda x, y: 0.0)


def test_sweep_finds_the_first_contact_on_the_chord():
    mon = CollisionMonitor(_scene(Cylinder(0.0, 0.0, 0.0, 3.0, 0.25)), 0.5, CollisionConfig())
    c = mon.sweep((2.0, 0.0, 1.0), (0.5, 0.0, 1.0))
    # the centre reaches 0.25 + 0.5 from the axis at x = 0.75: (2 - 0.75) / 1.5 of the chord
    assert c.kind == "cylinder" and c.obstacle_index == 0
    assert c.fraction == pytest.approx(1.25 / 1.5, abs=EPS)
    # a chord passing the axis at 0.76 m is clear, at 0.74 m it touches
    assert mon.sweep((-1.0, 0.76, 1.0), (1.0, 0.76, 1.0)) is None
    assert mon.sweep((-1.0, 0.74, 1.0), (1.0, 0.74, 1.0)) is not None
    # over the top: clear by 1 cm, then touching
    assert mon.sweep((-1.0, 0.0, 3.51), (1.0, 0.0, 3.51)) is None
    assert mon.sweep((-1.0, 0.0, 3.49), (1.0, 0.0, 3.49)).fraction < 0.5


def test_sweep_through_a_thin_box_that_both_ends_miss():
    """5 m/s for one 4 ms frame: a 2 cm chord across a 4 mm wall with a 2 mm
    sphere. Neither end of the chord is in contact, the middle is."""
    box = Box(1.0, 0.0, 0.0, 3.0, 0.002, 1.0)
    r = 0.002
    mon = CollisionMonitor(_scene(box), r, CollisionConfig())
    p0, p1 = (0.989, 0.0, 1.0), (1.009, 0.0, 1.0)
    assert box.signed_distance_m(*p0) > r and box.signed_distance_m(*p1) > r
    c = mon.sweep(p0, p1)
    assert c is not None and c.kind == "box"
    assert c.fraction == pytest.approx((0.996 - 0.989) / 0.02, abs=EPS / 0.02)


def test_buckets_only_hold_nearby_obstacles_and_long_chords_check_all():
    far = Cylinder(100.0, 100.0, 0.0, 3.0, 0.25)
    near = Cylinder(0.0, 0.0, 0.0, 3.0, 0.25)
    mon = CollisionMonitor(_scene(far, near), 0.4, CollisionConfig())
    assert mon.sweep((-2.0, 0.0, 1.0), (-0.5, 0.0, 1.0)).obstacle_index == 1
    # a 50 m chord (teleport) ending far from both still finds the one it crosses
    assert mon.sweep((100.0, 50.0, 1.0), (100.0, 150.0, 1.0)).obstacle_index == 0


@pytest.mark.parametrize("vel, landing, crash", [
    ((0.0, 0.0, -0.7), True, False),     # a landing at PX4's MPC_LAND_SPEED
    ((0.0, 0.0, -1.01), True, True),     # faster than 1 m/s down
    ((0.3, 0.4, -0.2), True, False),     # 0.5 m/s sideways: the limit itself
    ((0.3, 0.41, -0.2), True, True),     # just over it
    ((0.0, 0.0, -0.09), False, False),   # not landing, but a 9 cm/s hop
    ((0.0, 0.0, -0.3), False, True),     # not landing: 0.3 m/s into the ground
])
def test_touchdown_rules(vel, landing, crash):
    mon = CollisionMonitor(_scene(), 0.4, CollisionConfig())
    assert mon.touchdown_is_crash(vel, landing) is crash


def test_landing_intent():
    g = 1.0
    assert landing_intended(True, Setpoint((0.0, 0.0, 5.0)), g)                      # AUTO.LAND / disarmed
    assert landing_intended(False, None, g)
    assert landing_intended(False, Setpoint((0.0, 0.0, 1.15)), g)                    # 15 cm above the ground
    assert not landing_intended(False, Setpoint((0.0, 0.0, 1.25)), g)                # 25 cm: flying
    assert landing_intended(False, Setpoint((0.0, 0.0, math.nan), (0.0, 0.0, -0.5)), g)   # descent by velocity
    assert not landing_intended(False, Setpoint(None, (0.0, 0.0, 0.5)), g)           # climbing


def test_crash_text_names_what_and_where_and_fits_one_chunk():
    e = CrashEvent(1, "cylinder", 0, (10.0, 3.75, 1.2), (0.6, 0.8, 0.2))
    assert e.text == "CRASH: cylinder #1 at E10.00 N3.75 U1.20, 1.02 m/s"
    assert CrashEvent(1, "row", None, (1.0, -2e-17, 0.5), (1.0, 0.0, 0.0)).text == \
        "CRASH: vine row at E1.00 N0.00 U0.50, 1.00 m/s"
    long = CrashEvent(1, "box", 11, (-1234.567, 9876.54, 123.4), (0.0, 0.0, -12.0))
    assert len(long.text) <= 50 and long.text.startswith("CRASH") and "box #12" in long.text
    assert long.text == "CRASH: box #12 E-1234.57 N9876.54 U123.40 12.00m/s"   # fewer words first
    huge = CrashEvent(1, "cylinder", 99, (-12345.678, -12345.678, 1234.5), (30.0, 0.0, 0.0))
    assert huge.text == "CRASH cylinder #100 E-12346 N-12346 U1234 30m/s"     # then fewer decimals


def test_rest_height_on_top_of_what_is_under():
    box = Box(0.0, 0.0, 0.0, 1.2, 0.4, 0.3)
    mon = CollisionMonitor(_scene(box), 0.4, CollisionConfig())
    assert mon.rest_height_m(0.1, 0.1, 2.0) == pytest.approx(1.2)   # over the box
    assert mon.rest_height_m(0.5, 0.1, 2.0) == 0.0                   # beside it
    assert mon.rest_height_m(0.1, 0.1, -1.0) == -1.0                 # never upward


def test_vehicle_radius_default_is_arm_plus_a_10_inch_propeller():
    assert vehicle_radius_m(SimConfig(), 0.315) == pytest.approx(0.315 + 0.127)
    assert vehicle_radius_m(SimConfig(collision=CollisionConfig(vehicle_radius_m=0.5)), 0.315) == 0.5


# --- the simulation: each kind of contact ------------------------------------------------


def _assert_at_rest_crashed(sim, z_rest):
    pl = sim.plant
    assert pl.crashed and pl.landed
    assert pl.p[2] == pytest.approx(z_rest, abs=1e-9)
    assert pl.v == (0.0, 0.0, 0.0) and pl.f == (0.0, 0.0, 0.0, 0.0)


def test_cylinder_side_then_falls_and_rests():
    r = 0.442
    sim = _sim([ObstacleConfig("cylinder", x=3.0, y=0.0, height=2.5, radius=0.25)], radius=r)
    _glide(sim, (0.0, 0.0, 1.5), (1.0, 0.0, 0.0), 750)
    c = sim.crash
    assert c.kind == "cylinder" and c.obstacle_index == 0
    assert c.pos_enu_m[0] == pytest.approx(3.0 - 0.25 - r, abs=EPS) and abs(c.pos_enu_m[1]) < 1e-9
    assert c.speed_m_s == pytest.approx(1.0, abs=1e-6)
    # contact time: 2.308 m at 1 m/s from t = 0
    assert c.time_us == pytest.approx(1e6 * (3.0 - 0.25 - r), abs=2.0)
    _assert_at_rest_crashed(sim, 0.0)
    assert sim.plant.p[0] == pytest.approx(c.pos_enu_m[0])          # fell straight down
    assert c.text.startswith("CRASH: cylinder #1 at E2.31 N0.00 U1.50, 1.00 m/s")


def test_cylinder_top_rests_on_it():
    sim = _sim([ObstacleConfig("cylinder", x=1.0, y=1.0, height=1.0, radius=0.5)], radius=0.3)
    _glide(sim, (1.1, 1.0, 2.0), (0.0, 0.0, -0.5), 500)
    c = sim.crash
    assert c.kind == "cylinder" and c.pos_enu_m[2] == pytest.approx(1.0 + 0.3, abs=EPS)
    _settle(sim, 1.0)
    _assert_at_rest_crashed(sim, 1.0)   # its centre is over the top: it stays there


def test_yawed_box_corner():
    yaw = math.radians(30.0)
    box = ObstacleConfig("box", x=4.0, y=2.0, height=3.0, size_x=1.0, size_y=0.6, yaw_deg=30.0)
    c, s = math.cos(yaw), math.sin(yaw)
    corner = np.array([4.0 - c * 0.5 + s * 0.3, 2.0 - s * 0.5 - c * 0.3])   # the box's (-x, -y) corner
    u = np.array([-c + s, -s - c]) / math.sqrt(2.0)                         # outward along its diagonal
    r = 0.2
    start = corner + 3.0 * u
    sim = _sim([box], radius=r)
    _glide(sim, (start[0], start[1], 1.0), (-u[0], -u[1], 0.0), 1000)
    hit = sim.crash
    assert hit.kind == "box"
    # the corner is a vertical edge: first touched when the centre is r from it
    np.testing.assert_allclose(hit.pos_enu_m[:2], corner + r * u, atol=EPS)


def test_vine_row_from_the_side():
    occ = np.zeros((40, 60), dtype=bool)
    occ[20:24, 10:50] = True             # 0.1 m cells: row y in [2.0, 2.4], x in [1.0, 5.0]
    grid = OccupancyGrid(occ, ~occ, 0.1, (0.0, 0.0), 0.0)
    r = 0.442
    sim = _sim(radius=r, grid=grid)
    _glide(sim, (3.0, 0.5, 1.5), (0.0, 1.0, 0.0), 500)
    c = sim.crash
    assert c.kind == "row" and c.obstacle_index is None
    assert c.pos_enu_m[1] == pytest.approx(2.0 - r, abs=EPS)
    assert c.text.startswith("CRASH: vine row at E3.00 N1.56")
    _settle(sim, 2.0)
    _assert_at_rest_crashed(sim, 0.0)
    # over the canopy (2.0 m rows, default height) by 1 cm: no crash
    sim2 = _sim(radius=r, grid=grid)
    _glide(sim2, (3.0, 0.5, 2.0 + r + 0.01), (0.0, 1.0, 0.0), 1000)
    assert sim2.crash is None


def test_swept_at_5_m_s_through_a_thin_box():
    """No tunnelling: a 4 mm wall, a 2 mm vehicle and 2 cm frames."""
    sim = _sim([ObstacleConfig("box", x=1.0, y=0.0, height=3.0, size_x=0.004, size_y=2.0)], radius=0.002)
    ends = _glide(sim, (0.509, 0.0, 1.0), (5.0, 0.0, 0.0), 200)
    # the frame ends straddle the wall without touching it ...
    assert any(abs(p[0] - 0.989) < 1e-9 for p in ends[:30])
    assert sim.crash is not None and sim.crash.kind == "box"
    # ... and the contact is where the sphere first touches the wall's face
    assert sim.crash.pos_enu_m[0] == pytest.approx(1.0 - 0.002 - 0.002, abs=EPS)
    # without the swept check the same flight would pass: frames ended at 0.989 and 1.009
    wall = Box(1.0, 0.0, 0.0, 3.0, 0.002, 1.0)
    assert wall.signed_distance_m(0.989, 0.0, 1.0) > 0.002 and wall.signed_distance_m(1.009, 0.0, 1.0) > 0.002


def test_terrain_hit_at_speed_is_a_crash_with_the_free_fall_speed():
    sim = _sim()
    sim.plant.set_state((0.0, 0.0, 2.0))
    for _ in range(500):
        sim.step_frame((0.0,) * 4)           # motors off: free fall from 2 m
    c = sim.crash
    assert c.kind == "terrain"
    assert c.speed_m_s == pytest.approx(math.sqrt(2.0 * GRAVITY_M_S2 * 2.0), rel=2e-3)
    _assert_at_rest_crashed(sim, 0.0)


def test_landing_and_takeoff_are_not_crashes():
    sim = _sim()
    _glide(sim, (0.0, 0.0, 0.5), (0.0, 0.0, -0.7), 250)   # touches down at 0.7 m/s
    assert sim.plant.landed and sim.plant.touchdowns == 1 and sim.crash is None
    for _ in range(250):
        sim.step_frame((HOVER * 1.2,) * 4)                  # lifts off and climbs
    assert not sim.plant.landed and sim.plant.p[2] > 0.2 and sim.crash is None


def test_unplanned_touchdown_is_a_crash_only_when_not_landing():
    sim = _sim()
    sim.landing_intent = lambda: False
    _glide(sim, (0.0, 0.0, 0.5), (0.0, 0.0, -0.7), 250)
    assert sim.crash is not None and sim.crash.kind == "terrain"
    sim2 = _sim()
    sim2.landing_intent = lambda: True
    _glide(sim2, (0.0, 0.0, 0.5), (0.0, 0.0, -0.7), 250)
    assert sim2.crash is None


def test_sideways_touchdown_is_a_crash_even_when_landing():
    sim = _sim()
    _glide(sim, (0.0, 0.0, 0.05), (0.6, 0.0, -0.3), 100)
    assert sim.crash is not None and sim.crash.kind == "terrain"


def test_crashed_vehicle_stays_down_until_reset():
    sim = _sim([ObstacleConfig("cylinder", x=1.0, y=0.0, height=2.0, radius=0.2)], radius=0.3)
    _glide(sim, (0.0, 0.0, 1.0), (2.0, 0.0, 0.0), 250)
    _settle(sim, 2.0)
    assert sim.plant.p[2] == 0.0 and sim.plant.landed and sim.plant.f == (0.0,) * 4
    sim.reset((0.0, 0.0))
    assert sim.crash is None and not sim.plant.crashed
    for _ in range(250):
        sim.step_frame((HOVER * 1.2,) * 4)
    assert sim.plant.p[2] > 0.2


def test_collisions_can_be_turned_off():
    sim = _sim([ObstacleConfig("cylinder", x=1.0, y=0.0, height=2.0, radius=0.2)], radius=0.3, enabled=False)
    _glide(sim, (0.0, 0.0, 1.0), (2.0, 0.0, 0.0), 500)
    assert sim.crash is None and sim.plant.p[0] > 3.0


# --- the flight stack --------------------------------------------------------------------


def _nav(z=1.5, landed=False):
    return NavState(np.array([0.0, 0.0, z]), np.zeros(3), 0.0, 0.0, landed)


def test_flight_stack_crash_cuts_motors_reports_and_refuses_to_fly():
    st = FlightStack(Parameters(), (0.0, 0.0, 0.0))
    assert st.arm(0, _nav(0.0, True)).accepted
    st.takeoff(0, _nav(0.0, True), 1.5)
    st.update(10_000, _nav(1.0))
    assert st.system_status == mavlink.MAV_STATE_ACTIVE
    st.pop_events()
    ev = CrashEvent(20_000, "box", 0, (1.0, 2.0, 1.0), (1.0, 0.0, 0.0))
    st.crash(20_000, ev)
    texts = st.pop_events()
    assert [(e.severity, e.text) for e in texts] == [(mavlink.MAV_SEVERITY_CRITICAL, ev.text)]
    assert st.system_status == mavlink.MAV_STATE_EMERGENCY
    out = st.update(24_000, _nav(0.8))                       # falling: motors cut, still armed
    assert not out.armed and st.armed
    assert st.landed_state == mavlink.MAV_LANDED_STATE_IN_AIR
    st.update(28_000, _nav(0.0, True))                       # at rest: disarmed
    assert not st.armed and "Disarmed (crashed)" in [e.text for e in st.pop_events()]
    assert st.landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND
    assert st.system_status == mavlink.MAV_STATE_EMERGENCY
    for refused in (st.arm(30_000, _nav(0.0, True)), st.arm(30_000, _nav(0.0, True), force=True),
                    st.takeoff(30_000, _nav(0.0, True), 2.0), st.land(30_000, _nav(0.0, True)),
                    st.set_mode(30_000, _nav(0.0, True), FlightMode.POSCTL)):
        assert refused.result == mavlink.MAV_RESULT_DENIED and refused.reason == "crashed"
    assert not st.armed


def test_flight_stack_landing_intent_follows_mode_and_setpoint():
    st = FlightStack(Parameters(), (0.0, 0.0, 0.0))
    assert st.landing_intended(0.0)                          # disarmed
    st.arm(0, _nav(0.0, True))
    st.takeoff(0, _nav(0.0, True), 3.0)
    st.update(0, _nav(0.0, True))
    st.update(1_000_000, _nav(1.0))                          # climbing, setpoint 1.5 m up
    assert not st.landing_intended(0.0)
    st.land(1_000_000, _nav(1.0))
    st.update(1_004_000, _nav(1.0))
    assert st.landing_intended(0.0)


# --- the mission keys -----------------------------------------------------------------------


def test_collision_keys_in_a_mission_file(tmp_path):
    p = tmp_path / "m.yaml"
    p.write_text("name: t\nmap: m.yaml\ndem: d.asc\nhome: {lat: 44.8, lon: -0.6, alt_m: 30.0}\n"
                 "sim: {collision: {vehicle_radius_m: 0.5, touchdown_max_down_m_s: 1.5}}\n")
    m = load_mission(p)
    assert m.sim.collision.vehicle_radius_m == 0.5 and m.sim.collision.touchdown_max_down_m_s == 1.5
    p.write_text("name: t\nmap: m.yaml\ndem: d.asc\nhome: {lat: 44.8, lon: -0.6, alt_m: 30.0}\n"
                 "sim: {collision: {radius: 0.5}}\n")
    with pytest.raises(MissionError, match="sim.collision.radius"):
        load_mission(p)
    p.write_text("name: t\nmap: m.yaml\ndem: d.asc\nhome: {lat: 44.8, lon: -0.6, alt_m: 30.0}\n"
                 "sim: {collision: {vehicle_radius_m: -1}}\n")
    with pytest.raises(MissionError, match="vehicle_radius_m"):
        load_mission(p)


@pytest.mark.parametrize("kind, index, pos, vel", [
    ("cylinder", 0, (10.0, 3.75, 1.2), (0.6, 0.8, 0.2)),
    ("box", 11, (-1234.567, 9876.54, 123.4), (0.0, 0.0, -12.0)),
    ("cylinder", 99, (-12345.678, -12345.678, 1234.5), (30.0, 0.0, 0.0)),
    ("row", None, (3.0, 1.558, 1.5), (0.0, 1.0, 0.0)),
    ("terrain", None, (0.5, -2e-17, 0.0), (0.0, 0.0, -6.26)),
])
def test_the_companion_reads_the_crash_text_back(kind, index, pos, vel):
    from companion.link.crash_text import parse_crash

    e = CrashEvent(5, kind, index, pos, vel)
    got = parse_crash(e.text)
    assert got.kind == kind and got.obstacle_index == index and got.what == e.what
    tol = 0.5 if "E-12346" in e.text else 0.05 if "E-1234.6" in e.text else 0.005
    np.testing.assert_allclose(got.pos_enu_m, pos, atol=tol)
    assert got.speed_m_s == pytest.approx(e.speed_m_s, abs=tol)
    assert parse_crash("Disarmed (crashed)") is None and parse_crash("Land denied: crashed") is None


def test_rest_height_on_a_row():
    occ = np.zeros((40, 60), dtype=bool)
    occ[20:24, 10:50] = True
    grid = OccupancyGrid(occ, ~occ, 0.1, (0.0, 0.0), 0.0)
    sim = _sim(radius=0.3, grid=grid)
    assert sim.collisions.rest_height_m(3.0, 2.2, 3.0) == pytest.approx(2.0)   # on the canopy (2 m rows)
    assert sim.collisions.rest_height_m(3.0, 1.5, 3.0) == 0.0
