"""CPU of the per-frame parts that branch h16-speed changed, one at a time.

Usage::

    python benchmarks/bench_speed_parts.py [--repeat 7] [--number 3000]

Each figure is the minimum over ``--repeat`` runs of ``--number`` calls
(``time.process_time``), in microseconds per call: the minimum is the figure
least disturbed by other processes on a shared machine. Parts: the SITL's
sensor frame (``Simulation.step_frame`` on flat-rectangle, hovering: plant,
sensors, estimator) and the plant alone (4 physics steps), each with the
compiled kernel (when numba imports) and with the Python loop
(``VINEYARD_GNC_NUMBA=0`` semantics: the plant's ``_kernel`` set to None);
the SITL's decoding of a SET_POSITION_TARGET_LOCAL_NED; one ENU -> WGS-84
point (``mavcore.geodesy.enu2geodetic``, GLOBAL_POSITION_INT's and
GPS_RAW_INT's conversion). Runs on any revision that has these functions
(the kernel rows are skipped where ``sitl.plant_kernel`` does not exist).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def per_call_us(fn, number: int, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        c0 = time.process_time()
        for _ in range(number):
            fn()
        best = min(best, time.process_time() - c0)
    return best / number * 1e6


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--number", type=int, default=3000)
    args = ap.parse_args()
    import numpy as np
    from pymavlink.dialects.v20 import common as mavlink

    from mavcore import geodesy
    from companion.bundled import resolve_mission
    from mavcore.mission import load_mission
    from mavcore import codec
    from sitl.plant import Plant, PlantParams
    from sitl.sim import Simulation

    try:
        from sitl import plant_kernel
        kern = plant_kernel.kernel()
    except ImportError:
        kern = None
    rows = []
    mission = load_mission(resolve_mission("flat-rectangle"))
    for label, k in (("compiled kernel", kern), ("Python loop", None)):
        if label == "compiled kernel" and kern is None:
            continue
        pl = Plant(PlantParams(drag_n_s_m=0.3))
        pl._kernel = k
        pl.set_state((0.0, 0.0, 5.0))
        cmd = (0.5, 0.52, 0.49, 0.51)
        rows.append((f"Plant.advance, 4 steps, {label}",
                     per_call_us(lambda: pl.advance(cmd, 0.001, 4, (1.0, 0.0, 0.0)), args.number, args.repeat)))
        sim = Simulation(mission, np.random.default_rng(1))
        sim.plant._kernel = k
        hover = [mission.vehicle.mass_kg * 9.81 / 4 / mission.vehicle.max_thrust_per_rotor_n] * 4
        x, y = sim.plant.p[0], sim.plant.p[1]

        def frame():
            if sim.plant.p[2] < 1.0 or abs(sim.plant.p[0] - x) > 5:
                sim.plant.set_state((x, y, 3.0), f=(mission.vehicle.mass_kg * 9.81 / 4,) * 4)
            sim.step_frame(hover)
        rows.append((f"Simulation.step_frame (plant, sensors, estimator), {label}",
                     per_call_us(frame, args.number, args.repeat)))
    mav = mavlink.MAVLink(None, 255, 190)
    msg = mav.set_position_target_local_ned_encode(1000, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0b0000_1100_0000_0000,
                                                   1.0, 2.0, -3.0, 0.1, 0.2, -0.3, 0.01, 0.02, -0.03, 0.5, 0.0)
    rows.append(("mavcore.codec.decode_position_target",
                 per_call_us(lambda: codec.decode_position_target(msg, 0.0, (0.0, 0.0, 0.0)), args.number,
                             args.repeat)))
    geodesy.enu2geodetic(1.0, 2.0, 3.0, 44.8, -0.6, 30.0)
    rows.append(("mavcore.geodesy.enu2geodetic, one point",
                 per_call_us(lambda: geodesy.enu2geodetic(1.0, 2.0, 3.0, 44.8, -0.6, 30.0), args.number, args.repeat)))
    print(f"| part ({ROOT.name}) | CPU us per call (min of {args.repeat} x {args.number}) |")
    print("|---|---|")
    for name, us in rows:
        print(f"| {name} | {us:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
