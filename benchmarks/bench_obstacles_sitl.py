"""Obstacle avoidance end to end (issue 8): randomized obstacle placements
flown in the bundled SITL, in lockstep over MAVLink/UDP, through the real
``companion`` flight loop (``companion demo``).

Usage::

    python benchmarks/bench_obstacles_sitl.py [--flights 50] [--seed 1] [--cut 60]
        [--json results.json] [--keep DIR] [--only I ...] [--dry-run] [--from-json results.json]

Every flight is one ``companion demo --mission M --out DIR --no-plots --quiet
--cut S --seed N`` in a fresh process (SITL subprocess, planning, the flight,
report.json), one after the other. ``M`` is ``missions/obstacle-low`` (its
rangefinder rings and the ``replan.sensors`` mounts, flat-rectangle's maps
made absolute) with its ``sim.obstacles`` list replaced by the placement.

Placements (all drawn up front from ``--seed``, so flight I is the same with
``--only I``): 0-3 obstacles per flight, cylinders (radius 0.15-0.4 m) or
boxes (sides 0.3-1.0 m, yaw 0-90 deg), heights 0.8-4 m (above ``ceiling -
wall margin - clearance - body radius - governor margin`` = 3 - 0.1 - 0.5 -
0.442 - 0.1 = 1.858 m an obstacle cannot be climbed, ``replanner.too_tall``:
the vehicle has to stop and re-route, or hold and report when no route
exists). A centre is a point of the part of the trajectory
that is flown (the plan cut at ``--cut`` seconds, as ``companion fly
--cut`` cuts it: corridors y = 8.75 m westward and 6.25 m eastward, the
headlands between them, the start of the east headland), uniform in arc
length, moved up to 0.8 m across the direction of travel; it is at least
2.5 m from the launch point (the vehicle takes off there) and from the end
of the cut trajectory (it lands there). The footprint, grown by 0.05 m, lies
in free cells of the map: it touches no vine row and stays inside the
mapped field. Obstacles may overlap each other. The SITL's seed (noise) of
flight I is ``1000 * seed + I``.

Per flight: the outcome, from report.json:

- ``completed``: ``completed`` true (no violation, landed and disarmed);
- ``held``: the replanner found no route, held and reported
  (``violation.kind`` ``no_route``), no crash;
- ``crashed``: ``crashed`` true (the SITL's ground truth: the vehicle
  sphere touched an obstacle, a row or the ground too hard);
- ``failed``: anything else (another violation, no report, a timeout), with
  its reason;

and ``replanning`` (events, the true clearance of the vehicle sphere to the
obstacles from the SITL's ODOMETRY, lateral deviation, extra path, climb,
the event list with the nearest obstacle to each event) and
``tracking.max_error_m``.

``--from-json`` prints the flights and the summary of an earlier ``--json``
without flying. Results: BENCHMARKS.md, "Obstacle avoidance in the SITL".

Issue 8's targets: every flight completed (re-routed where a corridor is
blocked) or, where no route exists, held and reported; 0 crashes; minimum
true clearance >= 0.5 m; lateral deviation <= 0.5 m.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import re
import signal
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BASE_MISSION = ROOT / "missions" / "obstacle-low" / "mission.yaml"
#: wall-clock limit of one flight (s)
FLIGHT_TIMEOUT_S = 900.0

sys.path.insert(0, str(ROOT))
# The placement logic lives in the campaign package (``companion campaign``).
from companion.campaign.placement import (  # noqa: E402
    KEEP_OUT_M, OFFSET_M, FOOTPRINT_MARGIN_M, climbable, footprint_free, horizontal_distance,
    random_obstacle)

__all__ = ["KEEP_OUT_M", "OFFSET_M", "FOOTPRINT_MARGIN_M", "footprint_free", "random_obstacle"]


# --- placements ----------------------------------------------------------------------------------

def setup(base: Path, cut_s: float):
    """The base mission, its plan, the flown (cut) trajectory sampled every 0.05 s,
    and the vehicle's clearance figures."""
    from companion.flight_plan import FlightPlan
    from mavcore.mission import load_mission
    from companion.planner import plan_mission
    from companion.replan.replanner import mission_replan_config

    m = load_mission(base)
    plan = plan_mission(m)
    fp = FlightPlan.from_plan(plan)
    if cut_s is not None:
        fp = fp.cut(cut_s, m.trajectory)
    tr = fp.trajectory
    t = np.arange(float(tr.t0), float(tr.t0) + float(tr.duration_s), 0.05)
    path = np.asarray(tr.sample(t).p, dtype=float)
    rc = mission_replan_config(m)
    return m, plan.grid, path, float(tr.duration_s), rc


