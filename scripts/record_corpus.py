"""Record the replay regression corpus (``tests/data/replay/``).

Usage::

    python scripts/record_corpus.py [--out tests/data/replay] [--only NAME]

Flies short segments of the bundled ``flat-rectangle`` mission against the
bundled SITL (a subprocess, lockstep, loopback UDP) with ``companion fly``'s
own code (``companion.commands.fly.execute``), from a small ``plan.json``
planned here (format 2.x: the trajectory's pieces, no samples), and
writes for each flight ``NAME.tlog.xz`` (the .tlog, xz-compressed; ``companion
replay`` reads it as is) and ``NAME.report.json`` (the live flight's report).

Flights (``FLIGHTS``):

- ``companion-cut4``: ``--control companion --cut 4``, with the SITL's
  ground-truth ODOMETRY (the side-channel test withholds it);
- ``vehicle-cut4``: ``--control vehicle --cut 4``, no ground truth (the
  metrics use the vehicle's estimate);
- ``obstacle``: ``--control companion --cut 12`` of ``mission-obstacle.yaml``
  (the flat-rectangle plan with an unknown 1.2 m crate 5.45 m into the first
  corridor): the replanner climbs over it and rejoins; its decisions are
  STATUSTEXT ``companion: replan ...`` and the setpoints;
- ``linkloss``: ``--control companion --cut 8``; 2 s into the trajectory a
  relay between the companion and the SITL drops everything the companion
  sends (the companion stops answering, as far as the vehicle can tell):
  the SITL's lockstep times out (SIM_LS_TMO) and it runs free, COM_HIL_TMO
  hands the motors back to its own controller, the offboard loss failsafe
  holds (AUTO.LOITER) then lands; the companion, which still hears the
  vehicle, sees the mode it did not ask for, lets go and watches the
  landing. Not a completed flight (the report says why).

Streams the replay does not need are muted (ATTITUDE, ATTITUDE_QUATERNION,
POSITION_TARGET_LOCAL_NED, and DISTANCE_SENSOR but in ``obstacle``); the position streams for log
tools stay at 5 Hz. Re-record after any intended change of the controller,
the flight core or the SITL (the replay tests then pass again).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import lzma
import select
import shutil
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

MISSION = ROOT / "missions" / "flat-rectangle" / "mission.yaml"
PLAN_NAME = "plan-flat-rectangle.json"
ATTITUDE, ATTITUDE_QUATERNION, POSITION_TARGET_LOCAL_NED, DISTANCE_SENSOR = 30, 31, 85, 132
MUTE = (ATTITUDE, ATTITUDE_QUATERNION, POSITION_TARGET_LOCAL_NED, DISTANCE_SENSOR)

OBSTACLE_MISSION = ROOT / "tests" / "data" / "replay" / "mission-obstacle.yaml"

#: name -> (control, cut_s, request_truth, link cut: vehicle seconds after the trajectory starts or None,
#: mission, muted streams)
FLIGHTS = {
    "companion-cut4": ("companion", 4.0, True, None, MISSION, MUTE),
    "vehicle-cut4": ("vehicle", 4.0, False, None, MISSION, MUTE),
    "linkloss": ("companion", 8.0, False, 2.0, MISSION, MUTE),
    # the replanner's decisions: DISTANCE_SENSOR (41 sensors at 20 Hz) kept
    "obstacle": ("companion", 12.0, True, None, OBSTACLE_MISSION, (ATTITUDE, ATTITUDE_QUATERNION,
                                                                  POSITION_TARGET_LOCAL_NED)),
}


class DropRelay(threading.Thread):
    """UDP relay companion <-> SITL that, from vehicle time ``cut_at_s`` on,
    drops every datagram the companion sends (the vehicle's still arrive)."""

    def __init__(self, sitl_addr: tuple, cut_at_s: float | None) -> None:
        super().__init__(daemon=True)
        self.sitl_addr = sitl_addr
        self.cut_at_s = cut_at_s
        self.c = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.c.bind(("127.0.0.1", 0))
        self.v = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.v.bind(("127.0.0.1", 0))
        self.peer = None
        self.cut = False
        self.cut_t = None
        self.n_dropped = 0
        self.stop = False

    @property
    def url(self) -> str:
        return f"udpout:127.0.0.1:{self.c.getsockname()[1]}"

    def run(self) -> None:
        from mavcore.codec import split_datagram

        while not self.stop:
            r, _, _ = select.select([self.c, self.v], [], [], 0.05)
            for s in r:
                data, addr = s.recvfrom(65536)
                if s is self.c:
                    self.peer = addr
                    if self.cut:
                        self.n_dropped += 1
                    else:
                        self.v.sendto(data, self.sitl_addr)
                else:
                    if self.cut_at_s is not None and not self.cut:
                        for m in split_datagram(data):
                            if type(m) is not bytes and m.get_type() == "HIGHRES_IMU" \
                                    and m.time_usec * 1e-6 >= self.cut_at_s:
                                self.cut, self.cut_t = True, m.time_usec * 1e-6
                    if self.peer is not None:
                        self.c.sendto(data, self.peer)

    def close(self) -> None:
        self.stop = True
        self.join(2.0)
        self.c.close()
        self.v.close()


def record(name: str, out: Path, plan_path: Path) -> dict:
    from sitl.api import SitlProcess

    from companion.commands.demo import launch_pose
    from companion.commands.fly import execute, prepare
    from mavcore.mission import load_mission
    from companion.report import write_report
    from companion.runner import UNUSED_STREAMS

    control, cut_s, truth, link_cut, mission_path, mute = FLIGHTS[name]
    mission = load_mission(mission_path)
    fp = prepare(mission, str(plan_path))
    overrides = {"mute_streams": tuple(sorted(set(UNUSED_STREAMS + mute))), "request_truth": truth}
    with tempfile.TemporaryDirectory(prefix="corpus_") as tmp:
        tlog = Path(tmp) / f"{name}.tlog"
        pose = launch_pose(fp.cut(cut_s, mission.trajectory).trajectory, fp.target_enu_m)
        with SitlProcess(mission_path, lockstep=True, speed=1.0, start=pose) as sitl:
            relay = None
            url = sitl.url
            if link_cut is not None:
                host, port = sitl.listen.split(":")[1:]
                relay = DropRelay((host, int(port)), TRAJECTORY_START_S + link_cut)
                relay.start()
                url = relay.url
            try:
                result = execute(mission, fp, url, control, str(tlog), None, cut_s, overrides, str(plan_path))
            finally:
                if relay is not None:
                    relay.close()
        rep = dataclasses.replace(result.report, tlog=f"{name}.tlog.xz")   # not the temporary path
        write_report(rep, out / f"{name}.report.json")
        data = tlog.read_bytes()
    (out / f"{name}.tlog.xz").write_bytes(lzma.compress(data, preset=9 | lzma.PRESET_EXTREME))
    info = {"name": name, "mission": str(mission_path.relative_to(ROOT)), "control": control, "cut_s": cut_s, "request_truth": truth, "link_cut_s": link_cut,
            "completed": rep.completed, "sim_time_s": rep.sim_time_s, "tlog_bytes": len(data),
            "xz_bytes": (out / f"{name}.tlog.xz").stat().st_size}
    if relay is not None:
        info["link_cut_at_s"] = relay.cut_t
        info["companion_datagrams_dropped"] = relay.n_dropped
    return info


#: Vehicle time (s) the trajectory phase starts in these flights (launched under the first way-point):
#: setup and upload, 1 s of preflight, the 1.5 m climb, 1 s hold (``FlightCore._t_traj`` of a replay of
#: companion-cut4: 5.345 s).
TRAJECTORY_START_S = 5.35


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "tests" / "data" / "replay"))
    ap.add_argument("--only", choices=sorted(FLIGHTS), action="append")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    plan_path = out / PLAN_NAME
    if not plan_path.exists() or not args.only:
        import subprocess

        r = subprocess.run([sys.executable, "-m", "companion.cli", "plan", str(MISSION), "-o", str(plan_path)],
                           capture_output=True, text=True)
        if r.returncode != 0:
            raise SystemExit(r.stderr)
    manifest_path = out / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.exists() else {}
    for name in args.only or FLIGHTS:
        t0 = time.monotonic()
        info = record(name, out, plan_path)
        manifest[name] = info
        print(f"{name}: {'completed' if info['completed'] else 'NOT completed'}, {info['sim_time_s']:.1f} s, "
              f"{info['tlog_bytes'] / 1e6:.2f} MB -> {info['xz_bytes'] / 1e6:.2f} MB xz "
              f"({time.monotonic() - t0:.0f} s wall)", flush=True)
    manifest_path.write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    total = sum(p.stat().st_size for p in out.iterdir())
    print(f"corpus: {total / 1e6:.2f} MB in {out}")
    shutil.rmtree(out / "__pycache__", ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
