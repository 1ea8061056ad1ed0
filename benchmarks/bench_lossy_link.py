"""Flights through a lossy, jittery link in real time (issue 11's degradation target).

Usage::

    python benchmarks/bench_lossy_link.py [--loss 0.2] [--delay-ms 0,30] [--cut 60]
        [--controls vehicle companion] [--seeds 1 2 3] [--mission flat-rectangle]

Each flight: the bundled SITL as a subprocess in **real time** (no lockstep,
speed 1), a ``sitl.relay.UdpRelay`` between it and the companion that drops
each datagram with probability ``--loss`` and delays it by a uniform draw in
``--delay-ms`` (both directions, independently: datagrams are reordered),
and ``companion fly``'s own code (``execute``) flying the first ``--cut``
seconds of the mission's plan, launched under its first way-point.

Figures per flight: completed, crashed, degraded (the companion handed its
inner loop to the vehicle), the report's tracking error, and the same error
recomputed from the .tlog **at matching times**: every ground-truth
ODOMETRY the companion received is paired with the setpoint the companion
sent for the same vehicle millisecond (the reference of that frame), so a
late or lost telemetry datagram cannot make the vehicle look behind its
reference. Issue 11's targets: ``--control vehicle`` completes within 10 cm;
``--control companion``: no crash, completing or degrading, said in the report.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def matched_error(tlog_path: Path, t_start_s: float) -> tuple[float | None, float | None, int]:
    """(max, RMS, n) of |truth - reference| over the ODOMETRY messages received at or after
    ``t_start_s`` (vehicle time) whose millisecond has a setpoint sent by the companion."""
    from companion.link.tlog import read_tlog

    sp, truth = {}, []
    for r in read_tlog(tlog_path):
        m = r.msg
        kind = m.get_type()
        if kind == "SET_POSITION_TARGET_LOCAL_NED" and m.get_srcComponent() == 191:
            sp[int(m.time_boot_ms)] = (m.y, m.x, -m.z)
        elif kind == "ODOMETRY" and m.get_srcSystem() == 1 and m.get_srcComponent() == 1:
            if m.time_usec * 1e-6 >= t_start_s:
                truth.append((int(m.time_usec // 1000), (m.y, m.x, -m.z)))
    err = [float(np.linalg.norm(np.subtract(p, sp[ms]))) for ms, p in truth if ms in sp]
    if not err:
        return None, None, 0
    e = np.array(err)
    return float(e.max()), float(np.sqrt(np.mean(e * e))), len(e)


def fly(mission_name: str, control: str, loss: float, delay_ms: tuple, cut_s: float, seed: int) -> dict:
    from sitl.api import SitlProcess
    from sitl.relay import UdpRelay

    from companion.commands.demo import launch_pose
    from companion.bundled import missions_dir
    from companion.commands.fly import execute, prepare
    from mavcore.mission import load_mission

    path = missions_dir() / mission_name / "mission.yaml"
    mission = load_mission(path)
    fp = prepare(mission, None)
    pose = launch_pose(fp.cut(cut_s, mission.trajectory).trajectory, fp.target_enu_m)
    with tempfile.TemporaryDirectory(prefix="lossy_") as tmp:
        tlog = Path(tmp) / "flight.tlog"
        t0 = time.monotonic()
        with SitlProcess(path, lockstep=False, speed=1.0, start=pose) as sitl:
            host, port = sitl.url.split(":")[1:]
            with UdpRelay((host, int(port)), loss=loss, delay_min_s=delay_ms[0] / 1000,
                          delay_max_s=delay_ms[1] / 1000, seed=seed) as relay:
                res = execute(mission, fp, f"udpout:127.0.0.1:{relay.port}", control, str(tlog), None, cut_s,
                              {"request_truth": True})
        rep = res.report
        # the trajectory phase starts after setup, preflight, climb and hold: settle 5 s into it
        t_traj = res.log.array()
        from companion.flight.core import PHASE_CODE
        in_traj = t_traj[t_traj[:, 1] == PHASE_CODE["trajectory"]]
        t_from = float(in_traj[0, 0]) + rep.tracking.settle_s if len(in_traj) else float("inf")
        mmax, mrms, n = matched_error(tlog, t_from)
    return {"mission": mission_name, "control": control, "seed": seed, "loss": loss, "delay_ms": list(delay_ms),
            "cut_s": cut_s, "completed": rep.completed, "crashed": rep.crashed,
            "violation": None if rep.violation is None else rep.violation.get("kind"),
            "degraded": None if rep.degraded is None else rep.degraded.get("reason"),
            "report_max_error_m": rep.tracking.max_error_m, "report_rms_error_m": rep.tracking.rms_error_m,
            "matched_max_error_m": mmax, "matched_rms_error_m": mrms, "matched_samples": n,
            "wall_s": round(time.monotonic() - t0, 1)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mission", default="flat-rectangle")
    ap.add_argument("--controls", nargs="*", default=["vehicle", "companion"], choices=("vehicle", "companion"))
    ap.add_argument("--loss", type=float, default=0.2)
    ap.add_argument("--delay-ms", default="0,30")
    ap.add_argument("--cut", type=float, default=60.0)
    ap.add_argument("--seeds", type=int, nargs="*", default=[1])
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    lo, hi = (float(x) for x in args.delay_ms.split(","))
    rows = []
    print("| control | seed | completed | crashed | degraded | report max / RMS (mm) | time-matched max / RMS (mm) |")
    print("|---|---|---|---|---|---|---|")
    for control in args.controls:
        for seed in args.seeds:
            r = fly(args.mission, control, args.loss, (lo, hi), args.cut, seed)
            rows.append(r)
            mm = (lambda x: "n/a" if x is None else f"{1000 * x:.1f}")
            print(f"| {control} | {seed} | {r['completed']} | {r['crashed']} | {r['degraded'] or 'no'} | "
                  f"{mm(r['report_max_error_m'])} / {mm(r['report_rms_error_m'])} | "
                  f"{mm(r['matched_max_error_m'])} / {mm(r['matched_rms_error_m'])} "
                  f"({r['matched_samples']} samples) |", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