def placements(n_flights: int, seed: int, grid, path: np.ndarray) -> list[list[dict]]:
    rng = np.random.default_rng(seed)
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path[:, :2], axis=0).T))])
    return [[random_obstacle(rng, grid, path, cum) for _ in range(int(rng.integers(0, 4)))]
            for _ in range(n_flights)]


def obstacle_yaml(o: dict) -> str:
    keys = ["type", "x", "y"] + (["radius"] if o["type"] == "cylinder" else ["size_x", "size_y", "yaw_deg"]) \
        + ["height"]
    return "{" + ", ".join(f"{k}: {o[k]}" for k in keys) + "}"


def mission_text(base: Path, obstacles: list[dict]) -> str:
    """The base mission with absolute map/dem paths and ``sim.obstacles`` replaced."""
    text = base.read_text(encoding="utf-8")

    def absolute(mt):
        p = Path(mt.group(2))
        return f"{mt.group(1)}: {p if p.is_absolute() else (base.parent / p).resolve()}"

    text, n_paths = re.subn(r"^(map|dem): *(\S+) *$", absolute, text, flags=re.M)
    block = "  obstacles: []\n" if not obstacles else \
        "  obstacles:\n" + "".join(f"    - {obstacle_yaml(o)}\n" for o in obstacles)
    text, n_obs = re.subn(r"^  obstacles:(?: *\[\])? *\n(?:    - .*\n)*", lambda _: block, text, flags=re.M)
    if n_paths != 2 or n_obs != 1:
        raise SystemExit(f"{base}: expected map:, dem: and one sim.obstacles list "
                         f"(found {n_paths} paths, {n_obs} lists)")
    return text


# --- one flight ----------------------------------------------------------------------------------

def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(10)
    except (ProcessLookupError, subprocess.TimeoutExpired):
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    proc.wait()


def fly(index: int, obstacles: list[dict], sim_seed: int, cut_s: float, base: Path, rc,
        keep: Path | None, timeout_s: float) -> dict:
    work = Path(tempfile.mkdtemp(prefix=f"bench_obst_{index:03d}_"))
    mission = work / "mission.yaml"
    mission.write_text(mission_text(base, obstacles), encoding="utf-8")
    out = work / "out"
    cmd = [sys.executable, "-m", "companion", "demo", "--mission", str(mission), "--out", str(out),
           "--no-plots", "--quiet", "--cut", f"{cut_s:g}", "--seed", str(sim_seed)]
    t0 = time.perf_counter()
    # own process group: a timeout ends the demo and its SITL, nothing else
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, cwd=str(ROOT))
    try:
        stdout, stderr = proc.communicate(timeout=timeout_s)
        timed_out = False
    except subprocess.TimeoutExpired:
        _kill_group(proc)
        stdout, stderr = proc.communicate()
        timed_out = True
    wall = time.perf_counter() - t0
    (work / "stdout.txt").write_text(stdout or "")
    (work / "stderr.txt").write_text(stderr or "")
    rec = {"flight": index, "sim_seed": sim_seed, "n_obstacles": len(obstacles),
           "obstacles": [dict(o, top_m=o["height"], climbable=climbable(o, rc)) for o in obstacles],
           "returncode": proc.returncode, "wall_s": round(wall, 2)}
    rp = out / "report.json"
    if timed_out or not rp.exists():
        rec.update(outcome="failed", reason=("timeout after %.0f s" % timeout_s) if timed_out else
                   f"no report.json (exit {proc.returncode}): " + (stderr or "").strip()[-300:])
    else:
        rep = json.loads(rp.read_text())
        v = rep.get("violation") or {}
        r = rep.get("replanning") or {}
        events = []
        for e in r.get("event_list") or []:
            p = e.get("pos_enu_m") or [math.nan] * 3
            near = min(((horizontal_distance(o, p[0], p[1]), k) for k, o in enumerate(obstacles)),
                       default=(None, None))
            events.append({"t_s": round(e["t_s"], 3), "action": e["action"], "detail": e.get("detail"),
                           "pos_enu_m": [round(c, 3) for c in p], "obstacle_range_m": e.get("obstacle_range_m"),
                           "nearest_obstacle": near[1],
                           "nearest_obstacle_m": None if near[0] is None else round(near[0], 3)})
        if rep.get("crashed"):
            outcome = "crashed"
        elif rep.get("completed"):
            outcome = "completed"
        elif v.get("kind") == "no_route":
            outcome = "held"
        else:
            outcome = "failed"
        rec.update(
            outcome=outcome, completed=rep.get("completed"), crashed=rep.get("crashed"),
            violation_kind=v.get("kind"), violation_detail=v.get("detail"),
            violation_t_s=v.get("t_s"), crash=rep.get("crash"), error=rep.get("error"),
            reason=None if outcome == "completed" else (rep.get("error") or v.get("detail") or rep.get("phase")),
            events=r.get("events"), actions=[e["action"] for e in events],
            min_clearance_m=r.get("min_clearance_m"), min_clearance_obstacle=r.get("min_clearance_obstacle"),
            min_clearance_t_s=r.get("min_clearance_t_s"),
            max_lateral_deviation_m=r.get("max_lateral_deviation_m"), extra_path_m=r.get("extra_path_m"),
            max_climb_m=r.get("max_climb_m"), min_range_m=r.get("min_range_m"), replan_mode=r.get("mode"),
            tracking_max_error_m=(rep.get("tracking") or {}).get("max_error_m"),
            sim_time_s=rep.get("sim_time_s"), trajectory_duration_s=rep.get("trajectory_duration_s"),
            path_flown_fraction=rep.get("path_flown_fraction"), event_list=events)
    if keep is not None and (rec["outcome"] != "completed" or KEEP_ALL):
        dest = keep / f"flight-{index:03d}"
        if dest.exists():
            shutil.rmtree(dest)
        shutil.copytree(work, dest)
        rec["kept"] = str(dest)
    shutil.rmtree(work, ignore_errors=True)
    return rec


