"""Simulation frame plumbing (sitl/sim.py): multi-step physics, lazy frames,
gains updates and the default start position (mission ``sim.start_enu_m``)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mavcore.errors import MissionError
from mavcore.maps.grid import ElevationModel, OccupancyGrid
from mavcore.mission import load_mission
from mavcore.mission.schema import HomeConfig, Mission
from mavcore.mission.sim import SimConfig
from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig
from sitl.onboard import CascadedController, OnboardGains, Setpoint
from sitl.plant import Plant, PlantParams
from sitl.sim import SensorFrame, Simulation, TrueState
from sitl.world import World

VEH = VehicleConfig()
HOVER = VEH.mass_kg * GRAVITY_M_S2 / 4 / VEH.max_thrust_per_rotor_n


def _mission(**sim):
    return Mission(name="t", map="m.yaml", dem="d.asc", home=HomeConfig(44.8, -0.6, 30.0),
                   sim=SimConfig(rangefinders=(), **sim))


def _state(pl):
    return pl.p + pl.v + pl.R + pl.w + pl.f + pl.acc + (pl.landed, pl._count)


def test_advance_is_bit_for_bit_n_single_steps():
    # climb, then cut the motors so it falls back onto a sloped ground: lift-off,
    # flight with drag and wind, re-orthonormalisation (every 64 steps), touch-down
    ground = lambda x, y: 0.1 * x   # noqa: E731
    a = Plant(PlantParams(VEH, drag_n_s_m=0.3), ground, 10.0)
    b = Plant(PlantParams(VEH, drag_n_s_m=0.3), ground, 10.0)
    for pl in (a, b):
        pl.set_state((0.0, 0.0, 0.0), landed=True)
    wind = (1.0, -0.5, 0.2)
    for k in range(700):
        cmd = (1.3 * HOVER, 1.31 * HOVER, 1.29 * HOVER, 1.3 * HOVER) if k < 150 else (0.2,) * 4
        for _ in range(4):
            a.step(cmd, 1e-3, wind)
        b.advance(cmd, 1e-3, 4, wind)
        assert _state(a) == _state(b)
    assert a.landed and a.impact_speed_m_s == b.impact_speed_m_s > 0.0


def test_frames_are_immutable_and_give_arrays():
    sim = Simulation(_mission(), np.random.default_rng(0), start_enu_m=(1.0, 2.0, 3.0))
    fr = sim.step_frame((HOVER,) * 4)
    assert isinstance(fr, SensorFrame) and isinstance(fr.truth, TrueState)
    for x in (fr.accel_flu_m_s2, fr.gyro_flu_rad_s, fr.mag_flu_gauss, fr.pos_enu_m, fr.vel_enu_m_s,
              fr.truth.pos_enu_m, fr.truth.vel_enu_m_s, fr.truth.omega_flu_rad_s, fr.truth.acc_enu_m_s2):
        assert isinstance(x, np.ndarray) and x.shape == (3,)
    assert fr.truth.R.shape == (3, 3) and fr.truth.motor_thrust_n.shape == (4,)
    assert fr.pos_enu_m is fr.pos_enu_m                        # converted once, then cached
    assert np.allclose(fr.truth.R.T @ fr.truth.R, np.eye(3), atol=1e-15)
    with pytest.raises(dataclasses.FrozenInstanceError):
        fr.time_us = 0
    with pytest.raises(dataclasses.FrozenInstanceError):
        fr.truth.landed = True
    # the truth is a snapshot: later frames do not change it
    t0 = fr.truth
    sim.step_frame((0.0,) * 4)
    assert t0.pos_enu_m[2] > sim.truth.pos_enu_m[2]            # falling since then
    # constructed by hand, like the former dataclasses
    ts = TrueState(np.zeros(3), np.ones(3), np.eye(3), np.zeros(3), np.zeros(3), False, np.zeros(4))
    assert ts.vel_enu_m_s[0] == 1.0 and not ts.landed
    assert "TrueState(" in repr(ts)


def test_assigning_gains_takes_effect():
    slow = dataclasses.replace(OnboardGains(), max_speed_xy_m_s=0.5, max_tilt_rad=math.radians(10.0))
    a = CascadedController(VEH)
    a.gains = slow
    b = CascadedController(VEH, slow)
    c = CascadedController(VEH)
    R = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    sp = Setpoint(pos_enu_m=(10.0, 0.0, 2.0), yaw_enu_rad=0.0)
    args = ((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), R, (0.0, 0.0, 0.0), sp, 0.004)
    assert a.update_floats(*args) == b.update_floats(*args) != c.update_floats(*args)
    assert a.gains is slow


def test_start_cell_is_mid_corridor_nearest_the_free_centroid():
    # 7 x 5 cells of 1 m, row 3 occupied: two corridors of 3 rows. Free-cell
    # centroid (row, col) = (3, 2). Clearance (to the row or the map border):
    # 2 cells on rows 1 and 5, cols 1..3 (the ridge, = the max), 1 elsewhere.
    # Nearest ridge cells to (3, 2): (1, 2) and (5, 2), both at 2 cells; the
    # first in row-major order wins. (The plain nearest free cell, (2, 2),
    # touches the row.)
    occ = np.zeros((7, 5), bool)
    occ[3, :] = True
    w = World.build(OccupancyGrid(occ, ~occ, 1.0, (10.0, 20.0)))
    assert w.start_cell_enu() == pytest.approx((12.5, 21.5))     # cell (1, 2) centre
    sim = Simulation(_mission(), np.random.default_rng(0), world=w)
    assert sim.truth.pos_enu_m == pytest.approx([12.5, 21.5, 0.0])
    assert sim.truth.landed
    # a single free cell is its own start
    free = np.zeros((3, 3), bool)
    free[2, 1] = True
    w = World.build(OccupancyGrid(np.zeros((3, 3), bool), free, 0.5, (10.0, 20.0)))
    assert w.start_cell_enu() == pytest.approx((10.75, 21.25))
    assert World.build().start_cell_enu() is None


def test_mission_start_position_sits_on_the_terrain():
    x0 = y0 = -5.0
    xs = x0 + 0.5 * np.arange(40)
    X, Y = np.meshgrid(xs, xs)
    dem = ElevationModel(0.1 * X - 0.2 * Y + 1.0, x0, y0, 0.5)
    w = World.build(dem=dem)
    sim = Simulation(_mission(start_enu_m=(2.0, 1.0)), np.random.default_rng(0), world=w)
    assert sim.truth.pos_enu_m == pytest.approx([2.0, 1.0, 0.1 * 2.0 - 0.2 * 1.0 + 1.0], abs=1e-12)
    # an explicit start still wins
    sim.reset((0.0, 0.0))
    assert sim.truth.pos_enu_m == pytest.approx([0.0, 0.0, 1.0], abs=1e-12)


_YAML = """name: t
map: map.yaml
dem: dem.asc
home: {lat: 44.8, lon: -0.6, alt_m: 30.0}
sim: {start_enu_m: START}
"""


def test_start_key_in_the_mission_file(tmp_path):
    p = tmp_path / "m.yaml"
    p.write_text(_YAML.replace("START", "[3, -1.5]"))
    assert load_mission(p).sim.start_enu_m == (3.0, -1.5)
    for bad in ("[1, 2, 3]", "here", "[.nan, 0]"):
        p.write_text(_YAML.replace("START", bad))
        with pytest.raises(MissionError, match="sim"):
            load_mission(p)
