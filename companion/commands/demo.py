"""``companion demo [--mission NAME|PATH | --scenario FILE] [--control companion|vehicle] [--out out/] [--seed N]``.

No arguments needed: starts the bundled SITL (``python -m sitl``, a separate
process, lockstep, loopback UDP on a free port), plans the bundled
``flat-rectangle`` mission, flies it with the geometric controller, prints a
summary table and writes ``out/``: ``plan.json``, ``flight.tlog``,
``report.json`` and, with matplotlib (the ``plot`` extra), the paper's
Figs. 14-18 style figures (``companion.flight_plot``).

``--scenario FILE`` flies one scenario of a campaign (docs/campaign.md): its
base mission with its overrides merged in (written to ``out/mission.yaml``,
which the SITL loads), its seed, cut and control; ``--seed``, ``--cut`` and
``--control`` given on the command line win.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

from ..errors import InputError

DEFAULT_MISSION = "flat-rectangle"


def missions_dir() -> Path:
    """The bundled missions (``missions/`` next to the ``companion`` package)."""
    return Path(__file__).resolve().parents[2] / "missions"


def resolve_mission(name_or_path: str) -> Path:
    """A bundled mission name (``flat-rectangle``) or a mission YAML path."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or p.exists():
        if p.is_dir():
            p = p / "mission.yaml"
        return p
    bundled = missions_dir() / name_or_path / "mission.yaml"
    if not bundled.exists():
        names = sorted(d.name for d in missions_dir().iterdir() if (d / "mission.yaml").exists()) \
            if missions_dir().is_dir() else []
        raise InputError(f"--mission {name_or_path}", f"no such mission file or bundled mission "
                         f"(bundled: {', '.join(names) or 'none'})")
    return bundled


def add_arguments(parser) -> None:
    parser.add_argument("--mission", default=None, metavar="NAME|PATH",
                        help=f"bundled mission name or mission YAML (default {DEFAULT_MISSION})")
    parser.add_argument("--scenario", default=None, metavar="FILE",
                        help="a campaign's scenario file: base mission + overrides + seed + cut + control")
    parser.add_argument("--control", choices=("companion", "vehicle"), default=None,
                        help="who tracks the trajectory (default companion: the geometric controller)")
    parser.add_argument("--out", default="out", metavar="DIR", help="output directory (default %(default)s)")
    parser.add_argument("--cut", type=float, default=None, metavar="S",
                        help="fly only the first S seconds of the trajectory")
    parser.add_argument("--seed", type=int, default=None, metavar="N",
                        help="seed of the SITL's noise and wind (default: the mission's sim.seed)")
    parser.add_argument("--signing-key", default=None, metavar="FILE",
                        help="MAVLink 2 signing key file for both the SITL and the companion "
                             "(32 raw bytes, or a passphrase as MAVProxy's signing setup)")
    parser.add_argument("--no-plots", action="store_true", help="skip the figures")
    from .fly import add_safety_arguments

    add_safety_arguments(parser)
    parser.add_argument("--quiet", action="store_true", help="no progress display")


def launch_pose(trajectory, target_enu_m) -> tuple[float, float, float]:
    """Where a user sets the drone down: under the trajectory's first point,
    facing its first pointing direction.

    Returns
    -------
    (x_m, y_m, yaw_deg) : ENU map metres and the heading of the body x axis
    (ENU degrees from east, CCW) for which the pointing axis (body y, b2 of
    eq. 22 with b3 vertical) lies along the horizontal part of s(t0).
    """
    import numpy as np

    from ..runner import pointing_at, setpoint_yaw_enu

    smp = trajectory.sample(np.array([float(trajectory.t0)]))
    p0 = tuple(float(c) for c in smp.p[0])
    if smp.pointing is not None:
        s0 = tuple(float(c) for c in smp.pointing[0])
    else:
        s0 = pointing_at(p0, tuple(float(c) for c in target_enu_m))
    yaw = setpoint_yaw_enu(s0, (0.0, 0.0, 0.0))
    return (p0[0], p0[1], math.degrees(yaw))


def _replanning_row(rp) -> str:
    if not rp.enabled:
        return "off"
    text = f"{rp.events} events"
    if rp.event_list:
        text += f" ({', '.join(rp.actions)})"
    if rp.min_clearance_m is not None:
        text += f", min clearance {rp.min_clearance_m:.2f} m (truth)"
    return text


def _table(rows: list[tuple[str, str]]) -> str:
    w = max(len(k) for k, _ in rows)
    line = "+" + "-" * (w + 2) + "+" + "-" * 34 + "+"
    out = [line]
    for k, v in rows:
        out.append(f"| {k:<{w}} | {v:<32} |")
    out.append(line)
    return "\n".join(out)


