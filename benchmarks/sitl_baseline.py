"""The SITL's cascaded controller (``--control vehicle``) on its onboard
estimate versus on the true state, on the paper's sensors and on the
realistic profile (issue 7: a fair baseline).

Usage::

    python benchmarks/sitl_baseline.py [--missions flat-rectangle tilted-hexagon]
                                       [--variants truth estimate profile-truth profile-estimate]

Each row is ``companion demo --mission M --control vehicle --no-plots`` on a
copy of the bundled mission with the variant's ``sim`` keys added:

- ``truth``: ``onboard_state: truth`` (the controller reads the true state);
- ``estimate``: the default, the onboard estimator on the paper's noise;
- ``profile-truth`` / ``profile-estimate``: ``sensor_profile:
  icm42688p-bmm150-zedf9p`` (RTK-like GNSS, MEMS IMU biases);
- ``paper-estimate``: ``vector_sensors: paper`` on the estimate.

Errors are the SITL's true position against the reference after 5 s of
settling (report.json); lockstep flights, so the figures are deterministic.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
PROFILE = "icm42688p-bmm150-zedf9p"
VARIANTS = {
    "truth": {"onboard_state": "truth"},
    "estimate": {},
    "profile-truth": {"sensor_profile": PROFILE, "onboard_state": "truth"},
    "profile-estimate": {"sensor_profile": PROFILE},
    "paper-estimate": {"vector_sensors": "paper"},
}


def variant_mission(mission: str, sim_keys: dict, out_dir: Path) -> Path:
    """A copy of a bundled mission with extra ``sim`` keys (maps by absolute path)."""
    src = ROOT / "missions" / mission / "mission.yaml"
    d = yaml.safe_load(src.read_text())
    for k in ("map", "dem"):
        d[k] = str((src.parent / d[k]).resolve())
    d.setdefault("sim", {}).update(sim_keys)
    out = out_dir / f"{mission}.yaml"
    out.write_text(yaml.safe_dump(d))
    return out


def fly(mission_path: Path, out: Path) -> dict:
    cmd = [sys.executable, "-m", "companion.cli", "demo", "--mission", str(mission_path), "--control", "vehicle",
           "--out", str(out), "--no-plots", "--quiet"]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return json.loads((out / "report.json").read_text())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--missions", nargs="*", default=["flat-rectangle", "tilted-hexagon"])
    ap.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=list(VARIANTS))
    args = ap.parse_args(argv)
    print("| terrain | SITL state / sensors | completed | max error (mm) | RMS error (mm) |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for mission in args.missions:
            for v in args.variants:
                d = Path(tmp) / f"{mission}-{v}"
                d.mkdir()
                r = fly(variant_mission(mission, VARIANTS[v], d), d / "out")
                tr = r["tracking"]
                print(f"| {mission} | {v} | {'yes' if r['completed'] else 'NO'} | "
                      f"{tr['max_error_m'] * 1e3:.2f} | {tr['rms_error_m'] * 1e3:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
