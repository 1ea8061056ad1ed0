"""``companion fly MISSION.yaml [--plan plan.json] [--connect udpin:127.0.0.1:14540]
[--control companion|rates|vehicle] [--tlog flight.tlog] [--report report.json]``.

Flies a planned mission against a MAVLink vehicle (the bundled SITL or a
flight stack); see ``companion.runner`` for the sequence.

The connection string is from the companion's point of view. PX4's port
convention (``--ports px4``, the default, as ``sitl``'s): the vehicle sends
to the companion's port 14540, so the companion listens,
``udpin:127.0.0.1:14540`` (``udpin:0.0.0.0:14540`` for a vehicle on
another machine). The legacy convention (``--ports legacy``, ``sitl --ports
legacy``): the SITL listens on 14540 and the companion sends first,
``udpout:127.0.0.1:14540``.

Without ``--plan`` the mission is planned here (as ``companion plan``); with
it, the trajectory is rebuilt from the plan's way-points with the mission's
trajectory weights (the LQR solution is exact, so it is the same trajectory).
``--sortie N`` flies sortie N of the plan (``companion.sorties``: from the
launch point through its transit, its corridors, and back) instead of the
whole route; the runner flies it like any trajectory.
Exit code 0 when the flight completed (every check of
``companion.flight.monitor`` held: armed, airborne, in our mode, no crash,
error within ``--max-error``; landed and disarmed; the .tlog and the report
written), 3 when it did not (the report's ``violation`` says why, and what
was flown), 2 on bad input (checked before anything is flown or written:
outputs included, ``check_output_paths``, ``check_free_space`` and
``check_writable``).

An output that fails in flight (the .tlog: ENOSPC, EIO, deleted, replaced,
not growing) is a fault like a lost link: the vehicle lands (or holds,
``--on-failure``), and the report says so (``faults``). A report that cannot
be written where asked goes to the temporary directory, named on stderr and
in the report (``report_fallback``); exit code 3 either way.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
from pathlib import Path

from mavcore.errors import InputError

from ..assembly import build_flight_core
from ..flight_plan import FlightPlan, sensor_coverage_gate, slowed_mission, sortie_flight_plan

#: The companion's side of each port convention (``--ports``; ``sitl --ports``):
#: PX4's (the vehicle sends to the companion's port 14540) and the legacy one
#: (the bundled SITL listened on 14540 and the companion sent first).
CONNECT_BY_PORTS = {"px4": "udpin:127.0.0.1:14540", "legacy": "udpout:127.0.0.1:14540"}
DEFAULT_CONNECT = CONNECT_BY_PORTS["px4"]


#: Bytes a second of flight that a .tlog takes, rounded up from recordings of
#: the bundled SITL (BENCHMARKS.md "h19-inflight": 61 kB/s vehicle control,
#: 125 kB/s companion control, 173 kB/s with the rangefinders of replanning).
TLOG_BYTES_PER_S = 200_000
#: Vehicle seconds a flight takes besides its trajectory (take-off, hold,
#: hover, landing), for the free-space estimate.
FLIGHT_OVERHEAD_S = 120.0
#: Room kept for report.json and the file system's own blocks.
REPORT_RESERVE_BYTES = 1 << 20


def _name_max(directory: Path) -> int:
    try:
        return int(os.pathconf(directory, "PC_NAME_MAX"))
    except (OSError, ValueError, AttributeError):
        return 255


def _path_max(directory: Path) -> int:
    try:
        return int(os.pathconf(directory, "PC_PATH_MAX"))
    except (OSError, ValueError, AttributeError):
        return 4096


def check_output_paths(outputs) -> None:
    """Fail before any work when an output cannot be written where asked.

    Parameters
    ----------
    outputs : iterable of (option, path)
        E.g. ``(("--tlog", "flight.tlog"), ("--report", "report.json"))``.

    Raises
    ------
    InputError
        A path is a directory or another non-regular file, its directory does
        not exist, its name (or the report's temporary sibling,
        ``companion.report.temp_name``) is longer than the file system
        allows, or two options name the same file (one line naming the
        option and path). Whether the directory is writable is tried later,
        when all input is known good (``check_writable``): trying changes it.
    """
    from ..report import temp_name

    seen = {}
    for opt, path in outputs:
        p = Path(path)
        shown = f"{opt} {str(path)[:60]}{'...' if len(str(path)) > 60 else ''}"
        # names first: a too-long name fails every other question with ENAMETOOLONG
        try:
            parent_ok = p.parent.is_dir()
        except OSError:          # the directory's own name too long
            parent_ok = False
        limit = _name_max(p.parent) if parent_ok else 255
        for name in (p.name, temp_name(p).name):
            n = len(os.fsencode(name))
            if n > limit:
                raise InputError(shown, f"file name of {n} bytes is longer than the {limit} the file system allows")
        full = len(os.fsencode(os.path.abspath(p)))
        if full >= _path_max(p.parent if parent_ok else Path(".")):
            raise InputError(shown, f"path of {full} bytes is too long")
        try:
            if p.is_dir():
                raise InputError(f"{opt} {path}", "is a directory (give a file name)")
            if not p.parent.is_dir():
                raise InputError(f"{opt} {path}", f"directory {p.parent} does not exist")
            if p.exists() and not p.is_file():
                raise InputError(f"{opt} {path}", "exists and is not a regular file")
        except OSError as exc:
            raise InputError(shown, f"cannot be used: {exc.strerror or exc}") from None
        key = os.path.abspath(p)
        if key in seen:
            raise InputError(f"{opt} {path}", f"is also given as {seen[key]}")
        seen[key] = opt


def check_writable(outputs) -> None:
    """Fail before arming when an output's directory is not writable: a temporary
    file is created there and removed (permissions, a read-only mount, ACLs and
    quotas all answer; ``os.access`` would not see most of them).

    Parameters
    ----------
    outputs : iterable of (option, path)

    Raises
    ------
    InputError
        One line naming the option, the directory and the system's error.
    """
    import tempfile

    probed = set()
    for opt, path in outputs:
        d = os.path.abspath(Path(path).parent)
        if d in probed:
            continue
        try:
            fd, probe = tempfile.mkstemp(prefix=".cmp-", suffix=".probe", dir=d)
            os.close(fd)
            os.unlink(probe)
        except OSError as exc:
            raise InputError(f"{opt} {path}", f"directory {Path(path).parent} is not writable: "
                                              f"{exc.strerror or exc}") from None
        probed.add(d)


def expected_tlog_bytes(trajectory_duration_s: float) -> int:
    """Expected .tlog size (bytes) of a flight whose trajectory lasts
    ``trajectory_duration_s``: (trajectory + ``FLIGHT_OVERHEAD_S``) x ``TLOG_BYTES_PER_S``."""
    return int(math.ceil((max(0.0, trajectory_duration_s) + FLIGHT_OVERHEAD_S) * TLOG_BYTES_PER_S))


def check_free_space(outputs, statvfs=os.statvfs) -> None:
    """Fail before arming when a file system cannot hold what the flight will write.

    Parameters
    ----------
    outputs : iterable of (option, path, bytes)
        Each output and the bytes it is expected to take; outputs on one
        file system (``st_dev`` of the directory) add up.
    statvfs : callable
        ``os.statvfs`` (tests pass a fake one).

    Raises
    ------
    InputError
        One line naming the option, the bytes needed and the bytes free.
    """
    need: dict = {}
    for opt, path, nbytes in outputs:
        d = os.path.abspath(Path(path).parent)
        try:
            dev = os.stat(d).st_dev
        except OSError:
            dev = d
        first, total, _ = need.get(dev, ((opt, path, d), 0, None))
        need[dev] = (first, total + int(nbytes), None)
    for (opt, path, d), total, _ in need.values():
        try:
            st = statvfs(d)
        except OSError:
            continue            # nothing to go on (the write itself is guarded in flight)
        free = st.f_bavail * st.f_frsize
        if free < total:
            raise InputError(f"{opt} {path}", f"not enough free space in {d}: the flight needs about "
                                              f"{total / 1e6:.1f} MB, {free / 1e6:.1f} MB free")


def add_arguments(parser) -> None:
    parser.add_argument("mission", help="mission YAML file")
    parser.add_argument("--plan", metavar="PLAN.json", help="plan.json from `companion plan` (default: plan now)")
    parser.add_argument("--connect", default=None, metavar="URL",
                        help=f"pymavlink connection string, companion side (default: the --ports convention's, "
                             f"{DEFAULT_CONNECT}: PX4's, where the vehicle sends to the companion)")
    parser.add_argument("--ports", choices=tuple(CONNECT_BY_PORTS), default="px4",
                        help="port convention of the default --connect: px4 (default) or legacy "
                             f"({CONNECT_BY_PORTS['legacy']}, for `sitl --ports legacy`)")
    parser.add_argument("--control", choices=("companion", "rates", "vehicle"), default="companion",
                        help="companion: geometric controller answers every sensor frame with "
                             "HIL_ACTUATOR_CONTROLS; rates: with body rates and thrust (SET_ATTITUDE_TARGET, "
                             "the vehicle's rate loop flies); vehicle: setpoints only (default %(default)s)")
    parser.add_argument("--tlog", default="flight.tlog", metavar="FILE", help="telemetry log (default %(default)s)")
    parser.add_argument("--report", default="report.json", metavar="FILE", help="flight report (default %(default)s)")
    parser.add_argument("--cut", type=float, default=None, metavar="S",
                        help="fly only the way-points up to S seconds into the trajectory, the last one made a stop "
                             "(the trajectory is re-solved so it ends at rest)")
    parser.add_argument("--sortie", type=int, default=None, metavar="N",
                        help="fly only sortie N (1-based) of the plan: from the launch point, its corridors, "
                             "back to the launch point")
    parser.add_argument("--signing-key", default=None, metavar="FILE",
                        help="MAVLink 2 signing key file (32 raw bytes, or a passphrase hashed with SHA-256 as "
                             "MAVProxy's signing setup): sign everything, accept only signed vehicle messages")
    add_safety_arguments(parser)
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress display")


def add_safety_arguments(parser) -> None:
    """Flags shared by ``fly`` and ``demo``: what counts as a completed flight and what to do otherwise."""
    parser.add_argument("--max-error", type=float, default=0.5, metavar="M",
                        help="tracking error bound (m) of a completed flight; beyond it the flight is stopped "
                             "(default %(default)s)")
    parser.add_argument("--on-failure", choices=("land", "hold"), default="land",
                        help="when a flight must stop early (violation, SIGINT/SIGTERM): land, or hold "
                             "(AUTO.LOITER) and let go (default %(default)s)")
    parser.add_argument("--attach", choices=("refuse", "resume", "land"), default="refuse",
                        help="a vehicle already flying at connection: refuse, resume the trajectory from "
                             "the nearest way-point, or land it (default %(default)s)")
    parser.add_argument("--check-params", action="store_true",
                        help="at set-up, read the flight stack's offboard/guided loss parameters and warn of values "
                             "outside what a flight needs (docs/flying-a-real-vehicle.md#parameters-to-set)")
    parser.add_argument("--sensor-gap", choices=("refuse", "slow"), default="refuse",
                        help="where the rangefinders do not see the direction of travel far enough to stop "
                             "(docs/replan.md#sensor-coverage): refuse the flight, or fly the whole plan slower "
                             "(a direction no rangefinder sees is refused either way; default %(default)s)")


def safety_overrides(args) -> dict:
    """RunnerConfig keys from ``add_safety_arguments``'s flags (InputError on a bad value)."""
    import math

    if not (math.isfinite(args.max_error) and args.max_error > 0):
        raise InputError(f"--max-error {args.max_error}", "must be a finite number > 0 (metres)")
    out = {"max_tracking_error_m": float(args.max_error), "on_failure": args.on_failure, "attach": args.attach}
    if getattr(args, "check_params", False):
        out["check_params"] = True      # absent otherwise: the setup record stays as before
    return out


