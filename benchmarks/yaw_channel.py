"""The yaw channel in flight: motor commands, yaw error and tracking of ``companion demo`` (issue 17, h17-yaw).

Usage (the package on PYTHONPATH is the one measured, so a baseline
checkout can be measured with this same script)::

    PYTHONPATH=$PWD python benchmarks/yaw_channel.py                         # both terrains, both modes
    PYTHONPATH=$PWD python benchmarks/yaw_channel.py --missions flat-rectangle --controls companion --cut 20
    PYTHONPATH=$PWD python benchmarks/yaw_channel.py --profile icm42688p-bmm150-zedf9p

Each row is one ``companion demo --transport inproc`` (lockstep, the
mission's seed) run in this process, with two taps that change nothing:
``sitl.sim.Simulation.step_frame`` records the motor commands the plant
gets (in ``--control rates`` those of the SITL's rate loop) and the true
attitude; ``GeometricController.command`` records the desired attitude
R_d, the yaw torque demand and the collective thrust of each frame.

Figures, over the frames the geometric controller flew after its first
5 s (the take-over transient left out), airborne:

- tracking max / RMS (mm): report.json (after 5 s of settling);
- yaw error max / RMS (deg): true heading of body x minus R_d's (the
  heading of b1d), on the frame's true attitude;
- saturated frames: some motor command <= 0.002 or >= 0.998;
- yaw demand beyond the authority: ``|tau_z| > c_tau f`` (the mixer's
  ``yaw_torque_limit(f)`` at hover-like collectives), ``companion`` only
  (in ``rates`` the SITL's rate loop makes the torque);
- median and 99th percentile of ``|cmd_i(k) - cmd_i(k-1)|`` over motors
  and frames; frames whose yaw pair difference ``(c0 + c1) - (c2 + c3)``
  (PX4 quad-X: 0, 1 spin CCW, 2, 3 CW) moves by more than 0.5.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT / "benchmarks") not in sys.path:
    sys.path.insert(0, str(ROOT / "benchmarks"))

from control_modes import mission_copy  # noqa: E402

MISSIONS = ("flat-rectangle", "tilted-hexagon")


def fly(mission: str, control: str, cut_s: float | None, profile: str | None, tmp: Path) -> dict:
    """One demo with the taps; returns the figures of the module docstring."""
    from companion.cli import main as cli_main
    from companion.control import GeometricController
    from sitl.sim import Simulation

    plant_log, ctl_log = {}, []
    step0, cmd0 = Simulation.step_frame, GeometricController.command

    def step_frame(self, motor_cmd_norm):
        frame = step0(self, motor_cmd_norm)
        plant_log[frame.time_us - self.sensor_period_us] = (tuple(float(c) for c in motor_cmd_norm),
                                                            np.array(frame.truth.R), frame.truth.landed)
        return frame

    def command(self, t_s, meas, ref):
        cmd = cmd0(self, t_s, meas, ref)
        b1x, b1y = self.last_desired[0], self.last_desired[1]
        ctl_log.append((int(round(t_s * 1e6)), math.atan2(b1y, b1x), self._last_detail[0][2], self.last_desired[9]))
        return cmd

    out = Path(tempfile.mkdtemp(prefix=f"{mission}-{control}-", dir=tmp))
    path = mission_copy(mission, out / "mission", profile)
    argv = ["demo", "--mission", str(path), "--control", control, "--transport", "inproc", "--out", str(out),
            "--no-plots", "--quiet"]
    if cut_s is not None:
        argv += ["--cut", str(cut_s)]
    Simulation.step_frame, GeometricController.command = step_frame, command
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            rc = cli_main(argv)
    finally:
        Simulation.step_frame, GeometricController.command = step0, cmd0
    rep = json.loads((out / "report.json").read_text())
    from mavcore.mission import load_mission

    veh = load_mission(path).vehicle
    t0 = ctl_log[0][0]
    rows = [r for r in ctl_log if r[0] - t0 >= 5_000_000 and r[0] in plant_log]
    yaw_err, over = [], []
    for t_us, yaw_d, tau_z, f in rows:
        _, R, _ = plant_log[t_us]
        yaw = math.atan2(R[1, 0], R[0, 0])
        yaw_err.append(math.degrees(math.remainder(yaw - yaw_d, 2.0 * math.pi)))
        over.append(abs(tau_z) > veh.torque_coeff_m * f)
    t_first, t_last = rows[0][0], rows[-1][0]
    keys = sorted(k for k in plant_log if t_first <= k <= t_last and not plant_log[k][2])
    cmds = np.array([plant_log[k][0] for k in keys])
    d = np.abs(np.diff(cmds, axis=0))
    pair = (cmds[:, 0] + cmds[:, 1]) - (cmds[:, 2] + cmds[:, 3])
    yaw_err = np.array(yaw_err)
    tr = rep["tracking"]
    return {"rc": rc, "completed": bool(rep["completed"]), "max_mm": 1e3 * tr["max_error_m"],
            "rms_mm": 1e3 * tr["rms_error_m"], "yaw_max_deg": float(np.max(np.abs(yaw_err))),
            "yaw_rms_deg": float(np.sqrt(np.mean(yaw_err ** 2))),
            "sat": float(np.mean((cmds <= 0.002).any(axis=1) | (cmds >= 0.998).any(axis=1))),
            "over": float(np.mean(over)) if control == "companion" else float("nan"),
            "dcmd_med": float(np.median(d)), "dcmd_p99": float(np.percentile(d, 99)),
            "pair_jump": float(np.mean(np.abs(np.diff(pair)) > 0.5)), "frames": len(keys)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--missions", nargs="+", default=list(MISSIONS))
    ap.add_argument("--controls", nargs="+", default=["companion", "rates"], choices=("companion", "rates"))
    ap.add_argument("--cut", type=float, default=None)
    ap.add_argument("--profile", default=None, help="sim.sensor_profile (default: the mission's sensors)")
    ap.add_argument("--label", default="", help="a label for the rows (e.g. the branch)")
    args = ap.parse_args(argv)
    import companion

    print(f"# package: {Path(companion.__file__).resolve().parent}", flush=True)
    print("| label | terrain | sensors | --control | completed | max / RMS (mm) | yaw err max / RMS (deg) | "
          "saturated frames | tau_z beyond authority | median / p99 abs d cmd | yaw-pair jumps > 0.5 |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for mission in args.missions:
            for control in args.controls:
                r = fly(mission, control, args.cut, args.profile, Path(tmp))
                over = "n/a" if math.isnan(r["over"]) else f"{100 * r['over']:.1f} %"
                print(f"| {args.label} | {mission} | {args.profile or 'mission'} | {control} | "
                      f"{'yes' if r['completed'] else 'NO'} | {r['max_mm']:.2f} / {r['rms_mm']:.2f} | "
                      f"{r['yaw_max_deg']:.2f} / {r['yaw_rms_deg']:.2f} | {100 * r['sat']:.1f} % | "
                      f"{over} | "
                      f"{r['dcmd_med']:.4f} / {r['dcmd_p99']:.4f} | {100 * r['pair_jump']:.1f} % |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
