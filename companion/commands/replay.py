"""``companion replay FLIGHT.tlog [--mission MISSION.yaml] [--plan plan.json]
[--report replay.json] [--plot DIR] [--tolerance ABS | --exact] [--withhold TYPE,...]``.

Without ``--mission``: the flight's metrics from the recording alone (any
MAVLink .tlog, a foreign one included; see ``companion.replay.metrics``).
With it: the recorded flight's ``FlightCore`` is rebuilt from the setup
record in the .tlog, the mission (and ``--plan`` when the flight flew one),
fed the recorded vehicle messages in order, and every output it queues is
compared with the recorded one (``companion.replay.session``).

Exit codes: 0 metrics only, or every output identical: float32 fields bit
for bit when this environment is the recording's (``--exact``: always),
within float64 drift when it differs or is unknown (discrete fields exact;
``companion.replay.compare``), within ``--tolerance`` when given; 4 the outputs diverged (the first
divergence is named: vehicle time, message, field, recorded and computed
values); 2 bad input (one line, nothing written). A damaged .tlog is replayed
as far as it is valid: what was skipped, and where, is printed and reported.
A .tlog compressed with xz or gzip is read as is.
"""

from __future__ import annotations

import gzip
import lzma
import math
import sys
from pathlib import Path

from mavcore.errors import InputError
from mavcore.inputs import Limits, check, clip, limits, name, open_regular

#: Exit code of a replay whose outputs differ from the recording.
EXIT_DIVERGED = 4
CHUNK_BYTES = 1 << 20
REPORT_FORMAT = "companion-replay"
REPORT_FORMAT_VERSION = "1.0"


def add_arguments(parser) -> None:
    parser.add_argument("tlog", metavar="FLIGHT.tlog", help="recorded flight (.tlog, optionally .xz/.gz)")
    parser.add_argument("--mission", metavar="MISSION.yaml",
                        help="the flight's mission: re-run the companion and compare every output")
    parser.add_argument("--plan", metavar="PLAN.json", help="the plan.json the flight flew (with --mission)")
    parser.add_argument("--report", metavar="FILE", help="write the replay report (JSON)")
    parser.add_argument("--plot", metavar="DIR", help="write the flight figures into DIR (needs the plot extra)")
    parser.add_argument("--tolerance", type=float, default=0.0, metavar="ABS",
                        help="absolute tolerance on float fields (default 0: bit for bit in the recording's "
                             "environment, float64 drift in another)")
    parser.add_argument("--exact", action="store_true",
                        help="compare float32 fields bit for bit even when this environment is not the recording's")
    parser.add_argument("--withhold", default="", metavar="TYPE,...",
                        help="vehicle message types not fed to the re-run (e.g. ODOMETRY: outputs must not change)")
    parser.add_argument("--settle", type=float, default=5.0, metavar="S",
                        help="metrics: tracking error counted from S seconds after lift-off (default %(default)s)")


def open_tlog(path: str):
    """The .tlog's bytes as a binary stream (xz and gzip decompressed on the fly): a
    regular file within the ``tlog_bytes`` limit (docs/limits.md)."""
    f = open_regular(path, InputError, ".tlog", cap="tlog_bytes")
    head = f.read(6)
    f.seek(0)
    if head.startswith(b"\xfd7zXZ\x00"):
        return lzma.open(f, "rb")
    if head.startswith(b"\x1f\x8b"):
        return gzip.open(f, "rb")
    return f


def read_chunks(path: str):
    """Generator of the file's bytes in chunks; InputError when it cannot be read or
    decompressed, or decompresses to more than the ``tlog_bytes`` limit."""
    cap = limits().tlog_bytes
    total = 0
    f = open_tlog(path)
    try:
        while True:
            try:
                chunk = f.read(CHUNK_BYTES)
            except (OSError, EOFError, lzma.LZMAError) as exc:
                raise InputError(name(path), f"cannot read: {clip(exc)}") from None
            if not chunk:
                return
            total += len(chunk)
            check(name(path), "the decompressed size", total, "tlog_bytes")
            yield chunk
    finally:
        f.close()


def _garbage(path: str, exc) -> InputError:
    cap = limits().tlog_garbage_bytes
    return InputError(name(path), f"{exc}: above the limit {cap:,} ({Limits.env_name('tlog_garbage_bytes')}); "
                                  "not a .tlog, or one too damaged to replay")


def _withheld_ids(spec: str) -> tuple:
    from pymavlink.dialects.v20 import common as mavlink

    ids = []
    for name in filter(None, (s.strip().upper() for s in spec.split(","))):
        mid = getattr(mavlink, f"MAVLINK_MSG_ID_{name}", None)
        if mid is None:
            raise InputError(f"--withhold {spec}", f"unknown MAVLink message {name!r}")
        ids.append(int(mid))
    return tuple(ids)