def _pick_sortie(count: int, sortie: int, source: str) -> int:
    if not 1 <= sortie <= count:
        raise InputError("--sortie", f"{sortie} is not a sortie of {source} (it has {count})")
    return sortie - 1


class MissionMaps:
    """The mission's (grid, dem), read from disk (``load_mission_maps``) on the
    first ``get`` only: ``prepare``'s preflight check and ``execute`` share one
    reading (a 10 ha map costs ~0.2 s of CPU and ~45 MB a reading)."""

    def __init__(self, mission):
        self._mission = mission
        self._maps = None

    def get(self):
        """(OccupancyGrid, ElevationModel); MapError if unreadable."""
        if self._maps is None:
            from mavcore.maps.field import load_mission_maps

            self._maps = load_mission_maps(self._mission)
        return self._maps

    def seed(self, grid, dem) -> None:
        """Take maps already read from the mission's files (the planner's)."""
        self._maps = (grid, dem)


def prepare(mission, plan_path: str | None, sortie: int | None = None,
            maps: MissionMaps | None = None) -> FlightPlan:
    """Plan ``mission`` or rebuild the trajectory of ``plan_path``; ``sortie`` (1-based)
    picks one sortie of the plan instead of the whole route. ``maps``: where the
    mission's maps are read once (``MissionMaps``), shared with ``execute``.

    Raises
    ------
    PlanError, MapError
        Bad plan file or maps (one-line InputError).
    InputError
        ``--sortie`` is not a sortie of the plan.
    """
    import numpy as np

    if plan_path is None:
        from ..planner import plan_mission

        plan = plan_mission(mission)
        if maps is not None:
            maps.seed(plan.grid, plan.dem)
        if sortie is None:
            return FlightPlan.from_plan(plan, f"{mission.source} (planned)")
        so = plan.sorties.sorties[_pick_sortie(len(plan.sorties.sorties), sortie, mission.name)]
        w = so.waypoints
        return sortie_flight_plan(w.t_s, w.p_enu_m, w.v_enu_m_s, w.a_enu_m_s2, plan.target_enu_m,
                                  mission.trajectory, so.path_xy_m, w.corner,
                                  source=f"{mission.source} (planned) --sortie {sortie}")
    from ..plan_io import load_plan

    # a sortie is solved through its own way-points: the whole route's pieces are checked, not rebuilt
    pf = load_plan(plan_path, rebuild_trajectory=sortie is None)
    # the document's tree of Python objects (~60 MB for a 10 ha plan) is not needed
    # past the loader's arrays: freed before the maps are read on top of it
    pf = dataclasses.replace(pf, data={})
    from ..memory import release_freed_memory

    release_freed_memory()
    from ..preflight import check_plan
    grid, dem = (maps or MissionMaps(mission)).get()
    check_plan(pf, mission, grid, dem)    # whole plan and every sortie: on the map, above the terrain, for this field
    del grid, dem
    target = pf.target_enu_m
    if target is None:
        # A plan.json without ``target_enu_m`` (the loader does not require
        # it, docs/plan-json.md): S_p is where the pointing rays of eq. (21) meet.
        target = pointing_target_from_rays(pf.p_enu_m, pf.pointing_enu, str(plan_path))
    if sortie is not None:
        so = pf.sorties[_pick_sortie(len(pf.sorties), sortie, str(plan_path))]
        fp = sortie_flight_plan(so["waypoint_t_s"], so["waypoint_p_enu_m"], so["waypoint_v_enu_m_s"],
                                so["waypoint_a_enu_m_s2"], target, mission.trajectory,
                                source=f"{plan_path} --sortie {sortie}")
        return dataclasses.replace(fp, plan_sha256_hex=pf.sha256_hex)
    traj = pf.trajectory
    if traj is None:
        # a 1.x plan stores samples only: the LQR solution through its way-points is exact
        from ..trajectory import generate_trajectory     # scipy.linalg: only for these plans

        traj = generate_trajectory(pf.waypoint_t_s, pf.waypoint_p_enu_m, pf.waypoint_v_enu_m_s,
                                   pf.waypoint_a_enu_m_s2, mission.trajectory, target_enu_m=target)
    cov = pf.stats.get("coverage_fraction")
    return FlightPlan(traj, pf.waypoint_p_enu_m, np.asarray(target, dtype=float),
                      None if cov is None else float(cov), pf.waypoint_t_s, pf.waypoint_v_enu_m_s,
                      pf.waypoint_a_enu_m_s2, pf.path_xy_m if len(pf.path_xy_m) else None, pf.waypoint_corner,
                      source=str(plan_path), plan_sha256_hex=pf.sha256_hex)