#: --keep-all: keep the completed flights' directories too
KEEP_ALL = False


# --- summary -------------------------------------------------------------------------------------

def _fmt(x, unit=" m", nd=2) -> str:
    return "n/a" if x is None else f"{x:.{nd}f}{unit}"


def flight_line(r: dict) -> str:
    obs = " ".join(f"{o['type'][0]}{o['height']:.1f}{'' if o['climbable'] else '!'}" for o in r["obstacles"]) or "-"
    if "events" not in r:
        return f"{r['flight']:3d} seed {r['sim_seed']:5d} [{obs}] {r['outcome']}: {r['reason']} ({r['wall_s']:.0f} s)"
    return (f"{r['flight']:3d} seed {r['sim_seed']:5d} [{obs}] {r['outcome']:9s} "
            f"clear {_fmt(r['min_clearance_m'])} lat {_fmt(r['max_lateral_deviation_m'])} "
            f"extra {_fmt(r['extra_path_m'], ' m', 1)} climb {_fmt(r['max_climb_m'])} "
            f"track {_fmt(r['tracking_max_error_m'] and r['tracking_max_error_m'] * 1e3, ' mm', 1)} "
            f"flown {_fmt(r['path_flown_fraction'], '', 3)} "
            f"events {' '.join(r['actions']) or '-'} ({r['wall_s']:.0f} s)"
            + ("" if r["outcome"] == "completed" else f"  [{r['reason']}]"))


