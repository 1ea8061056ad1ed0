"""Paper reproduction (Mokrane et al. 2022, Section 3.4 and Figs. 20-21).

Flies both bundled terrains over MAVLink in lockstep against the bundled SITL
(paper settings: 1 m/s, 4 s per way-point, white noise of variance 5e-4 on
the unit vector measurements and on Omega, from each mission's ``sim:``
section) with the geometric controller and with the SITL's cascaded
controller on the same trajectory, and prints a Markdown table of the
position error after settling (from the SITL's true state), next to the
paper's maximum errors.

Usage::

    python benchmarks/paper_reproduction.py [--seeds 1 2 3]

Each flight is ``companion demo --mission M --control C --out DIR --no-plots``;
the figures come from its report.json.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

PAPER_MAX_MM = {"flat-rectangle": 2.8, "tilted-hexagon": 4.1, "flat-rectangle-windy": None}


def fly(mission: str, control: str, seed: int | None, out: Path) -> dict:
    cmd = [sys.executable, "-m", "companion.cli", "demo", "--mission", mission, "--control", control,
           "--out", str(out), "--no-plots", "--quiet"]
    if seed is not None:
        cmd += ["--seed", str(seed)]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return json.loads((out / "report.json").read_text())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--missions", nargs="*", default=["flat-rectangle", "tilted-hexagon"],
                    help="bundled missions (default: the paper's two terrains; also flat-rectangle-windy)")
    ap.add_argument("--seeds", type=int, nargs="*", default=[None],
                    help="SITL noise seeds (default: each mission's sim.seed)")
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for mission in args.missions:
            for control in ("companion", "vehicle"):
                for seed in args.seeds:
                    out = Path(tmp) / f"{mission}-{control}-{seed}"
                    r = fly(mission, control, seed, out)
                    tr = r["tracking"]
                    rows.append((mission, control, seed, r["completed"], tr["max_error_m"] * 1e3,
                                 tr["rms_error_m"] * 1e3, r["sim_time_s"], r["wall_time_s"]))
                    print(f"# {mission} {control} seed={seed}: max {tr['max_error_m'] * 1e3:.2f} mm",
                          file=sys.stderr, flush=True)
    print("| terrain | controller | seed | completed | max error (mm) | RMS error (mm) | paper max (mm) | vehicle time (s) | flight wall (s) |")
    print("|---|---|---|---|---|---|---|---|---|")
    names = {"companion": "geometric (companion)", "vehicle": "cascaded (SITL onboard)"}
    for mission, control, seed, ok, mx, rms, sim_s, wall_s in rows:
        seed_txt = "mission" if seed is None else str(seed)
        print(f"| {mission} | {names[control]} | {seed_txt} | {'yes' if ok else 'NO'} | {mx:.2f} | {rms:.2f} | "
              f"{PAPER_MAX_MM.get(mission) or '-'} | {sim_s:.1f} | {wall_s:.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