def pointing_target_from_rays(p_enu_m, s_enu, source: str) -> np.ndarray:
    """S_p (ENU m, (3,)) from sampled positions and pointing directions.

    Eq. (21) makes every s(t) point from x_d(t) at S_p, so S_p is the point
    nearest to all the rays in the least-squares sense:
    sum_k (I - s_k s_k^T) S_p = sum_k (I - s_k s_k^T) p_k.

    Raises
    ------
    PlanError
        The rays are (nearly) parallel, so they do not fix a point.
    """
    import numpy as np

    from mavcore.errors import PlanError

    p = np.asarray(p_enu_m, dtype=float)
    s = np.asarray(s_enu, dtype=float)
    s = s / np.linalg.norm(s, axis=1, keepdims=True)
    M = np.eye(3)[None] - s[:, :, None] * s[:, None, :]       # projectors normal to each ray
    A = M.sum(axis=0)
    b = np.einsum("kij,kj->i", M, p)
    if np.linalg.cond(A) > 1e8:
        raise PlanError(source, "no target_enu_m and the pointing directions do not meet at a point")
    return np.linalg.solve(A, b)


def open_link(connect: str, tlog_path: str | None, signing_key: bytes | None = None):
    """The vehicle link, opened (the tlog not yet: ``execute`` creates it).

    Raises
    ------
    InputError
        Unknown host, port in use, connection refused: one line, nothing written.
    """
    from ..link import Connection, TlogWriter

    tlog = TlogWriter(tlog_path) if tlog_path else None
    return Connection(connect, tlog=tlog, signing_key=signing_key).open()