def summary(rows: list[dict]) -> dict:
    by = {k: [r for r in rows if r["outcome"] == k] for k in ("completed", "held", "crashed", "failed")}
    clear = [r["min_clearance_m"] for r in rows if r.get("min_clearance_m") is not None]
    lat = [r["max_lateral_deviation_m"] for r in rows if r.get("max_lateral_deviation_m") is not None]
    extra_done = [r["extra_path_m"] for r in by["completed"] if r.get("extra_path_m") is not None]
    extra_repl = [r["extra_path_m"] for r in by["completed"] if r.get("events") and r.get("extra_path_m") is not None]
    track = [r["tracking_max_error_m"] for r in rows if r.get("tracking_max_error_m") is not None]
    acts = [a for r in rows for a in r.get("actions", [])]
    skipped = {r["flight"]: sum(int(mt.group(1)) for e in r.get("event_list", []) if e["action"] == "reroute"
                                for mt in [re.search(r"(\d+) unreachable", e.get("detail") or "")] if mt)
               for r in rows}
    flown = [r["path_flown_fraction"] for r in by["completed"] if r.get("path_flown_fraction") is not None]
    flown_free = [r["path_flown_fraction"] for r in by["completed"]
                  if not r["n_obstacles"] and r.get("path_flown_fraction") is not None]
    return {
        "flights": len(rows),
        "with_obstacles": sum(1 for r in rows if r["n_obstacles"]),
        "obstacles": sum(r["n_obstacles"] for r in rows),
        "unclimbable_obstacles": sum(1 for r in rows for o in r["obstacles"] if not o["climbable"]),
        "completed": len(by["completed"]),
        "completed_rerouted": sum(1 for r in by["completed"] if "reroute" in r.get("actions", [])),
        "completed_climbed": sum(1 for r in by["completed"] if "climb" in r.get("actions", [])),
        "held_no_route": len(by["held"]),
        "crashed": len(by["crashed"]),
        "other_failures": len(by["failed"]),
        "failures": [{"flight": r["flight"], "outcome": r["outcome"], "reason": r.get("reason")}
                     for r in rows if r["outcome"] in ("crashed", "failed")],
        "held": [{"flight": r["flight"], "reason": r.get("reason")} for r in by["held"]],
        "completed_with_pieces_skipped": [r["flight"] for r in by["completed"] if skipped[r["flight"]]],
        "min_clearance_m": min(clear) if clear else None,
        "flights_below_0_5_m": sum(1 for c in clear if c < 0.5),
        "max_lateral_deviation_m": max(lat) if lat else None,
        "flights_above_0_5_m_lateral": sum(1 for x in lat if x > 0.5),
        "median_extra_path_completed_m": statistics.median(extra_done) if extra_done else None,
        "median_extra_path_replanned_m": statistics.median(extra_repl) if extra_repl else None,
        "max_tracking_error_m": max(track) if track else None,
        "actions": {a: acts.count(a) for a in sorted(set(acts))},
        "path_flown_fraction_completed_median": statistics.median(flown) if flown else None,
        "path_flown_fraction_completed_min": min(flown) if flown else None,
        "path_flown_fraction_obstacle_free": statistics.median(flown_free) if flown_free else None,
        "median_wall_s": statistics.median(r["wall_s"] for r in rows) if rows else None,
        "total_wall_s": sum(r["wall_s"] for r in rows),
    }


