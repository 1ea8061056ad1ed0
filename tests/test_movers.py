"""Moving obstacles (sim.movers): kinematics, rangefinder returns, crashes, bad specs.

Every expected value is worked by hand from the scripted path: a walker is a
cylinder of radius 0.25 m, 1.8 m tall (``mavcore.mission.sim``); the
vehicle sphere's radius is set to 0.4 m here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavcore.errors import MissionError
from mavcore.mission import load_mission
from mavcore.mission.schema import HomeConfig, Mission
from mavcore.mission.sim import (CollisionConfig, MoverConfig, NoiseConfig, RangefinderConfig, SimConfig,
                                 WALKER_RADIUS_M)
from mavcore.movers import mover_pose, movers_nearest
from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig
from sitl.sensors import Rangefinder
from sitl.sim import Simulation
from sitl.world import World

GOOD = """\
name: test
map: maps/map.yaml
home: {lat: 44.8, lon: -0.6, alt_m: 30.0}
flight: {height_agl_m: 2.0, speed_m_s: 1.5, waypoint_interval_s: 3.0}
coverage: {line_spacing_m: 2.5, safety_margin_m: 0.45}
pointing: {target: [1.0, 2.0, 3.0]}
"""


def write(tmp_path, text):
    p = tmp_path / "mission.yaml"
    p.write_text(text)
    return p

LEVEL = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
RING = RangefinderConfig(id=0, orientation=0, hfov_deg=22.5, vfov_deg=2.0, max_m=10.0, min_m=0.1)
VEH = VehicleConfig()
RADIUS = 0.4


# --- kinematics ---------------------------------------------------------------------


def test_pose_on_an_l_shaped_path_worked_by_hand():
    # legs 3 m east then 4 m north (L = 7 m), 1 m/s, waits 2 s
    c = MoverConfig("walker", ((0.0, 0.0), (3.0, 0.0), (3.0, 4.0)), 1.0, loop=False, start_s=2.0)
    p = mover_pose(c, 1.0)
    assert (p.x_m, p.y_m, p.vx_m_s) == (0.0, 0.0, 0.0)             # waiting at path[0]
    p = mover_pose(c, 4.5)                                          # 2.5 m along the first leg
    assert (p.x_m, p.y_m) == pytest.approx((2.5, 0.0)) and p.vx_m_s == 1.0 and p.heading_rad == 0.0
    p = mover_pose(c, 7.0)                                          # 5 m: 2 m up the second leg
    assert (p.x_m, p.y_m) == pytest.approx((3.0, 2.0)) and p.heading_rad == pytest.approx(math.pi / 2)
    p = mover_pose(c, 100.0)                                        # stopped at the end
    assert (p.x_m, p.y_m) == pytest.approx((3.0, 4.0)) and p.vx_m_s == p.vy_m_s == 0.0


def test_looping_walker_goes_back_and_forth():
    c = MoverConfig("walker", ((0.0, 0.0), (3.0, 0.0), (3.0, 4.0)), 1.0, loop=True, start_s=2.0)
    p = mover_pose(c, 2.0 + 7.0 + 2.0)                              # 2 m back from the far end
    assert (p.x_m, p.y_m) == pytest.approx((3.0, 2.0)) and p.vy_m_s == pytest.approx(-1.0)
    p = mover_pose(c, 2.0 + 14.0 + 1.5)                             # a full round trip, then 1.5 m
    assert (p.x_m, p.y_m) == pytest.approx((1.5, 0.0)) and p.vx_m_s == pytest.approx(1.0)


def test_tractor_box_is_long_along_its_heading():
    # a tractor driving north: 3 m along y, 1.5 m along x
    c = MoverConfig("tractor", ((10.0, 0.0), (10.0, 20.0)), 2.0)
    d, k = movers_nearest((c,), 5.0, lambda x, y: 0.0, 10.0 + 2.0, 10.0, 1.0)   # centre (10, 10)
    assert k == 0 and d == pytest.approx(2.0 - 0.75)
    d, _ = movers_nearest((c,), 5.0, lambda x, y: 0.0, 10.0, 10.0 + 3.0, 1.0)
    assert d == pytest.approx(3.0 - 1.5)


# --- the SITL sees them where they are -----------------------------------------------


def _crossing(start_s=0.0, speed=1.5):
    """A walker crossing the beam 3 m ahead: from (3, -3) to (3, 3)."""
    return MoverConfig("walker", ((3.0, -3.0), (3.0, 3.0)), speed, start_s=start_s)


def test_rangefinder_returns_a_walker_at_its_true_range():
    world = World.build(movers=(_crossing(),))
    rf = Rangefinder(RING, 0)
    world.set_time(0.0)                          # at (3, -3): 45 deg off a 22.5 deg beam
    assert rf.true_distance(world, (0.0, 0.0, 1.5), LEVEL) == math.inf
    world.set_time(2.0)                          # 3 m walked at 1.5 m/s: on the axis
    assert rf.true_distance(world, (0.0, 0.0, 1.5), LEVEL) == pytest.approx(3.0 - WALKER_RADIUS_M, abs=0.02)
    # 0.4 s later it is 0.6 m aside, 11.3 deg: the nearest point in view is on the beam's edge
    world.set_time(2.4)
    a = math.radians(11.25)
    off = 3.0 * math.sin(math.atan2(0.6, 3.0) - a) * math.hypot(3.0, 0.6) / 3.0
    expect = math.hypot(3.0, 0.6) * math.cos(math.atan2(0.6, 3.0) - a) - math.sqrt(WALKER_RADIUS_M ** 2 - off ** 2)
    assert rf.true_distance(world, (0.0, 0.0, 1.5), LEVEL) == pytest.approx(expect, abs=0.02)


def _mission(movers, radius=RADIUS):
    return Mission(name="t", map="m.yaml", dem="d.asc", home=HomeConfig(44.8, -0.6, 30.0),
                   sim=SimConfig(movers=tuple(movers), noise=NoiseConfig(vector_variance=0.0, gyro_variance=0.0,
                                                                          range_std_m=0.0),
                                 rangefinders=(), collision=CollisionConfig(vehicle_radius_m=radius)))


def _hover(sim, p, frames):
    f = VEH.mass_kg * GRAVITY_M_S2 / 4.0
    sim.plant.set_state(p, v=(0.0, 0.0, 0.0), f=(f,) * 4)
    hover = (f / VEH.max_thrust_per_rotor_n,) * 4
    for _ in range(frames):
        sim.step_frame(hover)
        if sim.crash is not None:
            return


def test_the_simulation_poses_movers_on_the_vehicle_clock():
    sim = Simulation(_mission((_crossing(),)), np.random.default_rng(0), start_enu_m=(0.0, 0.0))
    for _ in range(250):                         # 1 s of 4 ms frames
        sim.step_frame((0.0,) * 4)
    ob = sim.world.obstacles_now[0]
    assert sim.time_us == 1_000_000 and (ob.x, ob.y) == pytest.approx((3.0, -1.5), abs=1e-12)


def test_a_walker_walking_into_a_hovering_vehicle_is_a_crash_that_names_it():
    sim = Simulation(_mission((_crossing(),)), np.random.default_rng(0), start_enu_m=(0.0, 0.0))
    _hover(sim, (3.0, 0.0, 1.0), 750)
    c = sim.crash
    assert c is not None and c.kind == "walker" and c.obstacle_index == 0
    assert c.text.startswith("CRASH: walker #1")
    from companion.link.crash_text import parse_crash

    back = parse_crash(c.text)                   # the companion reads it back
    assert back is not None and (back.kind, back.obstacle_index) == ("walker", 0)
    # contact when the walker's axis is radius + 0.25 m from the vehicle: 3 - 0.65 m walked at 1.5 m/s
    t_contact = (3.0 - (RADIUS + WALKER_RADIUS_M)) / 1.5
    assert c.time_us * 1e-6 == pytest.approx(t_contact, abs=0.005)


def test_a_walker_passing_at_more_than_the_radius_is_no_crash():
    # the walker's axis passes 0.7 m from the vehicle centre: 0.05 m of air between the surfaces
    walker = MoverConfig("walker", ((3.7, -3.0), (3.7, 3.0)), 1.5)
    sim = Simulation(_mission((walker,)), np.random.default_rng(0), start_enu_m=(0.0, 0.0))
    _hover(sim, (3.0, 0.0, 1.0), 750)
    assert sim.crash is None


# --- bad specs ----------------------------------------------------------------------


@pytest.mark.parametrize("movers, match", [
    ("[{type: walker, path: [[0, 0]], speed_m_s: 1.0}]", r"at least 2 points"),
    ("[{type: walker, path: [[0, 0], [0, 0]], speed_m_s: 1.0}]", r"equal consecutive"),
    ("[{type: walker, path: [[0, 0], [5, 0]], speed_m_s: 2.0}]", r"speed_m_s must be in \(0, 1.5\]"),
    ("[{type: tractor, path: [[0, 0], [5, 0]], speed_m_s: 0}]", r"speed_m_s must be in \(0, 5\]"),
    ("[{type: horse, path: [[0, 0], [5, 0]], speed_m_s: 1.0}]", r"sim\.movers\[0\]\.type"),
    ("[{type: walker, path: [[0, 0], [5, .nan]], speed_m_s: 1.0}]", r"finite"),
    ("[{type: walker, path: [[0, 0], [5, 0]], speed_m_s: 1.0, start_s: -1}]", r"start_s must be >= 0"),
    ("[{type: walker, path: [[0, 0], [5, 0]], speed: 1.0}]", r"speed.*unknown key|unknown key.*speed"),
])
def test_bad_mover_specs_name_the_problem(tmp_path, movers, match):
    with pytest.raises(MissionError, match=match):
        load_mission(write(tmp_path, GOOD + f"sim: {{movers: {movers}}}\n"))


def test_bad_mover_spec_is_one_line_exit_2(tmp_path, capsys):
    from companion.cli import main

    path = write(tmp_path, GOOD + "sim: {movers: [{type: walker, path: [[0, 0], [5, 0]], speed_m_s: 9}]}\n")
    assert main(["plan", str(path), "-o", str(tmp_path / "plan.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "mission.yaml" in err[0] and "speed_m_s" in err[0]
    assert not (tmp_path / "plan.json").exists()


# --- the companion's closing-speed rule (companion/replan/closing.py) ------------------


def test_closing_speed_of_a_walker_coming_down_the_beam():
    from companion.replan.closing import ClosingSpeed

    c = ClosingSpeed()
    u = (1.0, 0.0, 0.0)                          # beam along +x
    # a walker at 1.5 m/s toward the sensor: its surface 5.0 m, then 0.6 m nearer 0.4 s later
    for k in range(9):
        c.on_hit(0.05 * k, 3, (5.0 - 1.5 * 0.05 * k, 0.0, 1.5), u)
    assert c.approach_m_s(0.4) == pytest.approx(1.5, abs=1e-9)
    assert c.approach_m_s(0.4 + 1.01) == 0.0      # not measured again for HOLD_S: forgotten


def test_still_or_receding_obstacles_have_no_closing_speed():
    from companion.replan.closing import ClosingSpeed

    c = ClosingSpeed()
    u = (1.0, 0.0, 0.0)
    for k in range(20):                            # a post: the hit stays put while the vehicle flies
        c.on_hit(0.05 * k, 0, (5.0, 0.0, 1.5), u)
        c.on_hit(0.05 * k, 1, (5.0 + 1.0 * 0.05 * k, 0.0, 1.5), u)   # a walker walking away
    assert c.approach_m_s(1.0) == 0.0


def test_the_governor_bounds_the_closing_speed_not_the_vehicles_own():
    from companion.replan.closing import allowed_approach_m_s

    # still obstacle: the vehicle may approach at the stopping speed; a walker coming at
    # 1.5 m/s takes that off; with no room left the vehicle backs away at the walker's speed
    assert allowed_approach_m_s(2.0, 0.0) == 2.0
    assert allowed_approach_m_s(2.0, 1.5) == pytest.approx(0.5)
    assert allowed_approach_m_s(0.0, 1.5) == -1.5


# --- one short flight: a walker crosses the first corridor --------------------------------


def _walker_flight(tmp_path, field: str, home: str, seed: int, walker: str, cut_s: str) -> dict:
    """report.json's ``replanning`` of a ``demo`` flight over the bundled ``field``, in
    process, ``give_way`` on, one walker (``walker``: its sim.movers item), cut at
    ``cut_s``; asserts no crash and the configured clearance from the walker's true
    position (SITL truth)."""
    import json

    from companion.cli import main
    from companion.bundled import missions_dir
    from mavcore.mission.replan import ReplanConfig

    fd = missions_dir() / field
    (tmp_path / "m.yaml").write_text(
        f"name: walker-{field}\n"
        f"map: {fd / 'map.yaml'}\ndem: {fd / 'dem.asc'}\n"
        f"home: {home}\n"
        "flight: {height_agl_m: 1.5, speed_m_s: 1.0, waypoint_interval_s: 4.0}\n"
        "coverage: {line_spacing_m: 2.5, safety_margin_m: 0.45}\n"
        "pointing: {target: centroid}\n"
        "replan: {give_way: true}\n"
        f"sim:\n  noise: {{vector_variance: 5.0e-4, gyro_variance: 5.0e-4}}\n  seed: {seed}\n"
        f"  movers: [{walker}]\n")
    out = tmp_path / "out"
    main(["demo", "--mission", str(tmp_path / "m.yaml"), "--transport", "inproc", "--cut", cut_s,
          "--out", str(out), "--no-plots", "--quiet"])
    rep = json.loads((out / "report.json").read_text())
    rp = rep["replanning"]
    assert rep["crashed"] is False and rep["crash"] is None
    assert rp["clearance_source"] == "sim_truth" and rp["min_clearance_obstacle"] == 0    # the walker
    assert rp["min_clearance_m"] >= ReplanConfig.clearance_m
    return rp


def test_vehicle_gives_way_to_a_walker_crossing_the_first_corridor(tmp_path):
    """flat-rectangle's first corridor is flown westward along y = 8.75 m from x = 22 m
    (the trajectory starts about 7 s after boot). A worker steps off the row face at
    (17, 7.8) at 8.3 s and crosses the corridor at 1 m/s, into the next row: mid-corridor
    when the vehicle is about 3 m away. The vehicle must give way (an avoidance event)
    and keep the configured clearance (0.5 m, ``replan.clearance_m``) from the walker's
    true position (the SITL's ground truth), with no crash."""
    rp = _walker_flight(tmp_path, "flat-rectangle", "{lat: 44.8, lon: -0.6, alt_m: 30.0}", 1,
                        "{type: walker, path: [[17.0, 7.8], [17.0, 11.5]], speed_m_s: 1.0, start_s: 8.3}", "9")
    assert any(e["action"] in ("avoid", "stop") for e in rp["event_list"])       # it gave way


def test_vehicle_stops_and_looks_before_passing_a_worker_crossing_its_path(tmp_path):
    """tilted-hexagon's first corridor runs at 30 deg (direction (0.87, 0.5)). A worker
    sets off at 11 s from (7.0, 2.37) toward (4.0, 7.56) at 0.92 m/s (campaign
    obstacles-wide, scenario 7): across the corridor, perpendicular to it, and into the
    vehicle's path 2.4 m ahead of where it is first seen. Flying, the beams sweep, and a
    return moving across a beam reads as still (``closing``); the vehicle avoided it as
    a still obstacle, flew on toward the crossing point and was walked into at
    14.1 s. With ``give_way`` it stops and watches first (``LOOK_S`` at rest), reads the
    worker's motion, gives way and passes only once nothing moves: no crash, and the
    configured clearance from the worker's true position (SITL truth)."""
    rp = _walker_flight(tmp_path, "tilted-hexagon", "{lat: 44.85, lon: -0.55, alt_m: 45.0}", 2,
                        "{type: walker, path: [[6.998, 2.368], [3.998, 7.564]], speed_m_s: 0.919, "
                        "start_s: 10.997}", "10")
    stops = [e for e in rp["event_list"] if e["action"] == "stop"]
    assert stops and "whether it moves" in stops[0]["detail"]          # it looked first


# --- campaign: movers drawn from the seeded per-scenario generator ----------------------


def test_campaign_movers_cross_a_corridor_and_leave_other_draws_alone():
    import dataclasses

    from companion.campaign.scenarios import load_fields, scenario
    from companion.campaign.spec import MoverSpec, spec_from_dict

    base = {"name": "m", "missions": ["flat-rectangle"], "flights": 10, "seed": 3, "cut_s": 20.0,
            "obstacles": {"count": [1, 2], "placement": "rows"}, "wind": {"speed_m_s": [0.0, 2.0]}}
    spec = spec_from_dict({**base, "movers": {"count": [1, 1], "speed_m_s": [0.5, 2.5]}}, "t.yaml")
    plain = spec_from_dict(base, "t.yaml")
    fields = load_fields(spec)
    for i in (0, 7):
        s, p = scenario(spec, fields, i), scenario(plain, fields, i)
        sim = dict(s["overrides"]["sim"])
        movers = sim.pop("movers")
        assert sim == p["overrides"]["sim"] and s["seed"] == p["seed"]      # nothing else moved
        assert scenario(dataclasses.replace(spec, flights=1000), fields, i) == s   # independent of the count
        for mv in movers:
            (ax, ay), (bx, by) = mv["path"]
            # flat-rectangle's corridors run along x: across one is along y, 6 m long
            assert ax == pytest.approx(bx, abs=1e-3) and abs(by - ay) == pytest.approx(MoverSpec.length_m, abs=2e-3)
            assert 0.5 <= mv["speed_m_s"] <= 1.5 and mv["start_s"] >= 0.0      # a walker: capped at 1.5


def test_bad_campaign_mover_spec_names_the_key():
    from companion.campaign.spec import spec_from_dict
    from mavcore.errors import CampaignError

    with pytest.raises(CampaignError, match=r"movers.*kinds|kinds"):
        spec_from_dict({"name": "m", "missions": ["flat-rectangle"], "flights": 1,
                        "movers": {"kinds": ["horse"]}}, "t.yaml")
    with pytest.raises(CampaignError, match=r"movers\.speed_m_s"):
        spec_from_dict({"name": "m", "missions": ["flat-rectangle"], "flights": 1,
                        "movers": {"speed_m_s": [0.5, 9.0]}}, "t.yaml")


def test_a_beam_sliding_over_a_still_wall_is_no_closing_speed():
    from companion.replan.closing import ClosingSpeed

    # flying +x at 1 m/s past a wall; a beam looking back-left at 60 deg from the wall:
    # u = (-cos 60, sin 60); its return slides +x with the vehicle, d.u / |d| = -0.5:
    # 0.5 m/s "toward" the sensor that is only the beam sweeping across the wall
    c = ClosingSpeed()
    u = (-0.5, math.sqrt(3.0) / 2.0, 0.0)
    for k in range(20):
        c.on_hit(0.05 * k, 9, (1.0 * 0.05 * k, 2.0, 1.5), u)
    assert c.approach_m_s(0.95) == 0.0


def test_a_return_riding_with_the_vehicle_is_no_closing_speed():
    """A return that keeps its place relative to the sensor while the vehicle flies west at
    1.8 m/s follows the vehicle along the beam: read as a world speed, a mover chasing at
    1.8 m/s times the beam's level part along the flight. Given the sensor's position it is
    nothing. With a level beam (a return at the sensor's height) only the riding rule can
    tell; with the beam tilted 19 deg down over a canopy's top the return also keeps its
    height where a face coming down the beam would have risen 0.34 m per metre, so the
    level-surface rule drops it even without the sensor's position."""
    from companion.replan.closing import ClosingSpeed

    uh = math.hypot(0.93, 0.2)
    for axis, off, blind_expected in (
            ((0.93 / uh, 0.2 / uh, 0.0), (2.6, 0.56, 0.0), 1.8 * 0.93 / uh),     # level beam
            ((0.93, 0.2, -0.32), (2.6, 0.56, -0.9), 0.0)):                        # tilted over a top
        riding, blind = ClosingSpeed(), ClosingSpeed()
        for k in range(20):
            t = 0.05 * k
            o = (10.0 - 1.8 * t, 8.75, 2.9)
            hit = tuple(a + b for a, b in zip(o, off))
            riding.on_hit(t, 22, hit, axis, origin_enu_m=o)
            blind.on_hit(t, 22, hit, axis)
        assert riding.approach_m_s(0.95) == 0.0
        assert blind.approach_m_s(0.95) == pytest.approx(blind_expected, abs=1e-9)


@pytest.mark.parametrize("vehicle_m_s, walker_m_s", [(0.5, 1.5), (-1.0, 1.2)], ids=("gaining", "head-on"))
def test_a_walker_that_moves_relative_to_the_vehicle_is_measured_at_its_own_speed(vehicle_m_s, walker_m_s):
    """A walker gaining on a vehicle flying away from it (0.5 against 1.5 m/s), or walking
    at a vehicle flying toward it: its return moves relative to the sensor, and the world
    speed toward the sensor is the walker's."""
    from companion.replan.closing import ClosingSpeed

    c = ClosingSpeed()
    u = (-1.0, 0.0, 0.0)                           # looking back (-x) at the walker
    for k in range(20):
        t = 0.05 * k
        o = (vehicle_m_s * t, 0.0, 1.5)
        c.on_hit(t, 4, (-4.0 + walker_m_s * t, 0.0, 1.5), u, origin_enu_m=o)
    assert c.approach_m_s(0.95) == pytest.approx(walker_m_s, abs=1e-9)


def test_a_walker_crossing_the_beam_counts_only_while_the_vehicle_is_still():
    from companion.replan.closing import ClosingSpeed

    # a worker crossing a beam along +x at 0.9 m/s, 3 m ahead: its return moves across
    # the axis (-y, sensor to the north of it). Flying, that is what a beam sweeping
    # over a still wall does, so it is no closing speed; with the vehicle still the
    # beams do not sweep, and the whole level displacement is the worker's speed.
    u = (0.0, -1.0, 0.0)
    crossing = [(0.05 * k, (0.9 * 0.05 * k, 0.0, 1.5)) for k in range(20)]
    flying, still = ClosingSpeed(), ClosingSpeed()
    for t, hit in crossing:
        flying.on_hit(t, 2, hit, u)
        still.on_hit(t, 2, hit, u, still=True)
    assert flying.approach_m_s(0.95) == 0.0
    assert still.approach_m_s(0.95) == pytest.approx(0.9, abs=1e-9)
    # the same still vehicle before a still post: 1 cm of range noise is no mover
    post = ClosingSpeed()
    for k in range(20):
        post.on_hit(0.05 * k, 2, (0.0, 3.0 + 0.01 * (-1) ** k, 1.5), u, still=True)
    assert post.approach_m_s(0.95) == 0.0


def _scenario_replanning(tmp_path, text: str) -> dict:
    """report.json's ``replanning`` of a campaign scenario file (``text``) flown by ``demo`` in
    process; asserts no crash, the clearance measured from SITL truth, and a stop that watched
    the mover before anything else."""
    import json

    from companion.cli import main

    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(text)
    out = tmp_path / "out"
    main(["demo", "--scenario", str(scenario), "--transport", "inproc", "--out", str(out), "--no-plots", "--quiet"])
    rep = json.loads((out / "report.json").read_text())
    assert rep["crashed"] is False and rep["crash"] is None
    rp = rep["replanning"]
    assert rp["clearance_source"] == "sim_truth"
    assert any(e["action"] == "stop" and "whether it moves" in e["detail"] for e in rp["event_list"])
    return rp


def test_a_walker_crossing_straight_at_a_stopped_vehicle_is_given_way_along_the_corridor(tmp_path):
    """Fresh seed 20261151 of campaign obstacles-under, flight 3 (tilted-hexagon): a worker
    stands 2.9 m from the vehicle for 12 s, then walks straight at it across the corridor
    at 1.41 m/s. Backing away along the corridor gains no distance from a mover coming
    across it, and the governor's slight lean along the corridor flipped sign from frame to
    frame: the vehicle stayed put and was walked into (contact at 34.7 s). A stop now moves
    out of a crossing mover's path along the corridor, to the side it chose first, at the
    emergency limits (3 m/s^2, 8 m/s^3: docs/replan.md "The emergency brake"): 0.43 m of
    true clearance. At the normal limits (1 m/s^2, 2 m/s^3; the emergency limits set to them,
    the mutation) the 0.74 m the two radii need is mostly not won in the 1.6 s the walker
    takes: 0.20 m."""
    rp = _scenario_replanning(
        tmp_path,
        "campaign: obstacles-under\nscenario: 3\nmission: tilted-hexagon\nseed: 1472298831\ncut_s: 45.0\n"
        "control: companion\noverrides:\n  sim:\n    obstacles:\n"
        "    - {type: box, x: 6.34, y: 7.884, height: 0.883, size_x: 0.875, size_y: 0.315, yaw_deg: 70.497}\n"
        "    movers:\n    - type: walker\n      path:\n      - [12.922, 15.569]\n      - [15.8, 10.304]\n"
        "      speed_m_s: 1.406\n      loop: false\n      start_s: 33.101\n  replan: {give_way: true}\n")
    assert rp["min_clearance_m"] > 0.3
    assert any(e["detail"].endswith("cannot give way to a mover in time") for e in rp["event_list"])


def test_a_still_post_seen_by_a_beam_turning_at_rest_is_no_mover():
    from companion.replan.closing import ClosingSpeed

    # the vehicle at rest yaws at 7 deg/s (the pointing law); a post 5 m away holds the
    # return at 5 m while the beam turns, so the return placed on the axis slides across it
    # at r w = 5 x 0.1222 = 0.61 m/s. The look's "any motion counts" rule read that as a
    # mover; the beam turned, so the pair is judged by its motion along the axis: none.
    w = math.radians(7.0)
    o = (0.0, 0.0, 1.5)

    def axis(t):
        return (math.cos(w * t), math.sin(w * t), 0.0)

    turning, unjudged = ClosingSpeed(), ClosingSpeed()
    for k in range(20):
        t = 0.05 * k
        u = axis(t)
        hit = (5.0 * u[0], 5.0 * u[1], 1.5)
        turning.on_hit(t, 3, hit, u, still=True, origin_enu_m=o)
        unjudged.on_hit(t, 3, hit, u, still=True)          # no origin: the rule cannot judge
    assert turning.approach_m_s(0.95) == 0.0
    assert unjudged.approach_m_s(0.95) == pytest.approx(5.0 * w, rel=0.02)
    # a walker coming down the same turning beam at 1.2 m/s still reads its speed
    walker = ClosingSpeed()
    for k in range(20):
        t = 0.05 * k
        u = axis(t)
        r = 5.0 - 1.2 * t
        walker.on_hit(t, 3, (r * u[0], r * u[1], 1.5), u, still=True, origin_enu_m=o)
    assert walker.approach_m_s(0.95) == pytest.approx(1.2, abs=0.02)


def test_a_still_vehicle_whose_beam_does_not_turn_still_counts_a_crossing_walker():
    from companion.replan.closing import ClosingSpeed

    # the swept rule needs the beam to move: a fixed beam with its origin known keeps the
    # look's rule (a crossing walker's whole level displacement counts)
    u = (0.0, -1.0, 0.0)
    c = ClosingSpeed()
    for k in range(20):
        c.on_hit(0.05 * k, 2, (0.9 * 0.05 * k, 0.0, 1.5), u, still=True, origin_enu_m=(0.0, 3.0, 1.5))
    assert c.approach_m_s(0.95) == pytest.approx(0.9, abs=1e-9)


def test_in_flight_two_beams_on_one_still_object_are_no_mover():
    from companion.replan.closing import ClosingSpeed

    # a level beam (id 3) returns from a post's face 3 m ahead at 1.5 m; from 0.5 s on, the
    # low ring's beam below it (id 20, same azimuth) returns from the post 0.5 m nearer and
    # 0.5 m lower (its lower, wider part). Paired across the two beams the returns are
    # 0.71 m apart (within the 1 m match) and 0.5 m nearer along the axis: 0.83-1.67 m/s
    # for a still post. In flight only one beam's own returns are paired: no mover.
    u = (1.0, 0.0, 0.0)

    def feed(c, still):
        for k in range(24):
            t = 0.05 * k
            o = (0.3 * t, 0.0, 1.5)                      # flying on at 0.3 m/s (or at rest)
            if still:
                o = (0.0, 0.0, 1.5)
            c.on_hit(t, 3, (3.0, 0.0, 1.5), u, still=still, origin_enu_m=o)
            if t >= 0.5:
                c.on_hit(t, 20, (2.5, 0.0, 1.0), u, still=still, origin_enu_m=o)

    flying, at_rest = ClosingSpeed(), ClosingSpeed()
    feed(flying, False)
    feed(at_rest, True)
    assert flying.approach_m_s(1.15) == 0.0
    # at rest every beam's return is compared (a crossing walker passes from beam to beam):
    # the same returns there pair across the beams, which is what in flight no longer does
    assert at_rest.approach_m_s(1.15) > 0.8


def test_a_walker_coming_up_behind_a_slow_vehicle_is_given_way_at_the_escape_speed(tmp_path):
    """Campaign obstacles-mix (seed 20261126), scenario 84 (tilted-hexagon, the realistic sensor
    profile): after a rejoin the vehicle moves at 0.1 m/s when a worker walks up at 0.96 m/s
    from behind it, across the corridor. Two rules broke there:

    - the avoidance passed over points behind the vehicle, so the measured approach (1.0 m/s
      from 36.0 s) started nothing until the walker was 1.1 m away: 0.26 m of true clearance.
      Behind is safe only in a still world (``Replanner._threat``);
    - the give-way then backed away at the governor's deficit (w - v_stop(room)), which is zero
      where it starts and grows as the walker closes: tracked with lag, 0.39 m. Once the mover
      is inside the stopping distance of its closing speed the vehicle backs away at the whole
      give-way speed (w + ``closing.OUTPACE_M_S``) while the approach is measured.

    With both, the configured clearance (0.5 m, from the walker's true position) holds."""
    from mavcore.mission.replan import ReplanConfig

    rp = _scenario_replanning(
        tmp_path,
        "campaign: obstacles-mix\nscenario: 84\nmission: tilted-hexagon\nseed: 494333624\ncut_s: 45.0\n"
        "control: companion\noverrides:\n  sim:\n    obstacles:\n"
        "    - {type: cylinder, x: 12.379, y: 8.603, height: 0.947, radius: 0.092}\n"
        "    movers:\n    - type: walker\n      path:\n      - [12.332, 15.269]\n      - [15.19, 9.994]\n"
        "      speed_m_s: 0.955\n      loop: false\n      start_s: 35.819\n"
        "    sensor_profile: icm42688p-bmm150-zedf9p\n  replan: {give_way: true}\n")
    assert rp["min_clearance_m"] >= ReplanConfig.clearance_m


def test_a_give_way_from_a_false_approach_behind_does_not_close_on_the_worker_it_watches(tmp_path):
    """Campaign obstacles-mix (seed 20261200), scenario 71 (tilted-hexagon): rejoining after a
    climb, the vehicle stopped to watch a worker standing 3.6 m ahead, and a rear beam read a
    1.41 m/s approach from a box 5 m behind it (its field's edge swept over the box's top as
    the vehicle descended and pitched: the range fell 5.08 -> 4.84 m while the vehicle flew
    away). The give-way backed away from that "mover" at up to 1.3 m/s, toward the worker,
    who then walked down the corridor into it (contact at 37.2 s). A give-way now comes no
    nearer to another unknown obstacle than to the mover (``Replanner._govern_others``): the
    vehicle brakes where it is, and gives way to the worker when it walks."""
    from mavcore.mission.replan import ReplanConfig

    rp = _scenario_replanning(
        tmp_path,
        "campaign: obstacles-mix\nscenario: 71\nmission: tilted-hexagon\nseed: 556997552\ncut_s: 45.0\n"
        "control: companion\noverrides:\n  sim:\n    obstacles:\n"
        "    - {type: box, x: 11.757, y: 7.033, height: 1.308, size_x: 0.473, size_y: 0.396, yaw_deg: 74.742}\n"
        "    movers:\n    - type: walker\n      path:\n      - [12.557, 15.389]\n      - [15.327, 10.067]\n"
        "      speed_m_s: 1.215\n      loop: false\n      start_s: 34.924\n  replan: {give_way: true}\n")
    assert rp["min_clearance_m"] >= ReplanConfig.clearance_m


def test_giving_way_along_a_row_at_30_deg_the_brake_does_not_bend_into_the_row(tmp_path):
    """Fresh seed 20261228 along, flight 5 (tilted-hexagon, rows at 30 deg): a worker stands
    2.6 m ahead in the outer pass, then walks down it at 1.25 m/s. The vehicle backs away
    along the row at up to 1.3 m/s. With the brake on E and N, every predicted brake bent
    toward the row (the axis with more speed ran on), was refused as an approach, and the
    fallback brake drifted the reference into the row's margin band, where every motion
    along the row was then refused: the worker walked into the vehicle (contact at 20 s).
    With the brake on the command's axes (``companion.replan.shaper``) the vehicle backs out
    of the pass: 0.78 m of true clearance, and the flight ends in a hold the independent
    route check agrees with (the worker stands at the end of the pass)."""
    rp = _scenario_replanning(
        tmp_path,
        "campaign: fresh23-along\nscenario: 5\nmission: tilted-hexagon\nseed: 967294313\ncut_s: 45.0\n"
        "control: companion\noverrides:\n  sim:\n    obstacles:\n"
        "    - {type: box, x: 12.961, y: 10.265, height: 1.123, size_x: 0.834, size_y: 0.41, yaw_deg: 60.377}\n"
        "    - {type: cylinder, x: 13.49, y: 12.549, height: 1.494, radius: 0.114}\n"
        "    movers:\n    - type: walker\n      path:\n      - [8.044, 6.435]\n      - [2.847, 3.435]\n"
        "      speed_m_s: 1.245\n      loop: false\n      start_s: 16.737\n  replan: {give_way: true}\n")
    assert rp["min_clearance_m"] >= 0.5
    holds = [e for e in rp["event_list"] if e["action"] == "hold"]
    assert all("independent check agrees" in e["detail"] for e in holds)


def test_a_walker_keeping_pace_with_the_vehicle_backing_away_from_it_stays_a_mover():
    """A worker walks at 1.3 m/s after a vehicle that backs away from it, looking back (-x)
    at it. While the vehicle is slower the walker gains: 1.3 m/s is measured. Once the
    vehicle keeps pace (1.3 m/s from 1.0 s on), the return rides with the sensor: no speed
    of its own, but where the mover was, so its approach holds for as long as it keeps
    coming (here 3 s, three times ``HOLD_S``), at 1.3 m/s, not raised. Once its returns
    stop, the approach lapses ``HOLD_S`` later. The same riding returns with no approach
    measured first (the vehicle at 1.3 m/s from the start) are nothing: a return riding
    with the vehicle starts no give-way (fresh seed 20261224 along, flight 7: with the
    approach let go after a second of riding, the give-way braked and the worker walked
    into the vehicle)."""
    from companion.replan.closing import HOLD_S, ClosingSpeed

    u = (-1.0, 0.0, 0.0)
    walker = 1.3

    def vehicle_x(t, from_start):
        if from_start:
            return walker * t
        return 0.5 * t if t < 1.0 else 0.5 + walker * (t - 1.0)

    for from_start in (False, True):
        c = ClosingSpeed()
        t = 0.0
        while t < 4.0 - 1e-9:
            o = (vehicle_x(t, from_start), 0.0, 1.5)
            c.on_hit(t, 4, (-2.0 + walker * t, 0.0, 1.5), u, origin_enu_m=o)
            t = round(t + 0.05, 10)
        if from_start:
            assert c.approach_m_s(3.95) == 0.0
            continue
        assert c.approach_m_s(3.95) == pytest.approx(walker, abs=1e-9)
        assert c.approach_m_s(3.95 + HOLD_S - 0.01) == pytest.approx(walker, abs=1e-9)
        assert c.approach_m_s(3.95 + HOLD_S + 0.01) == 0.0


def test_a_held_approach_is_not_raised_by_returns_riding_with_the_vehicle():
    """0.5 m/s measured while the vehicle hovers, then returns that keep their place relative
    to the sensor while the vehicle backs away at 1.3 m/s from 1.0 s (read as a world speed:
    1.3 m/s). The pairs that straddle the change and do not ride count: the last of them,
    at 1.1 s against the return of 0.8 s (the return moved 0.23 m, the sensor 0.13 m: 0.33
    m/s apart, over ``MIN_M_S``), reads 0.23 / 0.3 = 0.767 m/s. From then on the returns ride
    (0.25 m/s apart or less): the approach holds at 0.767 m/s, not the vehicle's own speed
    (which would raise the give-way's speed, and the riding "mover's" with it)."""
    from companion.replan.closing import ClosingSpeed

    u = (-1.0, 0.0, 0.0)
    c = ClosingSpeed()
    t = 0.0
    while t < 3.0 - 1e-9:
        if t < 1.0:
            o, hit = (0.0, 0.0, 1.5), (-2.0 + 0.5 * t, 0.0, 1.5)
        else:
            o = (1.3 * (t - 1.0), 0.0, 1.5)
            hit = (-1.5 + 1.3 * (t - 1.0), 0.0, 1.5)
        c.on_hit(t, 4, hit, u, origin_enu_m=o)
        t = round(t + 0.05, 10)
    last_counted = ((-1.5 + 1.3 * 0.1) - (-2.0 + 0.5 * 0.8)) / 0.3
    assert last_counted == pytest.approx(0.767, abs=1e-3)
    assert c.approach_m_s(2.95) == pytest.approx(last_counted, abs=1e-9)
