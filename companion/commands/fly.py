"""``companion fly MISSION.yaml [--plan plan.json] [--connect udpout:127.0.0.1:14540]
[--control companion|vehicle] [--tlog flight.tlog] [--report report.json]``.

Flies a planned mission against a MAVLink vehicle (the bundled SITL or a
flight stack); see ``companion.runner`` for the sequence.

The connection string is from the companion's point of view: the bundled
SITL listens with ``udpin:127.0.0.1:14540`` (``sitl MISSION.yaml``'s
default), so the companion's default is ``udpout:127.0.0.1:14540`` (it
sends first). A vehicle that sends to a fixed port instead (PX4 SITL's
onboard link, ``udpout`` on its side) needs ``--connect udpin:0.0.0.0:PORT``.

Without ``--plan`` the mission is planned here (as ``companion plan``); with
it, the trajectory is rebuilt from the plan's way-points with the mission's
trajectory weights (the LQR solution is exact, so it is the same trajectory).
Exit code 0 when the flight completed (landed and disarmed), 1 when it did
not (the report says why), 2 on bad input.
"""

from __future__ import annotations

import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError

DEFAULT_CONNECT = "udpout:127.0.0.1:14540"


def check_output_paths(outputs) -> None:
    """Fail before any work when an output cannot be written where asked.

    Parameters
    ----------
    outputs : iterable of (option, path)
        E.g. ``(("--tlog", "flight.tlog"), ("--report", "report.json"))``.

    Raises
    ------
    InputError
        A path is a directory, its directory does not exist, or two options
        name the same file (one line naming the option and path).
    """
    seen = {}
    for opt, path in outputs:
        p = Path(path)
        if p.is_dir():
            raise InputError(f"{opt} {path}", "is a directory (give a file name)")
        if not p.parent.is_dir():
            raise InputError(f"{opt} {path}", f"directory {p.parent} does not exist")
        key = os.path.abspath(p)
        if key in seen:
            raise InputError(f"{opt} {path}", f"is also given as {seen[key]}")
        seen[key] = opt


def add_arguments(parser) -> None:
    parser.add_argument("mission", help="mission YAML file")
    parser.add_argument("--plan", metavar="PLAN.json", help="plan.json from `companion plan` (default: plan now)")
    parser.add_argument("--connect", default=DEFAULT_CONNECT, metavar="URL",
                        help="pymavlink connection string, companion side (default %(default)s, "
                             "matching `sitl`'s default udpin:127.0.0.1:14540)")
    parser.add_argument("--control", choices=("companion", "vehicle"), default="companion",
                        help="companion: geometric controller answers every sensor frame with "
                             "HIL_ACTUATOR_CONTROLS; vehicle: setpoints only (default %(default)s)")
    parser.add_argument("--tlog", default="flight.tlog", metavar="FILE", help="telemetry log (default %(default)s)")
    parser.add_argument("--report", default="report.json", metavar="FILE", help="flight report (default %(default)s)")
    parser.add_argument("--cut", type=float, default=None, metavar="S",
                        help="fly only the way-points up to S seconds into the trajectory, the last one made a stop "
                             "(the trajectory is re-solved so it ends at rest)")
    parser.add_argument("--signing-key", default=None, metavar="FILE",
                        help="MAVLink 2 signing key file (32 raw bytes, or a passphrase hashed with SHA-256 as "
                             "MAVProxy's signing setup): sign everything, accept only signed vehicle messages")
    parser.add_argument("--quiet", action="store_true", help="no progress display")


@dataclass(frozen=True, eq=False)
class FlightPlan:
    """What the runner needs from a plan (ENU, map frame)."""

    trajectory: object
    waypoints_p_enu_m: np.ndarray
    target_enu_m: np.ndarray
    coverage_fraction: float | None
    plan: object = None          # companion.planner.Plan when planned here
    waypoints_t_s: np.ndarray | None = None
    waypoints_v_enu_m_s: np.ndarray | None = None
    waypoints_a_enu_m_s2: np.ndarray | None = None

    @classmethod
    def from_plan(cls, plan) -> "FlightPlan":
        """From a ``companion.planner.Plan``."""
        w = plan.waypoints
        return cls(plan.trajectory, np.asarray(w.p_enu_m, dtype=float), np.asarray(plan.target_enu_m, dtype=float),
                   float(plan.stats.coverage_fraction), plan, np.asarray(w.t_s, dtype=float),
                   np.asarray(w.v_enu_m_s, dtype=float), np.asarray(w.a_enu_m_s2, dtype=float))

    def cut(self, cut_s: float, config) -> "FlightPlan":
        """The way-points up to the first one at or after ``cut_s`` seconds
        (so the flight lasts at least ``cut_s``), the last made a stop (v = a = 0), and the LQR trajectory re-solved through
        them with ``config`` (TrajectoryConfig): a short mission that ends at
        rest instead of a reference that halts at cruise speed."""
        from ..trajectory import generate_trajectory

        t = self.waypoints_t_s
        n = min(len(t), max(2, int(np.searchsorted(t, t[0] + cut_s, side="left")) + 1))
        t = t[:n].copy()
        p = self.waypoints_p_enu_m[:n]
        v = self.waypoints_v_enu_m_s[:n].copy()
        a = self.waypoints_a_enu_m_s2[:n].copy()
        speed = float(np.linalg.norm(v[-1]))
        if speed > 0.0:
            # The new stop ends a run: its piece also has to ramp down, which
            # ``companion.coverage.extract_waypoints`` pays for with half a
            # smooth ramp, t_acc / 2 = 0.5 * 1.875 V / a_ref (a_ref = 0.5 m/s^2).
            t[-1] += 0.5 * 1.875 * speed / 0.5
        v[-1] = 0.0
        a[-1] = 0.0
        traj = generate_trajectory(t, p, v, a, config, target_enu_m=self.target_enu_m)
        return FlightPlan(traj, p, self.target_enu_m, None, None, t, v, a)


