"""CPU per SITL sensor frame (4 ms, 1 kHz physics) with moving obstacles (sim.movers):
none, one walker crossing 4 m ahead, a walker and a tractor; a hovering vehicle, default
rangefinders. time.process_time over 1250 frames, median of 5 runs.

    python benchmarks/bench_movers.py
"""
import statistics
import time

import numpy as np
from mavcore.mission.schema import HomeConfig, Mission
from mavcore.mission.sim import SimConfig, MoverConfig, NoiseConfig
from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig
from sitl.sim import Simulation
VEH = VehicleConfig()
def run(movers):
    m = Mission(name="t", map="m.yaml", dem="d.asc", home=HomeConfig(44.8, -0.6, 30.0),
                sim=SimConfig(movers=movers,
                              noise=NoiseConfig(vector_variance=0.0, gyro_variance=0.0, range_std_m=0.0)))
    sim = Simulation(m, np.random.default_rng(0), start_enu_m=(0.0, 0.0))
    f = VEH.mass_kg * GRAVITY_M_S2 / 4.0
    sim.plant.set_state((0.0, 0.0, 1.5), v=(0.0, 0.0, 0.0), f=(f,) * 4)
    hover = (f / VEH.max_thrust_per_rotor_n,) * 4
    t0 = time.process_time()
    for _ in range(1250):
        sim.step_frame(hover)
    assert sim.crash is None
    return (time.process_time() - t0) / 1250 * 1e3
walker = MoverConfig("walker", ((4.0, -5.0), (4.0, 5.0)), 1.5, loop=True)
tractor = MoverConfig("tractor", ((-8.0, -8.0), (-8.0, 8.0)), 3.0, loop=True)
for name, mv in (("none", ()), ("1 walker", (walker,)), ("walker+tractor", (walker, tractor))):
    xs = [run(mv) for _ in range(5)]
    print(f"{name}: median {statistics.median(xs):.3f} ms CPU per 4 ms frame (5 runs x 1250 frames)")