def markdown(s: dict) -> str:
    n = s["flights"]
    ok = s["completed"] + s["held_no_route"]
    yes = (lambda c: "yes" if c else "**no**")
    lines = [
        "| figure | value | target | met |",
        "|---|---|---|---|",
        f"| flights (with obstacles; obstacles, of which not climbable) | {n} ({s['with_obstacles']}; "
        f"{s['obstacles']}, {s['unclimbable_obstacles']}) | | |",
        f"| completed (of which with a re-route; with a climb event) | {s['completed']} ({s['completed_rerouted']}; "
        f"{s['completed_climbed']}) | | |",
        f"| completed with coverage pieces left out by a re-route as unreachable | "
        f"{len(s['completed_with_pieces_skipped'])} | | |",
        f"| held and reported (`no_route`) | {s['held_no_route']} | | |",
        f"| completed or held and reported | {ok} / {n} | 100% | {yes(ok == n)} |",
        f"| crashed | {s['crashed']} | 0 | {yes(s['crashed'] == 0)} |",
        f"| other failures | {s['other_failures']} | 0 | {yes(s['other_failures'] == 0)} |",
        f"| min true clearance over flights (flights below 0.5 m) | {_fmt(s['min_clearance_m'], ' m', 3)} "
        f"({s['flights_below_0_5_m']}) | >= 0.5 m | "
        f"{yes(s['min_clearance_m'] is None or s['min_clearance_m'] >= 0.5)} |",
        f"| max lateral deviation (flights above 0.5 m) | {_fmt(s['max_lateral_deviation_m'], ' m', 3)} "
        f"({s['flights_above_0_5_m_lateral']}) | <= 0.5 m | "
        f"{yes(s['max_lateral_deviation_m'] is None or s['max_lateral_deviation_m'] <= 0.5)} |",
        f"| median extra path, completed flights (those that replanned) | "
        f"{_fmt(s['median_extra_path_completed_m'])} ({_fmt(s['median_extra_path_replanned_m'])}) | | |",
        f"| max tracking error (after settle) | {_fmt(s['max_tracking_error_m'] and s['max_tracking_error_m'] * 1e3, ' mm', 1)} | | |",
        f"| path flown (fraction of the plan's), completed flights: median / min (no obstacle) | "
        f"{_fmt(s['path_flown_fraction_completed_median'], '', 3)} / {_fmt(s['path_flown_fraction_completed_min'], '', 3)} "
        f"({_fmt(s['path_flown_fraction_obstacle_free'], '', 3)}) | | |",
        f"| replanning actions | {', '.join(f'{k} {v}' for k, v in s['actions'].items()) or '-'} | | |",
        f"| wall time per flight, median (total) | {s['median_wall_s'] or 0:.0f} s ({s['total_wall_s'] / 60:.0f} min) | | |",
    ]
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=50)
    ap.add_argument("--seed", type=int, default=1, help="seed of the placements (default %(default)s)")
    ap.add_argument("--cut", type=float, default=60.0,
                    help="fly the first S seconds of the trajectory (default %(default)s)")
    ap.add_argument("--json", default=None, metavar="PATH", help="write the per-flight results here")
    ap.add_argument("--keep-all", action="store_true", help="with --keep: keep completed flights too")
    ap.add_argument("--keep", default=None, metavar="DIR",
                    help="keep the mission and out dir of every flight that did not complete here")
    ap.add_argument("--only", type=int, nargs="+", default=None, metavar="I",
                    help="fly only these flights of the --flights placements")
    ap.add_argument("--mission", default=str(BASE_MISSION), help="base mission (default missions/obstacle-low)")
    ap.add_argument("--timeout", type=float, default=FLIGHT_TIMEOUT_S, help="wall seconds per flight")
    ap.add_argument("--dry-run", action="store_true", help="print the placements, fly nothing")
    ap.add_argument("--from-json", default=None, metavar="PATH",
                    help="fly nothing: print the flights and the summary of an earlier --json")
    a = ap.parse_args()
    if a.from_json:
        rows = json.loads(Path(a.from_json).read_text())["flights"]
        for r in rows:
            print(flight_line(r))
        return report(rows)
    base = Path(a.mission).resolve()
    keep = Path(a.keep).resolve() if a.keep else None
    global KEEP_ALL
    KEEP_ALL = bool(a.keep_all)
    if keep is not None:
        keep.mkdir(parents=True, exist_ok=True)

    m, grid, path, duration, rc = setup(base, a.cut)
    every = placements(a.flights, a.seed, grid, path)
    todo = a.only if a.only is not None else list(range(a.flights))
    print(f"{len(todo)} flights, placements seed {a.seed}, cut {a.cut:g} s (trajectory {duration:.1f} s, "
          f"({path[0, 0]:.2f}, {path[0, 1]:.2f}) -> ({path[-1, 0]:.2f}, {path[-1, 1]:.2f})), body radius "
          f"{rc.body_radius_m:.3f} m, clearance {rc.clearance_m} m, ceiling {rc.ceiling_agl_m} m: "
          f"climbable up to {rc.ceiling_agl_m - rc.clearance_m - rc.body_radius_m:.3f} m; python "
          f"{platform.python_version()}, {os.cpu_count()} cores", flush=True)
    if a.dry_run:
        for i in todo:
            print(f"{i:3d} " + ("; ".join(obstacle_yaml(o) for o in every[i]) or "-"))
        return 0

    rows = []
    meta = {"command": " ".join(sys.argv), "seed": a.seed, "cut_s": a.cut, "base_mission": str(base),
            "python": platform.python_version(), "cores": os.cpu_count(),
            "date": time.strftime("%Y-%m-%d %H:%M:%S %Z")}
    for i in todo:
        r = fly(i, every[i], 1000 * a.seed + i, a.cut, base, rc, keep, a.timeout)
        rows.append(r)
        print(flight_line(r), flush=True)
        if a.json:
            Path(a.json).write_text(json.dumps({"meta": meta, "summary": summary(rows), "flights": rows},
                                               indent=1) + "\n")
    return report(rows)


def report(rows: list[dict]) -> int:
    s = summary(rows)
    print()
    print(markdown(s))
    for f in s["failures"]:
        print(f"- flight {f['flight']} {f['outcome']}: {f['reason']}")
    for f in s["held"]:
        print(f"- flight {f['flight']} held: {f['reason']}")
    ok = s["crashed"] == 0 and s["other_failures"] == 0
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