def prepare(mission, plan_path: str | None) -> FlightPlan:
    """Plan ``mission`` or rebuild the trajectory of ``plan_path``.

    Raises
    ------
    PlanError, MapError
        Bad plan file or maps (one-line InputError).
    """
    if plan_path is None:
        from ..planner import plan_mission

        return FlightPlan.from_plan(plan_mission(mission))
    from ..plan_io import load_plan
    from ..trajectory import generate_trajectory

    pf = load_plan(plan_path)
    from ..preflight import check_plan_file
    check_plan_file(pf, mission)      # on the map, above the terrain, for this field (companion/preflight.py)
    target = pf.target_enu_m
    if target is None:
        # A plan.json without ``target_enu_m`` (it is not in DESIGN.md's
        # minimum): S_p is where the pointing rays of eq. (21) meet.
        target = pointing_target_from_rays(pf.p_enu_m, pf.pointing_enu, str(plan_path))
    traj = generate_trajectory(pf.waypoint_t_s, pf.waypoint_p_enu_m, pf.waypoint_v_enu_m_s,
                               pf.waypoint_a_enu_m_s2, mission.trajectory, target_enu_m=target)
    cov = pf.stats.get("coverage_fraction")
    return FlightPlan(traj, pf.waypoint_p_enu_m, np.asarray(target, dtype=float),
                      None if cov is None else float(cov), None, pf.waypoint_t_s, pf.waypoint_v_enu_m_s,
                      pf.waypoint_a_enu_m_s2)


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
    from ..errors import PlanError

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


def execute(mission, flight_plan: FlightPlan, connect: str, control: str, tlog_path: str | None,
            progress=None, cut_s: float | None = None, runner_overrides: dict | None = None,
            signing_key: bytes | None = None, conn=None):
    """Open the link (unless ``conn``, from ``open_link``, is given), fly, close.
    Returns ``companion.runner.FlightResult``.

    The link is opened before the tlog is created: a link that cannot be
    opened (unknown host, port in use, refused) is bad input and leaves no
    file behind.
    """
    from ..control import GeometricController
    from ..runner import MissionRunner, RunnerConfig

    try:
        if cut_s is not None:
            flight_plan = flight_plan.cut(cut_s, mission.trajectory)
        cfg = RunnerConfig(control=control, **(runner_overrides or {}))
        ctrl = None
        if control == "companion":
            ctrl = GeometricController(mission.vehicle, mission.control, flight_plan.target_enu_m)
    except BaseException:
        if conn is not None:
            conn.close()
        raise
    if conn is None:
        conn = open_link(connect, tlog_path, signing_key)
    tlog = conn.tlog
    if tlog is not None:
        try:
            tlog.open()
        except OSError as exc:
            conn.close()
            raise InputError(str(tlog_path), f"cannot write: {exc.strerror or exc}") from None
    try:
        home = (mission.home.lat, mission.home.lon, mission.home.alt_m)
        runner = MissionRunner(conn, flight_plan.trajectory, flight_plan.waypoints_p_enu_m, home,
                               flight_plan.target_enu_m, mission.vehicle, ctrl, cfg, progress,
                               mission.name, flight_plan.coverage_fraction)
        return runner.run()
    finally:
        conn.close()
        if tlog is not None:
            tlog.close()


def run(args) -> int:
    from ..link import check_connection_string
    from ..mission import load_mission
    from ..progress import Progress
    from ..report import write_report

    check_connection_string(args.connect)
    if args.cut is not None and not (math.isfinite(args.cut) and args.cut > 0):
        raise InputError(f"--cut {args.cut}", "must be a finite number of seconds > 0")
    check_output_paths((("--tlog", args.tlog), ("--report", args.report)))
    key = None
    if args.signing_key is not None:
        from ..link.signing import load_signing_key
        key = load_signing_key(args.signing_key)
    mission = load_mission(args.mission)
    # The link first: a bad --connect (unknown host, port in use, refused) fails before any planning.
    conn = open_link(args.connect, args.tlog, key)
    try:
        fp = prepare(mission, args.plan)
    except BaseException:
        conn.close()
        raise
    progress = Progress(enabled=not args.quiet)
    result = execute(mission, fp, args.connect, args.control, args.tlog, progress, args.cut, conn=conn)
    rep = result.report
    write_report(rep, args.report)
    tr = rep.tracking
    err = "n/a" if tr.max_error_m is None else f"max {tr.max_error_m * 1000:.2f} mm, rms {tr.rms_error_m * 1000:.2f} mm"
    print(f"companion fly: {'completed' if rep.completed else 'NOT completed'} ({rep.control} control), "
          f"{rep.sim_time_s:.1f} s flown in {rep.wall_time_s:.1f} s wall, tracking {err} "
          f"({tr.truth_source}); report {args.report}")
    if rep.error:
        print(f"companion fly: {rep.error}", file=sys.stderr)
    return 0 if rep.completed else 1