def flight_setup(mission, plan_path: str | None, control: str, cut_s: float | None, overrides: dict,
                 sensor_gap: str = "refuse", plan_sha256_hex: str | None = None) -> dict:
    """The flight's setup record (``companion.flight.setup_record``): what ``companion replay``
    needs to rebuild this flight from its .tlog and the same mission (and plan) files, and the
    numeric environment it ran in (``companion.flight.environment``: bit-for-bit replay is
    promised only in the same one). ``plan_sha256_hex``: the SHA-256 of the plan bytes the
    flight was prepared from (``PlanFile.sha256_hex``), else the file at ``plan_path`` is read."""
    import hashlib

    from .. import __version__
    from ..flight.environment import fingerprint

    def digest(path) -> str | None:
        if path is None:
            return None
        try:
            return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]
        except OSError:
            return None

    return {
        "format": "companion-setup/1",
        "version": __version__,
        "mission": mission.name,
        "mission_sha": digest(mission.source),
        "map_sha": digest(mission.map_path if mission.map is not None else mission.field_path),
        "dem_sha": digest(mission.dem_path),
        "plan_sha": (plan_sha256_hex[:16] if plan_sha256_hex else digest(plan_path)) if plan_path else None,
        "control": control,
        "cut_s": cut_s,
        "runner": {k: (list(v) if isinstance(v, tuple) else v) for k, v in sorted(overrides.items())},
        "sensor_gap": sensor_gap,
        "environment": fingerprint(),
    }


