"""A worker steps out of a vine row in front of the vehicle: least true clearance with the
emergency brake on, and off (the emergency limits set to the normal ones). The flight of
``tests/test_replan_emergency_brake.py``, swept over the time the worker sets off
(BENCHMARKS.md "h15-brake").

flat-rectangle's first corridor is flown westward along y = 8.75 m at 1 m/s. The worker
starts inside the row below (x = 17 m, y = 6.9 m, hidden by the canopy) and crosses the
corridor at 1 m/s. Each flight is ``companion demo --transport inproc --cut 14`` in this
process (seeded lockstep: the outcome does not depend on the machine's load).

    python benchmarks/step_out_sweep.py [--starts 9.5 9.75 10.0 10.25 10.5]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import tempfile
from pathlib import Path

from companion.bundled import missions_dir
from companion.cli import main
from mavcore.mission.replan import ReplanConfig


def write_mission(directory: Path, start_s: float, emergency: bool) -> Path:
    """The step-out mission (module doc) as ``directory/m.yaml``: the worker sets off at
    ``start_s``; ``emergency`` False sets the emergency limits to the normal ones."""
    fd = missions_dir() / "flat-rectangle"
    off = "" if emergency else (f", emergency_accel_m_s2: {ReplanConfig.accel_m_s2}, "
                                f"emergency_jerk_m_s3: {ReplanConfig.jerk_m_s3}")
    path = directory / "m.yaml"
    path.write_text(
        "name: step-out\n"
        f"map: {fd / 'map.yaml'}\ndem: {fd / 'dem.asc'}\n"
        "home: {lat: 44.8, lon: -0.6, alt_m: 30.0}\n"
        "flight: {height_agl_m: 1.5, speed_m_s: 1.0, waypoint_interval_s: 4.0}\n"
        "coverage: {line_spacing_m: 2.5, safety_margin_m: 0.45}\n"
        "pointing: {target: centroid}\n"
        f"replan: {{give_way: true{off}}}\n"
        "sim:\n  noise: {vector_variance: 5.0e-4, gyro_variance: 5.0e-4}\n  seed: 1\n"
        f"  movers: [{{type: walker, path: [[17.0, 6.9], [17.0, 11.5]], speed_m_s: 1.0, start_s: {start_s}}}]\n")
    return path


def fly(directory: Path, start_s: float, emergency: bool) -> dict:
    """report.json of the step-out flight (``write_mission``) flown in ``directory``."""
    mission = write_mission(directory, start_s, emergency)
    with contextlib.redirect_stdout(io.StringIO()):        # the demo's own summary table
        main(["demo", "--mission", str(mission), "--transport", "inproc", "--cut", "14", "--out",
              str(directory / "out"), "--no-plots", "--quiet"])
    return json.loads((directory / "out" / "report.json").read_text())


def main_(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=float, nargs="+", default=[9.5, 9.75, 10.0, 10.25, 10.5])
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        print("| sets off at | first seen | emergency brake on | off (the mutation) |")
        print("|---|---|---|---|")
        for t in args.starts:
            cells = []
            first = None
            for on in (True, False):
                rep = fly(Path(tempfile.mkdtemp(dir=tmp)), t, on)
                rp = rep["replanning"]
                if first is None:
                    first = next(e["obstacle_range_m"] for e in rp["event_list"] if e["obstacle_range_m"] is not None)
                cells.append(f"crash ({rep['crash']['text']})" if rep["crash"] else f"{rp['min_clearance_m']:.3f} m")
            print(f"| {t:g} s | {first:.2f} m | {cells[0]} | {cells[1]} |")


if __name__ == "__main__":
    main_()
