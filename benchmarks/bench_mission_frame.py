"""Per-frame cost of the SITL flying AUTO.MISSION (issue 17) against holding
in AUTO.LOITER, in process, without links (process time, median of runs).

Usage::

    python benchmarks/bench_mission_frame.py [--mission missions/flat-rectangle/mission.yaml] [--runs 3]

The mission's QGC ``.plan`` is exported by ``companion plan --qgc`` into a
temporary directory; its mission and geofence items are stored in a
``SitlServer`` (no sockets), which is armed and flown ``--seconds`` of
vehicle time from take-off: once holding with nothing stored (take-off,
then AUTO.LOITER: the SITL's per-frame work before missions), once in
AUTO.MISSION with the fence enforced. Printed: microseconds of
``step_once`` per sensor frame (``time.process_time``), median of ``--runs``;
then the mission state machine and the fence check alone (an ideal vehicle),
which is the part the mission adds to a frame.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from companion.cli import main as companion_main   # noqa: E402
from mavcore.mission import load_mission   # noqa: E402
from mavcore.codec import MissionItem   # noqa: E402
from sitl.flightstack import FlightMode, NavState   # noqa: E402
from sitl.server import ServerConfig, SitlServer   # noqa: E402


def plan_items(plan_path: Path) -> tuple[list, list]:
    """(mission, fence) ``MissionItem``s of a QGC .plan (simple items, polygon fences)."""
    doc = json.loads(plan_path.read_text())
    mission = []
    for seq, it in enumerate(doc["mission"]["items"]):
        p = [0.0 if v is None else float(v) for v in it["params"]]
        mission.append(MissionItem(seq, int(it["frame"]), int(it["command"]), int(seq == 0), 1, *p[:4],
                                   round(p[4] * 1e7), round(p[5] * 1e7), p[6], 0))
    fence = []
    for poly in doc["geoFence"]["polygons"]:
        for lat, lon in poly["polygon"]:
            fence.append(MissionItem(len(fence), 0, 5001, 0, 1, float(len(poly["polygon"])), 0.0, 0.0, 0.0,
                                     round(lat * 1e7), round(lon * 1e7), 0.0, 1))
    return mission, fence


def _state(srv):
    """The flight stack's view of the current frame (``Vehicle.state``; ``SitlServer._state`` before h17-split)."""
    return srv.vehicle.state() if hasattr(srv, "vehicle") else srv._state()


def fly(mission_path: Path, items: tuple, mode: str, seconds: float) -> float:
    """Microseconds of process time per ``step_once``, flying ``seconds``."""
    srv = SitlServer(load_mission(mission_path), ServerConfig())
    if mode == "mission":   # hold: nothing stored, the SITL as it was before missions were flown
        srv.missions.stored[0], srv.missions.stored[1] = tuple(items[0]), tuple(items[1])
        srv.missions.version += 1
    srv.step_once()
    srv.mission_link.sync_store()
    veh = getattr(srv, "vehicle", srv)        # the vehicle's parts (``sitl.vehicle``; the server before h17-split)
    now, st = veh.sim.time_us, _state(srv)
    if mode == "mission":
        assert veh.stack.start_mission(now, st, None).accepted
    else:
        veh.stack.takeoff(now, st, None)
    assert veh.stack.arm(now, st).accepted
    n = int(seconds * 1e6 / veh.sim.sensor_period_us)
    t0 = time.process_time()
    for _ in range(n):
        srv.step_once()
    dt = time.process_time() - t0
    if mode == "mission":
        assert veh.stack.mode in (FlightMode.MISSION, FlightMode.RTL), veh.stack.mode
        assert not veh.stack.fence_breached
    return dt / n * 1e6


def executor_alone(mission_path: Path, items: tuple, seconds: float) -> float:
    """Microseconds per frame of ``MissionExecutor.update`` + ``Fence.breached``
    alone, on an ideal vehicle that is where the last setpoint was."""
    srv = SitlServer(load_mission(mission_path), ServerConfig())
    srv.missions.stored[0], srv.missions.stored[1] = tuple(items[0]), tuple(items[1])
    srv.missions.version += 1
    srv.step_once()
    srv.mission_link.sync_store()
    veh = getattr(srv, "vehicle", srv)
    ex, fence = veh.stack.mission, veh.stack.fence
    st = _state(srv)
    ex.start(st, None)
    dt = veh.sim.sensor_period_us * 1e-6
    n = int(seconds / dt)
    p = list(st.pos_enu_m)
    t0 = time.process_time()
    for _ in range(n):
        s = NavState(p, (0.0, 0.0, 0.0), 0.0, 0.0, False)
        sp = ex.update(s, dt).setpoint
        fence.breached(p[0], p[1])
        if sp is not None and sp.pos_enu_m is not None and sp.pos_enu_m[2] == sp.pos_enu_m[2]:
            p = list(sp.pos_enu_m)
    return (time.process_time() - t0) / n * 1e6


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mission", default=str(ROOT / "missions" / "flat-rectangle" / "mission.yaml"))
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=30.0, help="vehicle seconds flown per run")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        with contextlib.redirect_stdout(io.StringIO()):
            assert companion_main(["plan", args.mission, "-o", f"{d}/plan.json", "--qgc", f"{d}/p.plan"]) == 0
        items = plan_items(Path(d) / "p.plan")
    print(f"{len(items[0])} mission items, {len(items[1])} fence items; {args.seconds:g} s of flight per run")
    for mode in ("hold", "mission"):
        fly(Path(args.mission), items, mode, 2.0)   # warm-up
        us = [fly(Path(args.mission), items, mode, args.seconds) for _ in range(args.runs)]
        print(f"{mode:8s} {statistics.median(us):7.1f} us/frame (runs: {', '.join(f'{u:.1f}' for u in us)})")
    us = [executor_alone(Path(args.mission), items, args.seconds) for _ in range(args.runs)]
    print(f"executor + fence check alone {statistics.median(us):5.1f} us/frame "
          f"(runs: {', '.join(f'{u:.1f}' for u in us)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
