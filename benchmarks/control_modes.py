"""The three control modes like for like, over seeds and checkouts (issue 17: README "Control modes like for like").

Usage::

    python benchmarks/control_modes.py --checkout base=/tmp/base main=$PWD --seeds 1 2 3 \\
        --profile icm42688p-bmm150-zedf9p --jobs 2 --out rows.jsonl

Each row is one fresh ``python -m companion demo --mission M --control C
--transport inproc --seed S --no-plots --quiet`` with ``PYTHONPATH`` set to
the checkout (so a baseline checkout is measured by this same script), on
a copy of the bundled mission with absolute map paths and, with
``--profile``, ``sim.sensor_profile`` (``--no-replan``: ``replan.enabled:
false``, so that the flight follows the planned trajectory and nothing
else; on the realistic profile the replanner reacts to returns it does not
explain by the map). The in-process transport flies the
same flight packet for packet as UDP (``tests/test_transport_e2e.py``).
The rows are run interleaved: for each (mission, control, seed) every
checkout in turn, so a change of machine load falls on all of them alike.

Figures from report.json: completed, the replanner's events, max and RMS position error after 5 s
of settling (mm); and the process's CPU time (user + sys, ``os.wait4``) and
peak RSS, which depend on the machine's load and are only indicative.
Prints a markdown table of every row, then per (mission, control,
checkout) the median over the seeds.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import statistics
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MISSIONS = ("flat-rectangle", "tilted-hexagon")
CONTROLS = ("companion", "rates", "vehicle")


def mission_copy(mission: str, out_dir: Path, profile: str | None, replan: bool = True) -> Path:
    """The bundled mission with absolute map paths and, with ``profile``, ``sim.sensor_profile``
    (``replan=False``: ``replan.enabled: false``)."""
    import yaml

    src = ROOT / "missions" / mission / "mission.yaml"
    data = yaml.safe_load(src.read_text())
    for key in ("map", "dem"):
        data[key] = str((src.parent / data[key]).resolve())
    if profile is not None:
        data["sim"] = dict(data.get("sim") or {}, sensor_profile=profile)
    if not replan:
        data["replan"] = dict(data.get("replan") or {}, enabled=False)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "mission.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def fly(checkout: Path, mission_path: Path, control: str, seed: int | None, cut_s: float | None, out: Path) -> dict:
    """One demo in a fresh process; the figures of the module docstring."""
    cmd = [sys.executable, "-m", "companion", "demo", "--mission", str(mission_path), "--control", control,
           "--transport", "inproc", "--out", str(out), "--no-plots", "--quiet"]
    if seed is not None:
        cmd += ["--seed", str(seed)]
    if cut_s is not None:
        cmd += ["--cut", str(cut_s)]
    env = dict(os.environ, PYTHONPATH=str(checkout))
    with open(out / "stderr.txt", "w") as err:
        proc = subprocess.Popen(cmd, cwd=checkout, env=env, stdout=subprocess.DEVNULL, stderr=err)
        _, status, ru = os.wait4(proc.pid, 0)
    row = {"rc": os.waitstatus_to_exitcode(status), "cpu_s": ru.ru_utime + ru.ru_stime, "rss_mb": ru.ru_maxrss / 1024}
    rep_path = out / "report.json"
    if not rep_path.exists():
        return dict(row, completed=False, max_mm=float("nan"), rms_mm=float("nan"), replans=-1, error="no report")
    rep = json.loads(rep_path.read_text())
    tr = rep["tracking"]
    return dict(row, completed=bool(rep["completed"]), max_mm=1e3 * tr["max_error_m"], rms_mm=1e3 * tr["rms_error_m"],
                replans=int(rep["replanning"]["events"]), error=rep.get("error"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkout", nargs="+", required=True, metavar="LABEL=PATH")
    ap.add_argument("--missions", nargs="+", default=list(MISSIONS))
    ap.add_argument("--controls", nargs="+", default=list(CONTROLS), choices=CONTROLS)
    ap.add_argument("--seeds", nargs="+", type=int, default=[None], help="default: the mission's sim.seed")
    ap.add_argument("--profile", default=None, help="sim.sensor_profile (default: the mission's sensors)")
    ap.add_argument("--cut", type=float, default=None)
    ap.add_argument("--no-replan", action="store_true",
                    help="replan.enabled: false (the tracking of the planned trajectory alone)")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None, help="append each row to this JSON-lines file")
    args = ap.parse_args(argv)
    try:
        checkouts = [(lab, Path(p).resolve()) for lab, p in (c.split("=", 1) for c in args.checkout)]
    except ValueError:
        print(f"control_modes: --checkout wants LABEL=PATH, got {args.checkout}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        paths = {m: mission_copy(m, tmp / "missions" / m, args.profile, not args.no_replan) for m in args.missions}
        jobs = [(m, c, s, lab, co) for m, c, s in itertools.product(args.missions, args.controls, args.seeds)
                for lab, co in checkouts]

        def run(job):
            m, c, s, lab, co = job
            out = Path(tempfile.mkdtemp(prefix=f"{lab}-{m}-{c}-", dir=tmp))
            r = dict(fly(co, paths[m], c, s, args.cut, out), label=lab, mission=m, control=c, seed=s,
                     profile=args.profile, cut_s=args.cut, replan=not args.no_replan)
            print(f"# {json.dumps(r)}", file=sys.stderr, flush=True)
            if args.out is not None:
                with open(args.out, "a") as fh:
                    fh.write(json.dumps(r) + "\n")
            return r

        with ThreadPoolExecutor(max_workers=args.jobs) as pool:
            rows = list(pool.map(run, jobs))
    print("| checkout | terrain | `--control` | seed | completed | replanning events | max (mm) | RMS (mm) | CPU (s) | peak RSS (MB) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['label']} | {r['mission']} | {r['control']} | {r['seed']} | {'yes' if r['completed'] else 'NO'} | "
              f"{r['replans']} | {r['max_mm']:.2f} | {r['rms_mm']:.2f} | {r['cpu_s']:.1f} | {r['rss_mb']:.0f} |")
    print("\n| terrain | `--control` | checkout | seeds | max, median (mm) | RMS, median (mm) |")
    print("|---|---|---|---|---|---|")
    for m, c in itertools.product(args.missions, args.controls):
        for lab, _ in checkouts:
            sel = [r for r in rows if (r["mission"], r["control"], r["label"]) == (m, c, lab)]
            print(f"| {m} | {c} | {lab} | {len(sel)} | {statistics.median(r['max_mm'] for r in sel):.2f} | "
                  f"{statistics.median(r['rms_mm'] for r in sel):.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