def _check_args(args) -> tuple:
    if not (math.isfinite(args.tolerance) and args.tolerance >= 0):
        raise InputError(f"--tolerance {args.tolerance}", "must be a finite number >= 0")
    if getattr(args, "exact", False) and args.tolerance > 0:
        raise InputError("--exact", "cannot be combined with --tolerance")
    if not (math.isfinite(args.settle) and args.settle >= 0):
        raise InputError(f"--settle {args.settle}", "must be a finite number >= 0")
    if args.plan and not args.mission:
        raise InputError("--plan", "needs --mission (the plan is only used to re-run the flight)")
    withhold = _withheld_ids(args.withhold)
    if withhold and not args.mission:
        raise InputError("--withhold", "needs --mission (it changes what the re-run is fed)")
    open_tlog(args.tlog).close()          # a regular file within the size limit, before anything else
    if args.report:
        from .fly import check_output_paths

        check_output_paths((("--report", args.report),))
    if args.plot:
        from ..plot import require_matplotlib

        require_matplotlib("--plot")
        d = Path(args.plot)
        if d.exists() and not d.is_dir():
            raise InputError(f"--plot {args.plot}", "exists and is not a directory")
        if not d.exists() and not d.parent.is_dir():
            raise InputError(f"--plot {args.plot}", f"directory {d.parent} does not exist")
    return withhold


def _rebuild(args):
    """(core, flight plan, warnings) of the recorded flight, from its setup and the given files."""
    from ..link.tlog_scan import TlogGarbage
    from mavcore.mission import load_mission
    from ..replay import build_core, find_setup, setup_mismatches
    from .fly import flight_setup, prepare

    try:
        setup = find_setup(read_chunks(args.tlog), limits().tlog_garbage_bytes)
    except TlogGarbage as exc:
        raise _garbage(args.tlog, exc) from None
    except ValueError as exc:
        raise InputError(args.tlog, f"setup record unreadable: {exc}") from None
    if setup is None:
        raise InputError(args.tlog, "no companion setup record (not written by companion fly/demo): "
                                    "replay it without --mission for its metrics")
    mission = load_mission(args.mission)
    if setup.get("plan_sha") and not args.plan:
        raise InputError("--plan", f"the flight flew a plan file (sha {setup['plan_sha']}): give it with --plan")
    current = flight_setup(mission, args.plan, setup.get("control", "companion"), setup.get("cut_s"),
                           setup.get("runner") or {})
    warnings = setup_mismatches(setup, current)
    fp = prepare(mission, args.plan)
    try:
        core = build_core(setup, mission, fp)
    except ValueError as exc:
        raise InputError(args.tlog, f"setup record: {exc}") from None
    return core, fp, warnings, setup


def _environment(setup) -> list | None:
    """How this environment differs from the recording's (``["unknown"]``: no fingerprint recorded)."""
    from ..flight.environment import differences, fingerprint

    return differences((setup or {}).get("environment"), fingerprint())


def _report_doc(args, result, setup, warnings) -> dict:
    from ..report import _finite

    doc = {
        "format": REPORT_FORMAT,
        "format_version": REPORT_FORMAT_VERSION,
        "tlog": str(args.tlog),
        "mission": args.mission,
        "plan": args.plan,
        "setup": setup,
        "warnings": list(warnings),
        "scan": result.scan.to_dict(),
        "metrics": result.metrics.to_dict(),
        "comparison": None if result.comparison is None else result.comparison.to_dict(),
        "flight": None if result.flight is None else result.flight.to_dict(),
    }
    return _finite(doc)


def _mm(x) -> str:
    return "n/a" if x is None else f"{x * 1000:.2f} mm"


