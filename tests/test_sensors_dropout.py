"""Rangefinder dropouts (``sim.noise.range_dropout_probability``): each due
reading is lost with probability p, seeded; p = 0 draws nothing (the noise
stream, hence every earlier flight, is unchanged)."""

from __future__ import annotations

import math

import numpy as np

from mavcore.mission.schema import HomeConfig, Mission
from mavcore.mission.sim import NoiseConfig, RangefinderConfig, SimConfig
from mavcore.vehicle import GRAVITY_M_S2
from sitl.sim import Simulation

RF = (RangefinderConfig(id=7, orientation=25, min_m=0.2, max_m=5.0, rate_hz=250.0),)   # one reading per frame


def _readings(p: float | None, frames: int, seed: int = 3) -> list:
    noise = NoiseConfig(range_std_m=0.01, range_dropout_probability=p)
    mission = Mission(name="t", map="m.yaml", dem="d.asc", home=HomeConfig(44.8, -0.6, 30.0),
                      sim=SimConfig(rangefinders=RF, noise=noise))
    sim = Simulation(mission, np.random.default_rng(seed))
    f = mission.vehicle.mass_kg * GRAVITY_M_S2 / 4
    cmd = [f / mission.vehicle.max_thrust_per_rotor_n] * 4
    out = []
    for k in range(frames):
        sim.plant.set_state((0.0, 0.0, 2.0), f=(f,) * 4)
        out.append([r.distance_m for r in sim.step_frame(cmd).ranges])
    return out


def test_dropout_rate_is_binomial():
    n, p = 800, 0.3
    got = _readings(p, n)
    kept = sum(len(r) for r in got)
    expected = n * (1 - p)
    assert abs(kept - expected) < 5 * math.sqrt(n * p * (1 - p))   # 5 sigma of Binomial(n, 1 - p)
    assert all(len(r) <= 1 for r in got)


def test_no_dropout_draws_nothing_and_is_seeded():
    assert _readings(0.0, 100) == _readings(None, 100)        # p = 0: the same noise stream as before the key
    assert _readings(0.5, 100) == _readings(0.5, 100)          # seeded
    assert _readings(0.5, 100) != _readings(0.5, 100, seed=4)
    assert all(r == [] for r in _readings(1.0, 20))
