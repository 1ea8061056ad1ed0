"""Paper reproduction (Mokrane et al. 2022, Section 3.4) and the ablation of the project's changes.

Usage::

    python benchmarks/paper_reproduction.py                      # in-process, both terrains
    python benchmarks/paper_reproduction.py --missions flat-rectangle --cut 40
    python benchmarks/paper_reproduction.py --mode mavlink       # each row a `companion demo`

Tables (Markdown), per terrain, the position error after 5 s of settling
(max and RMS, from the true position against the reference):

1. *The paper's sensors*: the IMU gives two unfiltered unit vectors of
   constant inertial directions (``g R^T e3`` and ``|m| R^T m_hat``) with
   white noise of variance 5e-4 per component, Omega with the same noise;
   position and velocity exact (mocap). Rows: the paper's law (eq. 27
   exactly, no integral term, no filters, no governor), the same with the
   pointing governor (feasibility), then the project's changes added one at
   a time, ending at the project's default on these sensors. Every row says
   what the controller was given.
2. *Physical sensors* (the SITL's default: an accelerometer that measures
   the specific force, the paper's noise on the directions and on Omega,
   exact position/velocity), with and without the observer.
3. The SITL's cascaded controller on the same trajectory. In-process it
   flies on the true state (the SITL's estimator is not in-process);
   over MAVLink (``--mode mavlink``) it flies whatever the SITL gives it
   (its own estimator once ``sim.onboard_state: estimate`` exists).

In-process (``--mode inprocess``, default): ``track_inprocess.fly``, the
SITL's plant and sensors stepped frame by frame, the paper's vectors made
by ``sensor_models``. Over MAVLink: a temporary mission (the bundled one
with the row's ``control:`` and ``sim:`` keys; the paper's vectors need the
SITL's ``sim.vector_sensors: paper``) flown by ``companion demo``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
for _p in (str(ROOT), str(HERE)):
    if _p not in sys.path:
        sys.path.insert(0, _p)

PAPER_MAX_MM = {"flat-rectangle": 2.8, "tilted-hexagon": 4.1}

# The paper's law: eq. (27) with r1 = e3 against the paper's accelerometer vector, the raw
# magnetometer against the field, no integral term, no filters, no governor.
PAPER_LAW = dict(attitude_law="paper", mag_perpendicular=False, accel_vector_gain_rad_s=0.0,
                 mag_vector_gain_rad_s=0.0, pointing_limit=False, ki=0.0, vectors="paper",
                 velocity_aided=False, observer=False)


@dataclass(frozen=True)
class Row:
    """One controller/sensor configuration of the tables."""

    name: str
    control: str                       # "companion" | "vehicle"
    cfg: dict = field(default_factory=dict)
    sensors: str = "physical"          # "paper" | "physical"
    vectors_info: str = ""
    attitude_info: str = ""
    posvel_info: str = "exact (mocap)"


def _ablation_rows() -> list[Row]:
    paper_vec = "paper's unit vectors, var 5e-4"
    steps = [
        ("paper's law (eq. 27), paper's sensors", {}, "raw vectors (r1 = e3, r2 = m)"),
        ("  side row: + pointing governor only (feasibility)", dict(pointing_limit=True), "raw vectors"),
        ("  side row: + governor, gains for raw vectors (kx 120, kv 45, rho1 100)",
         dict(pointing_limit=True, kx=120.0, kv=45.0, rho1=100.0), "raw vectors"),
        ("+ decoupled law", dict(attitude_law="decoupled"), "raw vectors"),
        ("+ field normal to the vertical", dict(mag_perpendicular=True), "raw vectors, field projected"),
        ("+ pointing governor", dict(pointing_limit=True), "raw vectors, field projected"),
        # both paper vectors are world-fixed: gyro-propagated filters, gain ~ sigma_gyro / sigma_vector = 1
        ("+ vector filters", dict(accel_vector_gain_rad_s=1.0, mag_vector_gain_rad_s=1.0),
         "gyro-propagated filtered vectors"),
        ("+ integral term", dict(ki=60.0), "gyro-propagated filtered vectors"),
        ("+ velocity-aided tilt", dict(velocity_aided=True),
         "r1 = unit(dv/dt + g e3) from the velocity, b1 = thrust axis; filtered field"),
        ("+ observer = project default", dict(observer=True, accel_vector_gain_rad_s=0.05),
         "observer R_hat (velocity-aided, gyro bias estimated): b_i = R_hat^T r_i"),
    ]
    rows, cfg = [], dict(PAPER_LAW)
    for i, (name, delta, att) in enumerate(steps):
        if i in (1, 2):     # side rows: the paper's law with only the governor (and gains for it)
            rows.append(Row(name, "companion", dict(PAPER_LAW, **delta), "paper", paper_vec, att))
            continue
        cfg = dict(cfg, **delta)
        rows.append(Row(name, "companion", dict(cfg), "paper", paper_vec, att))
    return rows


def _physical_rows() -> list[Row]:
    phys = "physical IMU (specific force), paper's noise"
    return [
        Row("previous default (no observer)", "companion", dict(observer=False), "physical", phys,
            "filtered specific force vs unit(dv/dt + g e3); filtered field"),
        Row("project default (observer)", "companion", {}, "physical", phys,
            "observer R_hat: b_i = R_hat^T r_i, bias-corrected gyro"),
    ]


def _baseline_row(sensors: str, inprocess: bool) -> Row:
    if inprocess:
        return Row("SITL cascaded (onboard)", "vehicle", {}, sensors, "-", "true state (in-process: no estimator)",
                   "true state")
    return Row("SITL cascaded (onboard)", "vehicle", {}, sensors, "the SITL's", "the SITL's (estimate or truth)",
               "the SITL's")


# --- flying -------------------------------------------------------------------------------------


def fly_inprocess(mission: str, row: Row, cut_s: float | None, seed: int | None, cache: dict) -> dict:
    from mavcore.mission.control import ControlConfig
    from mavcore.mission import load_mission
    from companion.planner import plan_mission
    from sensor_models import SensorSpec
    from track_inprocess import fly

    if mission not in cache:
        m = load_mission(ROOT / "missions" / mission / "mission.yaml")
        cache[mission] = (m, plan_mission(m))
    m, plan = cache[mission]
    spec = SensorSpec(vectors="paper") if row.sensors == "paper" else None
    cfg = ControlConfig(**row.cfg) if row.control == "companion" else None
    r = fly(m.source, row.control, cfg, seed=seed, cut_s=cut_s, plan=plan, mission=m,
            sensors=spec if row.control == "companion" else None, abort_m=5.0)
    return {"completed": not r.extra["diverged"], "max_mm": 1e3 * r.max_m, "rms_mm": 1e3 * r.rms_m}


def _mission_overlay(mission: str, row: Row, out_dir: Path, sim_extra: dict | None = None) -> Path:
    """A copy of the bundled mission with absolute map paths and the row's control/sim keys
    (``sim_extra``: more ``sim:`` keys, mappings merged one level deep)."""
    import yaml

    src = ROOT / "missions" / mission / "mission.yaml"
    data = yaml.safe_load(src.read_text())
    for key in ("map", "dem"):
        data[key] = str((src.parent / data[key]).resolve())
    if row.control == "companion" and row.cfg:
        data["control"] = dict(data.get("control") or {}, **row.cfg)
    sim = dict(data.get("sim") or {})
    if row.sensors == "paper":
        sim["vector_sensors"] = "paper"
    for key, val in (sim_extra or {}).items():
        if isinstance(val, dict) and isinstance(sim.get(key), dict):
            val = dict(sim[key], **{k: list(v) if isinstance(v, tuple) else v for k, v in val.items()})
        sim[key] = val
    data["sim"] = sim
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "mission.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def fly_mavlink(mission: str, row: Row, cut_s: float | None, seed: int | None, tmp: Path,
                sim_extra: dict | None = None) -> dict:
    """One ``companion demo`` of the row on a temporary copy of the mission; figures from report.json."""
    out = Path(tempfile.mkdtemp(prefix=f"{mission}-", dir=tmp))
    path = _mission_overlay(mission, row, out / "mission", sim_extra)
    cmd = [sys.executable, "-m", "companion.cli", "demo", "--mission", str(path), "--control", row.control,
           "--out", str(out), "--no-plots", "--quiet"]
    if seed is not None:
        cmd += ["--seed", str(seed)]
    if cut_s is not None:
        cmd += ["--cut", str(cut_s)]
    res = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if res.returncode != 0 or not (out / "report.json").exists():
        return {"completed": False, "max_mm": float("nan"), "rms_mm": float("nan"),
                "error": (res.stderr.strip().splitlines() or ["?"])[-1]}
    r = json.loads((out / "report.json").read_text())
    tr = r["tracking"]
    return {"completed": bool(r["completed"]), "max_mm": 1e3 * tr["max_error_m"], "rms_mm": 1e3 * tr["rms_error_m"]}


def _fmt(x: float) -> str:
    return "-" if x != x else (f"{x:.2f}" if x < 100 else f"{x:.0f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--missions", nargs="*", default=["flat-rectangle", "tilted-hexagon"])
    ap.add_argument("--mode", choices=("inprocess", "mavlink"), default="inprocess")
    ap.add_argument("--cut", type=float, default=None, help="fly only the first S seconds of each trajectory")
    ap.add_argument("--seed", type=int, default=None, help="noise seed (default: each mission's sim.seed)")
    ap.add_argument("--tables", nargs="*", default=["paper", "physical"], choices=("paper", "physical"))
    ap.add_argument("--rows", nargs="*", default=None, metavar="TEXT",
                    help="fly only the rows whose name contains one of these")
    args = ap.parse_args(argv)
    inproc = args.mode == "inprocess"
    cache: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        for mission in args.missions:
            tables = []
            if "paper" in args.tables:
                tables.append(("the paper's sensors", _ablation_rows() + [_baseline_row("paper", inproc)]))
            if "physical" in args.tables:
                tables.append(("physical sensors (the SITL's default)",
                               _physical_rows() + [_baseline_row("physical", inproc)]))
            for title, rows in tables:
                print(f"\n### {mission}, {title} ({args.mode}{', cut %g s' % args.cut if args.cut else ''})\n")
                print("| controller | vectors | attitude used | position/velocity | completed | max (mm) "
                      "| RMS (mm) | paper max (mm) |")
                print("|---|---|---|---|---|---|---|---|")
                for row in rows:
                    if args.rows and not any(x in row.name for x in args.rows):
                        continue
                    r = (fly_inprocess(mission, row, args.cut, args.seed, cache) if inproc
                         else fly_mavlink(mission, row, args.cut, args.seed, Path(tmp)))
                    note = f" ({r['error']})" if r.get("error") else ""
                    print(f"| {row.name} | {row.vectors_info} | {row.attitude_info} | {row.posvel_info} | "
                          f"{'yes' if r['completed'] else 'NO' + note} | {_fmt(r['max_mm'])} | {_fmt(r['rms_mm'])} | "
                          f"{PAPER_MAX_MM.get(mission, '-')} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