def execute(mission, flight_plan: FlightPlan, connect: str, control: str, tlog_path: str | None,
            progress=None, cut_s: float | None = None, runner_overrides: dict | None = None,
            plan_path: str | None = None, signing_key: bytes | None = None, conn=None,
            report_path: str | None = None, option_names=("--tlog", "--report"),
            maps: MissionMaps | None = None, sensor_gap: str = "refuse"):
    """Open the link (unless ``conn``, from ``open_link``, is given), fly, close.
    Returns ``companion.runner.FlightResult``. ``maps``: the mission's maps as
    ``prepare`` read them (``MissionMaps``), else read here.

    The link is opened before the tlog is created: a link that cannot be
    opened (unknown host, port in use, refused) is bad input and leaves no
    file behind. What is flown (the plan, a sortie, a cut and its re-solved
    trajectory) passes ``companion.preflight.check_flight_plan`` first
    (``PlanError``: nothing has been sent). Then the file systems of
    ``tlog_path`` and ``report_path`` must hold the flight's expected .tlog
    (``check_free_space``; InputError otherwise).
    """
    from ..preflight import check_flight_plan
    from ..runner import MissionRunner, RunnerConfig

    plan_sha = flight_plan.plan_sha256_hex   # of the plan file read (taken before a cut re-solves the plan)
    try:
        if cut_s is not None:
            flight_plan = flight_plan.cut(cut_s, mission.trajectory)
        maps = (maps or MissionMaps(mission)).get()
        check_flight_plan(flight_plan.source or str(plan_path or mission.source), flight_plan, mission, *maps)
        flight_plan, coverage_doc = sensor_coverage_gate(mission, flight_plan, sensor_gap, maps[1])
        mission = slowed_mission(mission, coverage_doc["time_scale"])
        traj = flight_plan.trajectory
        outputs = []
        if tlog_path:
            outputs.append((option_names[0], tlog_path, expected_tlog_bytes(float(traj.tf - traj.t0))))
        if report_path:
            outputs.append((option_names[1], report_path, REPORT_RESERVE_BYTES))
        check_free_space(outputs)
        check_writable([o[:2] for o in outputs])
        cfg = RunnerConfig(control=control, **(runner_overrides or {}))
        core = build_flight_core(mission, flight_plan, cfg,
                                 flight_setup(mission, plan_path, control, cut_s, runner_overrides or {}, sensor_gap,
                                              plan_sha),
                                 maps)
        core.sensor_coverage = coverage_doc
    except BaseException:
        if conn is not None:
            conn.close()
        raise
    from ..memory import release_freed_memory

    release_freed_memory()   # the planner's peak is not held through the flight
    if conn is None:
        conn = open_link(connect, tlog_path, signing_key)
    tlog = conn.tlog
    try:
        if tlog is not None:
            try:
                tlog.open()
            except OSError as exc:
                raise InputError(str(tlog_path), f"cannot write: {exc.strerror or exc}") from None
        return MissionRunner(conn, core, progress).run()
    finally:
        conn.close()
        if tlog is not None:
            tlog.close()