def run(args) -> int:
    from sitl.api import SitlProcess

    t_start = time.monotonic()
    scenario = None
    if getattr(args, "scenario", None) is not None:
        if args.mission is not None:
            raise InputError(f"--scenario {args.scenario}", "give either --mission or --scenario, not both")
        from ..campaign.scenario_file import load_scenario

        scenario = load_scenario(args.scenario)
        args.seed = scenario.seed if args.seed is None else args.seed
        args.cut = scenario.cut_s if args.cut is None else args.cut
        args.control = args.control or scenario.control
        mission_path = None
    else:
        mission_path = resolve_mission(args.mission or DEFAULT_MISSION)
    args.control = args.control or "companion"
    if args.cut is not None and not (math.isfinite(args.cut) and args.cut > 0):
        raise InputError(f"--cut {args.cut}", "must be a finite number of seconds > 0")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}", "exists and is not a directory")
    if not out.exists() and not out.parent.is_dir():
        raise InputError(f"--out {out}", f"directory {out.parent} does not exist")
    if out.is_dir():
        from .fly import check_output_paths
        check_output_paths([("--out", out / n) for n in ("plan.json", "flight.tlog", "report.json")
                            + (("mission.yaml",) if scenario is not None else ())])
    key = None
    if args.signing_key is not None:
        from ..link.signing import load_signing_key
        key = load_signing_key(args.signing_key)
    from ..mission import load_mission
    from .fly import safety_overrides

    overrides = safety_overrides(args)
    if scenario is not None:
        import yaml

        from ..campaign.scenario_file import scenario_mission

        data, mission = scenario_mission(scenario, args.scenario)   # bad input fails here
        out.mkdir(parents=True, exist_ok=True)
        mission_path = out / "mission.yaml"
        mission_path.write_text(f"# {args.scenario}: mission {scenario.mission} + the scenario's overrides\n"
                                + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=120),
                                encoding="utf-8")
        mission = load_mission(mission_path)
    else:
        mission = load_mission(mission_path)     # bad input fails here, before the SITL starts
    # The SITL process starts now (it imports and loads its world while we
    # plan) and gets its launch pose once the plan exists.
    sitl = SitlProcess(mission_path, lockstep=True, speed=1.0, seed=args.seed, start="later",
                       signing_key_file=args.signing_key).launch()
    try:
        return _plan_and_fly(args, mission, out, sitl, t_start, key, overrides)
    finally:
        sitl.stop()


def _plan_and_fly(args, mission, out, sitl, t_start, signing_key=None, overrides=None) -> int:
    from ..plan_io import plan_json_text, plan_to_json_dict
    from ..progress import Progress
    from ..report import write_report
    from ..runner import UNUSED_STREAMS
    from .fly import EXIT_FAILED, FlightPlan, execute

    ATTITUDE = 30   # MAVLINK_MSG_ID_ATTITUDE: the SITL's ground-truth ODOMETRY carries the attitude

    from ..planner import plan_mission

    plan = plan_mission(mission)
    plan_text = plan_json_text(plan_to_json_dict(plan, mission, 10.0))
    t_planned = time.monotonic()
    out.mkdir(parents=True, exist_ok=True)
    (out / "plan.json").write_text(plan_text, encoding="utf-8")

    fp = FlightPlan.from_plan(plan)
    progress = Progress(enabled=not args.quiet)
    # The vehicle starts where a user would set it down: under the first
    # way-point, facing the first pointing direction (take-off = climb + hold).
    # The SITL runs at speed 1 until the companion engages lockstep (the
    # vehicle clock barely moves while the link comes up), then flat out.
    sitl.set_start(launch_pose(plan.trajectory, plan.target_enu_m))
    sitl.wait_ready()
    try:
        result = execute(mission, fp, sitl.url, args.control, str(out / "flight.tlog"), progress, args.cut,
                         {"mute_streams": UNUSED_STREAMS + (() if mission.replan.enabled else (ATTITUDE,)),
                          **(overrides or {})},
                         signing_key=signing_key)
    finally:
        sitl.stop()
    rep = result.report
    write_report(rep, out / "report.json")
    t_flown = time.monotonic()

    figures = []
    if not args.no_plots:
        try:
            from ..flight_plot import write_flight_figures
        except ImportError:   # matplotlib missing: the plot extra is optional here
            figures = None
        else:
            try:
                figures = write_flight_figures(result.log, plan, out)
                rp = rep.replanning
                if mission.sim.obstacles or rp.events:
                    from ..flight_plot import write_avoidance_figure

                    f = write_avoidance_figure(result.log, plan, mission.sim.obstacles, rp.event_list, out,
                                               plan.grid)
                    if f is not None:
                        figures.append(f)
            except ImportError:
                figures = None
    total = time.monotonic() - t_start
    tr = rep.tracking
    mm = (lambda x: "n/a" if x is None else f"{x * 1000:.2f} mm")
    rows = [
        ("mission", f"{mission.name} ({len(plan.waypoints.t_s)} way-points)"),
        ("control", rep.control),
        ("completed", "yes" if rep.completed else f"NO ({rep.error or rep.phase})"),
        ("trajectory", f"{rep.trajectory_duration_s:.1f} s, coverage {plan.stats.coverage_fraction:.0%}"),
        ("vehicle time flown", f"{rep.sim_time_s:.1f} s ({rep.n_frames} frames)"),
        ("max error (after settle)", mm(tr.max_error_m)),
        ("rms error (after settle)", mm(tr.rms_error_m)),
        ("truth source", tr.truth_source),
        ("replanning", _replanning_row(rep.replanning)),
        ("planning", f"{t_planned - t_start:.2f} s"),
        ("flight wall time", f"{rep.wall_time_s:.2f} s ({rep.real_time_factor or 0:.1f}x real time)"),
        ("demo wall time", f"{total:.2f} s"),
    ]
    print(_table(rows))
    files = ["plan.json", "flight.tlog", "report.json"] + [Path(f).name for f in (figures or [])]
    print(f"wrote {out}/: {', '.join(files)}" + ("" if figures is not None else
                                                 " (figures skipped: install the plot extra)"))
    if not rep.completed:
        print(f"companion demo: NOT completed: {rep.error or rep.phase}", file=sys.stderr)
    return 0 if rep.completed else EXIT_FAILED
