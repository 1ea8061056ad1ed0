"""``companion demo [--mission NAME|PATH | --scenario FILE] [--control companion|rates|vehicle] [--out out/] [--seed N]``.

No arguments needed: starts the bundled SITL (``python -m sitl``, a separate
process, lockstep, loopback UDP on a free port; ``--transport inproc``: in
this process, the same MAVLink bytes through memory, ``mavcore.link.pipe``), plans the bundled
``flat-rectangle`` mission, flies it with the geometric controller, prints a
summary table and writes ``out/``: ``plan.json``, ``flight.tlog``,
``report.json``, ``map.html`` (the plan and the flown track on a
self-contained map, ``companion.html_map``) and, with matplotlib (the
``plot`` extra), the paper's Figs. 14-18 style figures (``companion.flight_plot``).

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

from mavcore.errors import InputError

from ..bundled import resolve_mission

DEFAULT_MISSION = "flat-rectangle"
#: How the companion reaches the bundled SITL (``--transport``).
TRANSPORTS = ("udp", "inproc")


def add_arguments(parser) -> None:
    parser.add_argument("--mission", default=None, metavar="NAME|PATH",
                        help=f"bundled mission name or mission YAML (default {DEFAULT_MISSION})")
    parser.add_argument("--scenario", default=None, metavar="FILE",
                        help="a campaign's scenario file: base mission + overrides + seed + cut + control")
    parser.add_argument("--control", choices=("companion", "rates", "vehicle"), default=None,
                        help="who tracks the trajectory (default companion: the geometric controller; rates: its "
                             "outer part, through the vehicle's rate loop)")
    parser.add_argument("--autopilot", choices=("px4", "ardupilot"), default=None,
                        help="flight stack the bundled SITL speaks as; the companion detects it from its "
                             "HEARTBEAT (default: the mission's sim.autopilot, else px4)")
    parser.add_argument("--out", default="out", metavar="DIR", help="output directory (default %(default)s)")
    parser.add_argument("--cut", type=float, default=None, metavar="S",
                        help="fly only the first S seconds of the trajectory")
    parser.add_argument("--seed", type=int, default=None, metavar="N",
                        help="seed of the SITL's noise and wind (default: the mission's sim.seed)")
    parser.add_argument("--signing-key", default=None, metavar="FILE",
                        help="MAVLink 2 signing key file for both the SITL and the companion "
                             "(32 raw bytes, or a passphrase as MAVProxy's signing setup)")
    parser.add_argument("--no-plots", action="store_true", help="skip the figures")
    parser.add_argument("--transport", choices=TRANSPORTS, default="udp",
                        help="udp (default): the SITL in its own process over loopback UDP; inproc: in this "
                             "process, the same MAVLink bytes through memory (same flight, faster)")
    from .fly import add_safety_arguments

    add_safety_arguments(parser)
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress display")


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
    vw = max([32] + [len(v) for _, v in rows])
    line = "+" + "-" * (w + 2) + "+" + "-" * (vw + 2) + "+"
    out = [line]
    for k, v in rows:
        out.append(f"| {k:<{w}} | {v:<{vw}} |")
    out.append(line)
    return "\n".join(out)


def start_sitl(transport: str, mission_path, seed, signing_key_file, autopilot: str | None = None,
               realtime: bool = False):
    """The bundled SITL for ``--transport``, launched with its launch pose to
    come (``set_start``, then ``wait_ready``): ``SitlProcess`` (a subprocess,
    loopback UDP; it imports and loads its world while we plan) or
    ``SitlInProcess`` (this process, ``inproc:``). Lockstep either way, but
    ``realtime`` (a scenario's lossy link): a subprocess at speed 1, no lockstep.
    ``autopilot``: the personality (None: the mission's ``sim.autopilot``)."""
    from sitl.api import SitlInProcess, SitlProcess

    if transport == "inproc" and not realtime:
        return SitlInProcess(mission_path, seed=seed, start="later", signing_key_file=signing_key_file,
                             autopilot=autopilot).launch()
    return SitlProcess(mission_path, lockstep=not realtime, speed=1.0, seed=seed, start="later",
                       signing_key_file=signing_key_file, autopilot=autopilot).launch()


def run(args) -> int:

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
        check_output_paths([("--out", out / n) for n in ("plan.json", "flight.tlog", "report.json", "map.html")
                            + (("mission.yaml",) if scenario is not None else ())])
    key = None
    if args.signing_key is not None:
        from mavcore.link.signing import load_signing_key
        key = load_signing_key(args.signing_key)
    from mavcore.mission import load_mission
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
    link = scenario.link if scenario is not None else None
    sitl = start_sitl(getattr(args, "transport", "udp"), mission_path, args.seed, args.signing_key,
                      getattr(args, "autopilot", None), realtime=link is not None)
    try:
        return _plan_and_fly(args, mission, out, sitl, t_start, key, overrides, link)
    finally:
        sitl.stop()


def _plan_and_fly(args, mission, out, sitl, t_start, signing_key=None, overrides=None, link=None) -> int:
    from ..plan_io import plan_json_text, plan_to_json_dict
    from ..progress import Progress
    from ..report import write_report_or_fallback
    from ..runner import UNUSED_STREAMS
    from ..summary import control_text, coverage_text, failure_lines, outcome_text
    from .fly import EXIT_FAILED, execute
    from ..flight_plan import FlightPlan

    ATTITUDE = 30   # MAVLINK_MSG_ID_ATTITUDE: the SITL's ground-truth ODOMETRY carries the attitude

    from ..planner import plan_mission

    plan = plan_mission(mission)
    plan_text = plan_json_text(plan_to_json_dict(plan, mission), time.perf_counter())
    t_planned = time.monotonic()
    out.mkdir(parents=True, exist_ok=True)
    (out / "plan.json").write_text(plan_text, encoding="utf-8")

    fp = FlightPlan.from_plan(plan)
    progress = Progress(enabled=not args.quiet)
    # The vehicle starts where a user would set it down: under the first
    # way-point, facing the first pointing direction (take-off = climb + hold).
    # The SITL runs at speed 1 until the companion engages lockstep (the
    # vehicle clock barely moves while the link comes up), then flat out.
    # A mission's sim.start_enu_m (a campaign's start point) moves the launch
    # point; the take-off then climbs and transfers level to the first point.
    pose = launch_pose(plan.trajectory, plan.target_enu_m)
    if mission.sim.start_enu_m is not None:
        pose = (float(mission.sim.start_enu_m[0]), float(mission.sim.start_enu_m[1]), pose[2])
    sitl.set_start(pose)
    sitl.wait_ready()
    relay = None
    url = sitl.url
    try:
        if link is not None:   # a scenario's lossy, jittery link: a relay between us and the SITL
            from sitl.relay import UdpRelay

            host, port = sitl.url.split(":")[1:]
            relay = UdpRelay((host, int(port)), loss=link.loss, delay_min_s=link.delay_ms[0] / 1000,
                             delay_max_s=link.delay_ms[1] / 1000, seed=int(args.seed or 0)).start()
            url = f"udpout:127.0.0.1:{relay.port}"
        result = execute(mission, fp, url, args.control, str(out / "flight.tlog"), progress, args.cut,
                         {"mute_streams": UNUSED_STREAMS + (() if mission.replan.enabled else (ATTITUDE,)),
                          **(overrides or {})},
                         signing_key=signing_key, report_path=str(out / "report.json"),
                         option_names=("--out", "--out"), sensor_gap=args.sensor_gap)
    finally:
        if relay is not None:
            relay.stop()
        sitl.stop()
    written = write_report_or_fallback(result.report, out / "report.json")
    rep = written.report
    if written.fallback:
        where = f"written to {written.path} instead" if written.path is not None else "not written"
        print(f"companion demo: {written.error}; report {where}", file=sys.stderr)
    t_flown = time.monotonic()

    figures = []
    if not args.no_plots:
        try:
            from ..flight_plot import write_flight_figures
        except ImportError:   # matplotlib missing: the plot extra is optional here
            figures = None
        else:
            try:
                figures = write_flight_figures(result.log, plan, out, obstacles=mission.sim.obstacles)
                rp = rep.replanning
                if mission.sim.obstacles or rp.events:
                    from ..flight_plot import write_avoidance_figure

                    f = write_avoidance_figure(result.log, plan, mission.sim.obstacles, rp.event_list, out,
                                               plan.grid)
                    if f is not None:
                        figures.append(f)
            except ImportError:
                figures = None
    from ..html_map import html_map_text
    from ..map_layers import flown_track, plan_layers, with_flight

    layers = with_flight(plan_layers(plan, mission), flown_track(result.log), mission.sim.obstacles)
    (out / "map.html").write_text(html_map_text(layers, f"{mission.name}: flight"), encoding="utf-8")
    total = time.monotonic() - t_start
    tr = rep.tracking
    mm = (lambda x: "n/a" if x is None else f"{x * 1000:.2f} mm")
    rows = [
        ("mission", f"{mission.name} ({len(plan.waypoints.t_s)} way-points)"),
        ("control", control_text(rep)),
        ("completed", "yes" if rep.completed else f"NO ({outcome_text(rep)})"),
        ("trajectory", f"{rep.trajectory_duration_s:.1f} s"),
        ("coverage", coverage_text(rep.coverage_fraction, rep.planned_coverage_fraction).removeprefix("coverage ")),
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
    files = ["plan.json", "flight.tlog", "report.json", "map.html"] + [Path(f).name for f in (figures or [])]
    print(f"wrote {out}/: {', '.join(files)}" + ("" if figures is not None else
                                                 " (figures skipped: install the plot extra)"))
    for line in failure_lines(rep):
        print(f"companion demo: {line}", file=sys.stderr)
    return 0 if rep.completed else EXIT_FAILED