def run(args) -> int:
    from ..link import check_connection_string
    from mavcore.mission import load_mission
    from ..progress import Progress

    if args.connect is None:
        args.connect = CONNECT_BY_PORTS[args.ports]
    check_connection_string(args.connect)
    if args.cut is not None and not (math.isfinite(args.cut) and args.cut > 0):
        raise InputError(f"--cut {args.cut}", "must be a finite number of seconds > 0")
    check_output_paths((("--tlog", args.tlog), ("--report", args.report)))
    key = None
    if args.signing_key is not None:
        from mavcore.link.signing import load_signing_key
        key = load_signing_key(args.signing_key)
    overrides = safety_overrides(args)
    if args.sortie is not None and args.sortie < 1:
        raise InputError("--sortie", f"sorties are numbered from 1, got {args.sortie}")
    from ..long_lived import imports_kept

    with imports_kept(args.process_exits):
        # The flight's modules, imported together: kept out of the collector's passes (the
        # two collections of ``release_freed_memory`` before the flight walk only what the
        # flight's preparation made; the runner freezes that too when it starts).
        from .. import assembly, plan_io, preflight, runner  # noqa: F401
        from ..flight import environment  # noqa: F401
        from ..replan import coverage_check  # noqa: F401
        from ..trajectory import extrema  # noqa: F401
        from mavcore.maps import field  # noqa: F401
    mission = load_mission(args.mission)
    # The link first: a bad --connect (unknown host, port in use, refused) fails before any planning.
    conn = open_link(args.connect, args.tlog, key)
    try:
        maps = MissionMaps(mission)
        fp = prepare(mission, args.plan, args.sortie, maps)
    except BaseException:
        conn.close()
        raise
    progress = Progress(enabled=not args.quiet)
    result = execute(mission, fp, args.connect, args.control, args.tlog, progress, args.cut, overrides,
                     args.plan, conn=conn, report_path=args.report, maps=maps,
                     sensor_gap=args.sensor_gap)
    return finish_report(result.report, args.report, "companion fly")


def finish_report(rep, report_path, prog: str) -> int:
    """Write the report (``write_report_or_fallback``: the configured path, else
    the temporary directory, named on stderr), print the summary rendered
    from it (``companion.summary``) and return the exit code."""
    from ..report import write_report_or_fallback
    from ..summary import control_text, coverage_text, failure_lines, outcome_text

    written = write_report_or_fallback(rep, report_path)
    rep = written.report
    if written.fallback:
        where = (f"written to {written.path} instead" if written.path is not None
                 else "not written anywhere; it follows on stdout")
        print(f"{prog}: {written.error}; report {where}", file=sys.stderr)
        if written.path is None:
            import json
            print(json.dumps(rep.to_dict()))
    tr = rep.tracking
    err = "n/a" if tr.max_error_m is None else f"max {tr.max_error_m * 1000:.2f} mm, rms {tr.rms_error_m * 1000:.2f} mm"
    print(f"{prog}: {outcome_text(rep)} ({control_text(rep)}), "
          f"{rep.sim_time_s:.1f} s flown in {rep.wall_time_s:.1f} s wall, "
          f"{coverage_text(rep.coverage_fraction, rep.planned_coverage_fraction)}, tracking {err} "
          f"({tr.truth_source}); report {written.path if written.path is not None else '(stdout)'}")
    rp = rep.replanning
    if rp.enabled and rp.events:
        clr = "" if rp.min_clearance_m is None else f", min clearance {rp.min_clearance_m:.2f} m (sim truth)"
        print(f"{prog}: replanning: {rp.events} events ({', '.join(rp.actions)}){clr}")
    for line in failure_lines(rep):
        print(f"{prog}: {line}", file=sys.stderr)
    return 0 if rep.completed else EXIT_FAILED


#: Exit code of a flight that did not complete (2 is bad input).
EXIT_FAILED = 3
