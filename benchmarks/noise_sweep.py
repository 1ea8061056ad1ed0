"""Noise sweep: velocity noise x gyro bias, and the realistic sensor profile.

Usage::

    python benchmarks/noise_sweep.py                              # in-process, flat-rectangle
    python benchmarks/noise_sweep.py --missions flat-rectangle tilted-hexagon --cut 60
    python benchmarks/noise_sweep.py --mode mavlink               # each point a `companion demo`
    python benchmarks/noise_sweep.py --realistic --missions flat-rectangle tilted-hexagon flat-rectangle-windy

Grid: white velocity noise (per axis, every frame) 0 / 1 mm/s / 1 cm/s /
5 cm/s x constant gyro bias 0 / 0.01 rad/s (all axes), on top of the
mission's sensors (the SITL's physical IMU with the paper's noise, exact
position). Controllers: the project's default (observer), the previous
default (no observer: tilt from the differentiated velocity), and the
SITL's cascaded controller (in-process on the true state, so the sensor
noise does not reach it; over MAVLink on whatever the SITL gives it).

``--realistic``: the in-process realistic profile (``sensor_models.REALISTIC``:
RTK-like 10 Hz fixes 80 ms late with 1 cm / 2 cm / 2 cm/s noise, a
BMI088-class IMU with biases and bias walk, a disturbed magnetometer)
for the geometric controller; over MAVLink ``sim.sensor_profile:
--profile``.

A flight that leaves the reference by more than 5 m is stopped and marked
diverged. Figures: max and RMS position error after 5 s of settling (mm).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
for _p in (str(ROOT), str(HERE)):
    if _p not in sys.path:
        sys.path.insert(0, _p)

from paper_reproduction import Row, _fmt, fly_mavlink  # noqa: E402

VEL_STD = (0.0, 0.001, 0.01, 0.05)
GYRO_BIAS = (0.0, 0.01)
CONTROLLERS = {
    "geometric, observer (default)": ("companion", {}),
    "geometric, no observer (previous)": ("companion", {"observer": False}),
    "cascaded (SITL onboard)": ("vehicle", {}),
    # --control rates: over MAVLink only (the in-process harness has no rate loop); not in the default list
    "geometric, body rates (SITL rate loop)": ("rates", {}),
}


def _fly_inprocess(mission: str, control: str, cfg: dict, noise: dict, sensors, cut_s, seed, cache) -> dict:
    from mavcore.mission.control import ControlConfig
    from mavcore.mission import load_mission
    from companion.planner import plan_mission
    from track_inprocess import fly

    if mission not in cache:
        m = load_mission(ROOT / "missions" / mission / "mission.yaml")
        cache[mission] = (m, plan_mission(m))
    m, plan = cache[mission]
    try:
        r = fly(m.source, control, ControlConfig(**cfg) if control == "companion" else None, seed=seed, cut_s=cut_s,
                plan=plan, mission=m, sensors=sensors if control == "companion" else None, noise_overrides=noise,
                abort_m=5.0)
    except (ValueError, ZeroDivisionError, OverflowError) as exc:
        # the controller broke down (e.g. a degenerate vector): a failed point, not a crash of the sweep
        return {"completed": False, "max_mm": float("nan"), "rms_mm": float("nan"), "error": str(exc)[:60]}
    return {"completed": not r.extra["diverged"], "max_mm": 1e3 * r.max_m, "rms_mm": 1e3 * r.rms_m}


def _cell(r: dict) -> str:
    if not r["completed"]:
        return "**diverged**" if r["max_mm"] == r["max_mm"] else f"failed ({r.get('error', '?')})"
    return f"{_fmt(r['max_mm'])} / {_fmt(r['rms_mm'])}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--missions", nargs="*", default=["flat-rectangle"])
    ap.add_argument("--mode", choices=("inprocess", "mavlink"), default="inprocess")
    ap.add_argument("--cut", type=float, default=None, help="fly only the first S seconds of each trajectory")
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--controllers", nargs="*", default=[k for k, v in CONTROLLERS.items() if v[0] != "rates"],
                    choices=list(CONTROLLERS))
    ap.add_argument("--realistic", action="store_true", help="the realistic profile instead of the grid")
    ap.add_argument("--profile", default="icm42688p-bmm150-zedf9p",
                    help="SITL sensor profile name (--mode mavlink --realistic)")
    args = ap.parse_args(argv)
    cache: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        for mission in args.missions:
            if args.realistic:
                print(f"\n### {mission}, realistic sensors ({args.mode}): max / RMS error (mm)\n")
                print("| controller | sensors | completed | max (mm) | RMS (mm) |")
                print("|---|---|---|---|---|")
                for name in args.controllers:
                    control, cfg = CONTROLLERS[name]
                    if args.mode == "inprocess":
                        from sensor_models import REALISTIC
                        r = _fly_inprocess(mission, control, cfg, {}, REALISTIC, args.cut, args.seed, cache)
                        sens = REALISTIC.label if control == "companion" else "true state (in-process)"
                    else:
                        row = Row(name, control, cfg, "physical")
                        r = fly_mavlink(mission, row, args.cut, args.seed, Path(tmp),
                                        sim_extra={"sensor_profile": args.profile})
                        sens = f"sim.sensor_profile: {args.profile}"
                    print(f"| {name} | {sens} | {'yes' if r['completed'] else 'NO'} | {_fmt(r['max_mm'])} | "
                          f"{_fmt(r['rms_mm'])} |", flush=True)
                continue
            print(f"\n### {mission}, velocity noise x gyro bias ({args.mode}"
                  f"{', cut %g s' % args.cut if args.cut else ''}): max / RMS error after 5 s (mm)\n")
            cols = [f"{1e3 * v:g} mm/s, bias {b:g}" for v in VEL_STD for b in GYRO_BIAS]
            print("| controller | " + " | ".join(cols) + " |")
            print("|---" * (len(cols) + 1) + "|")
            for name in args.controllers:
                control, cfg = CONTROLLERS[name]
                label = name + (", true state" if control == "vehicle" and args.mode == "inprocess" else "")
                cells = []
                for v in VEL_STD:
                    for b in GYRO_BIAS:
                        noise = {"velocity_std_m_s": v, "gyro_bias_rad_s": (b, b, b)}
                        if args.mode == "inprocess":
                            r = _fly_inprocess(mission, control, cfg, noise, None, args.cut, args.seed, cache)
                        else:
                            r = fly_mavlink(mission, Row(name, control, cfg, "physical"), args.cut, args.seed,
                                            Path(tmp), sim_extra={"noise": noise})
                        cells.append(_cell(r))
                        print(f"# {mission} {name} v={v} b={b}: {cells[-1]}", file=sys.stderr, flush=True)
                print(f"| {label} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