def _print_summary(args, result, warnings) -> None:
    s, m = result.scan, result.metrics
    name = f"companion replay: {args.tlog}"
    print(f"{name}: {s.n_records} records, {s.n_bytes / 1e6:.2f} MB, {m.duration_s:.3f} s of vehicle time "
          f"({m.n_frames} frames; {m.n_vehicle_messages} vehicle and {m.n_companion_messages} companion messages)")
    modes = ", ".join(f"{k} {v:.1f} s" for k, v in m.time_in_mode_s.items()) or "none recorded"
    dist = "n/a" if m.distance_m is None else f"{m.distance_m:.2f} m ({m.horizontal_distance_m:.2f} m horizontal)"
    print(f"  flight time {m.flight_time_s:.2f} s ({m.flight_time_source or 'unknown'}), distance {dist} "
          f"from {m.position_source or 'no position'}; modes: {modes}")
    tr = m.tracking
    if tr.reference_source is None:
        print("  tracking: no reference recorded (no setpoints)")
    else:
        print(f"  tracking vs {tr.reference_source}: max {_mm(tr.max_error_m)}, rms {_mm(tr.rms_error_m)} "
              f"({tr.n_samples} samples from {tr.settle_s:g} s after lift-off; position "
              f"{tr.position_source or 'n/a'}{', ESTIMATED' if tr.estimated else ''})")
    clr = "n/a" if m.min_clearance_m is None else f"{m.min_clearance_m:.2f} m"
    print(f"  min clearance {clr}, replanning events {m.replanning_events}")
    if s.n_regions or s.n_time_jumps:
        where = ", ".join(f"{r.kind} {r.n_bytes} B at byte {r.offset}" for r in s.regions[:5])
        more = "" if s.n_regions <= 5 else f", ... ({s.n_regions} regions)"
        print(f"  skipped: {s.n_skipped_bytes} bytes, {s.n_skipped_packets} packets"
              f"{' (' + where + more + ')' if where else ''}; time stamp jumps: {s.n_time_jumps}")
    for w in warnings:
        print(f"  warning: {w}")
    c = result.comparison
    if c is not None:
        tol = _mode_text(c)
        if c.identical:
            extra = f", {c.n_within_tolerance} within tolerance" if c.n_within_tolerance else ""
            inj = f"; re-injected: {', '.join(c.injected)}" if c.injected else ""
            print(f"  replay: {c.n_compared} outputs identical ({tol}{extra}){inj}")
        else:
            print(f"  replay: DIVERGED ({tol}): {c.n_differing} of {c.n_compared} outputs differ")


def _mode_text(c) -> str:
    """Which comparison was used, and why."""
    if c.mode == "absolute":
        return f"tolerance {c.tolerance:g}"
    if c.mode == "bitwise":
        why = "" if c.environment is None else ": same environment as the recording"
        return f"float32 fields bit for bit{why}"
    env = list(c.environment or ())
    why = ("the recording has no environment fingerprint" if env == ["unknown"]
           else "environment differs from the recording's: " + ", ".join(env[:6]) + (", ..." if len(env) > 6 else ""))
    return f"within float64 drift ({why}); discrete fields exact"


def run(args) -> int:
    withhold = _check_args(args)
    core, fp, warnings, setup = (None, None, [], None)
    if args.mission:
        core, fp, warnings, setup = _rebuild(args)
    from ..link.tlog_scan import TlogGarbage
    from ..replay import replay_chunks

    env = _environment(setup) if core is not None else None
    if getattr(args, "exact", False):
        env = None                  # bit for bit, whatever the environment
    try:
        result = replay_chunks(read_chunks(args.tlog), core, args.tolerance, withhold, args.settle,
                               with_log=bool(args.plot), environment=env,
                               max_garbage_bytes=limits().tlog_garbage_bytes)
    except TlogGarbage as exc:
        raise _garbage(args.tlog, exc) from None
    if result.scan.n_records == 0:
        raise InputError(args.tlog, "no MAVLink records (not a .tlog?)")
    if setup is None:
        setup = result.setup
    _print_summary(args, result, warnings)
    if args.report:
        import json

        from .plan import write_atomically

        doc = _report_doc(args, result, setup, warnings)
        write_atomically({args.report: (json.dumps(doc, indent=2) + "\n").encode("utf-8")})
    if args.plot and result.log is not None:
        from ..flight_plot import write_flight_figures

        Path(args.plot).mkdir(exist_ok=True)
        dem = grid = None
        obstacles = ()
        if args.mission:      # the terrain (heights above ground), the rows and the obstacles
            from mavcore.maps.field import load_mission_maps
            from mavcore.mission import load_mission

            m = load_mission(args.mission)
            grid, dem = load_mission_maps(m)
            obstacles = m.sim.obstacles
        figs = write_flight_figures(result.log, core.inputs if core is not None else None, args.plot,
                                    obstacles=obstacles, dem=dem, grid=grid)
        print(f"  figures: {', '.join(Path(f).name for f in figs) or 'none (no flight rows)'} in {args.plot}")
    c = result.comparison
    if c is not None and not c.identical:
        print(f"companion replay: DIVERGED at {c.first_divergence.describe()}", file=sys.stderr)
        s = result.scan
        if s.n_skipped_packets or s.n_skipped_bytes:
            print(f"companion replay: note: the recording is damaged ({s.n_skipped_packets} packets, "
                  f"{s.n_skipped_bytes} bytes skipped, the first at byte {s.regions[0].offset}): outputs "
                  "after a lost packet cannot match", file=sys.stderr)
        for w in warnings:
            print(f"companion replay: note: {w}", file=sys.stderr)
        return EXIT_DIVERGED
    return 0
