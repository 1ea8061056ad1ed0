"""Flight report (report.json, docs/report-json.md) and its tracking statistics.

``tracking_stats`` is pure: arrays in, a named result out. ``write_report``
writes the JSON atomically (temporary file + rename), so an interrupted run
leaves no partial report. The document starts with ``format_version``
(``REPORT_FORMAT_VERSION``); its schema is docs/schemas/report.schema.json.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

#: report.json format written here ("MAJOR.MINOR", docs/README.md "Versions").
REPORT_FORMAT_VERSION = "3.4"


@dataclass(frozen=True)
class TrackingStats:
    """Position tracking error over the trajectory phase after settling.

    Attributes
    ----------
    max_error_m : float or None
        Largest Euclidean position error (m); None without samples.
    rms_error_m : float or None
        Root mean square of the Euclidean error (m).
    settle_s : float
        Time (s) after the start of the trajectory phase before the error counts.
    n_samples : int
        Number of samples used.
    truth_source : str
        Where the vehicle position came from: "sim_truth" (the simulator's
        ground truth, ODOMETRY) or "estimate" (LOCAL_POSITION_NED, when the
        vehicle sends no ground truth, e.g. a real flight stack).
    t_start_s : float or None
        Vehicle time (s) at which the trajectory phase begins, fixed at
        arming: the samples counted are those from ``t_start_s + settle_s``
        on. None when the vehicle was never armed.
    """

    max_error_m: float | None
    rms_error_m: float | None
    settle_s: float
    n_samples: int = 0
    truth_source: str = "sim_truth"
    t_start_s: float | None = None


@dataclass(frozen=True)
class ReplanningStats:
    """Reactive replanning summary (docs/report-json.md ``replanning``).

    Attributes
    ----------
    enabled : bool
        The replanner flew the trajectory phase (mission ``replan.enabled``).
    events : int
        Number of replanning events (avoid, climb, stop, reroute, rejoin, hold).
    min_clearance_m : float or None
        Smallest true clearance (m) between the vehicle sphere and an unknown
        obstacle, from the SITL's ODOMETRY and the obstacles' geometry
        (``clearance_source`` "sim_truth"); None without truth or obstacles.
    clearance_source : str or None
    min_clearance_t_s : float or None
        Vehicle time of the smallest clearance (s).
    min_clearance_obstacle : int or None
        Index of that obstacle in ``sim.obstacles``; ``len(sim.obstacles) + k``
        for mover k of ``sim.movers`` (measured where it was at that vehicle time).
    min_range_m : float or None
        Smallest non-downward DISTANCE_SENSOR reading (m) in hold, trajectory and hover.
    max_lateral_deviation_m : float
        Largest horizontal distance between the reference and the leg being
        avoided, while avoiding and rejoining (m).
    extra_path_m : float
        Length of the flown reference minus the planned trajectory's (m).
    max_climb_m : float
        Largest climb of the reference above the planned height while avoiding (m).
    min_obstacle_range_m : float or None
        Smallest distance from the reference to a remembered obstacle point (m).
    event_list : tuple of dict
        The events: {t_s, pos_enu_m, obstacle_range_m, action, detail}.
    readings, unknown_hits, ignored_readings : int
        DISTANCE_SENSOR readings handed to the replanner, classified unknown, without evidence.
    mode : str or None
        The replanner's last mode.
    coverage_skipped : tuple of dict
        Plan left out by rejoins and re-routes: {from_s, to_s, length_m, reason}.
    max_height_agl_m : float or None
        Largest height of the reference above the terrain under it while avoiding
        and rejoining (m); None when it never did.
    ceiling_agl_m : float or None
        The avoiding modes' ceiling above the terrain (m); None without a replanner.
    """

    events: int = 0
    min_clearance_m: float | None = None
    max_lateral_deviation_m: float = 0.0
    enabled: bool = False
    clearance_source: str | None = None
    min_clearance_t_s: float | None = None
    min_clearance_obstacle: int | None = None
    min_range_m: float | None = None
    extra_path_m: float = 0.0
    max_climb_m: float = 0.0
    min_obstacle_range_m: float | None = None
    event_list: tuple = ()
    readings: int = 0
    unknown_hits: int = 0
    ignored_readings: int = 0
    mode: str | None = None
    coverage_skipped: tuple = ()
    max_height_agl_m: float | None = None
    ceiling_agl_m: float | None = None

    @property
    def actions(self) -> tuple[str, ...]:
        """The distinct actions of ``event_list``, in the order they first happened."""
        return tuple(dict.fromkeys(e["action"] for e in self.event_list))


@dataclass(frozen=True)
class FlightReport:
    """Everything report.json holds (docs/report-json.md), after ``format_version``.

    Attributes
    ----------
    completed : bool
        The trajectory was flown to its end and the vehicle landed and
        disarmed, with no violation (``companion.flight.monitor``): it stayed
        armed, airborne, in the mode we asked for, did not crash, and the
        tracking error stayed within the bound.
    control : str
        "companion" (geometric controller, HIL_ACTUATOR_CONTROLS) or "vehicle".
    sim_time_s : float
        Vehicle time spent from the first to the last frame (s).
    wall_time_s : float
        Wall-clock duration of the flight (s).
    tracking, replanning : see their classes
    coverage_fraction : float or None
        From the plan's statistics.
    tlog : str or None
        Path of the recorded .tlog.
    crashed : bool
        The vehicle reported a crash (STATUSTEXT CRITICAL "CRASH...").
    crash : dict or None
        ``{t_s, text}`` of the crash report.
    violation : dict or None
        The first violation (``Violation.to_dict``): why the flight is not completed.
    planned_coverage_fraction : float or None
        The plan's coverage; ``coverage_fraction`` is what was flown of it
        (planned coverage times ``path_flown_fraction``).
    path_flown_fraction : float or None
        Fraction of the planned coverage path the vehicle passed within 0.5 m of.
    degraded : dict or None
        When the inner loop was handed back to the vehicle's controller: time and reason.
    interrupted : str or None
        The signal that stopped the flight.
    link : dict or None
        Link statistics (messages received, rejected, bad bytes).
    resumed_from_s : float or None
        ``--attach resume``: trajectory time (s from its start) the flight resumed at.
    phase : str
        "done" for a completed flight; otherwise the phase in which the first
        violation or fault happened (where it failed).
    end_phase : str
        The phase the flight ended in ("done": landed and disarmed, "holding",
        "released", "ended", or where the link was lost).
    control_in_use : str
        Who flew the inner loop at the end: ``control``, or "vehicle" after a
        ``degraded`` hand-over.
    control_mode_changes : tuple of dict
        ``{t_s, from, to, reason, phase}`` of each change of ``control_in_use``.
    faults : tuple of dict
        Output faults, ``{t_s, kind, detail, phase}``: kind "tlog" (a write
        error, the file deleted, replaced or not growing) or "report" (the
        report could not be written where asked).
    report_fallback : dict or None
        ``{path, wanted, reason}`` when this report was written to ``path``
        because ``wanted`` could not be written.
    sensor_coverage : dict or None
        The pre-flight sensor coverage check (``--sensor-gap``): ``{mode,
        checked, gaps, time_scale}`` (docs/report-json.md).
    guard : dict or None
        What the guard checked and refused (``companion.safety.gate``,
        docs/report-json.md ``guard``); None when no guard flew.
    """

    completed: bool
    control: str
    sim_time_s: float
    wall_time_s: float
    tracking: TrackingStats
    replanning: ReplanningStats = field(default_factory=ReplanningStats)
    coverage_fraction: float | None = None
    tlog: str | None = None
    mission: str = ""
    phase: str = ""
    error: str | None = None
    real_time_factor: float | None = None
    n_frames: int = 0
    trajectory_duration_s: float = 0.0
    crashed: bool = False
    crash: dict | None = None
    violation: dict | None = None
    planned_coverage_fraction: float | None = None
    path_flown_fraction: float | None = None
    degraded: dict | None = None
    interrupted: str | None = None
    link: dict | None = None
    resumed_from_s: float | None = None
    end_phase: str = ""
    control_in_use: str = ""
    control_mode_changes: tuple = ()
    faults: tuple = ()
    report_fallback: dict | None = None
    sensor_coverage: dict | None = None
    guard: dict | None = None

    def __post_init__(self) -> None:
        # Unset: the flight ended where it stopped, flown as configured.
        if not self.end_phase:
            object.__setattr__(self, "end_phase", self.phase)
        if not self.control_in_use:
            object.__setattr__(self, "control_in_use", self.control)

    def to_dict(self) -> dict:
        """The report.json document: ``format_version`` first, then the fields."""
        return {"format_version": REPORT_FORMAT_VERSION, **_finite(asdict(self))}


def _finite(obj):
    """JSON has no NaN/inf: map them to None, recursively."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def tracking_stats(t_s, err_m, t_start_s: float, settle_s: float = 5.0,
                   truth_source: str = "sim_truth") -> TrackingStats:
    """Max and RMS of a position error series after ``t_start_s + settle_s``.

    Parameters
    ----------
    t_s : array_like (N,)
        Sample times (s, vehicle clock).
    err_m : array_like (N,)
        Euclidean position error |p_true - p_ref| (m) at those times.
    t_start_s : float
        Start of the trajectory phase (s, same clock).
    settle_s : float
        Samples before ``t_start_s + settle_s`` are ignored.
    """
    t = np.asarray(t_s, dtype=float)
    e = np.asarray(err_m, dtype=float)
    sel = (t >= t_start_s + settle_s) & np.isfinite(e)
    if not np.any(sel):
        return TrackingStats(None, None, float(settle_s), 0, truth_source)
    es = e[sel]
    return TrackingStats(float(es.max()), float(math.sqrt(float(np.mean(es * es)))), float(settle_s),
                         int(es.size), truth_source)


def temp_name(path: str | Path) -> Path:
    """The temporary sibling ``write_report`` writes first: a short name of its own
    (``.cmp-<pid>.tmp``, at most 21 bytes), so any legal final name works."""
    p = Path(path)
    return p.with_name(f".cmp-{os.getpid()}.tmp")


def write_report(report: FlightReport, path: str | Path) -> Path:
    """Write ``report`` as JSON to ``path`` atomically (``temp_name`` + rename);
    returns the path. The directory must exist (a deleted output directory is
    a fault, not something to recreate). Raises OSError; nothing is left
    behind on failure."""
    p = Path(path)
    tmp = temp_name(p)
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(json.dumps(report.to_dict(), indent=2) + "\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, p)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return p


def fallback_report_path(wanted: str | Path, tmp_dir: str | None = None) -> Path:
    """Where a report goes when ``wanted`` cannot be written: the temporary
    directory (``tempfile.gettempdir()``), a new name with the process id and
    the wall time."""
    import tempfile
    import time

    d = Path(tmp_dir if tmp_dir is not None else tempfile.gettempdir())
    stem = Path(wanted).stem[:40] or "report"
    return d / f"companion-{stem}-{os.getpid()}-{int(time.time())}.json"


@dataclass(frozen=True)
class ReportWritten:
    """What ``write_report_or_fallback`` did: the report as written and where."""

    report: FlightReport
    path: Path | None
    fallback: bool
    error: str | None = None


def write_report_or_fallback(report: FlightReport, path: str | Path, tmp_dir: str | None = None) -> ReportWritten:
    """Write ``report`` to ``path``; if that fails, record a "report" fault and
    the fallback (``report_fallback``, ``completed`` False) in the report and
    write it to ``fallback_report_path``. ``path`` None when neither could be
    written (``error`` says why; the caller prints the report elsewhere)."""
    import errno as _errno
    from dataclasses import replace

    def why(exc: OSError) -> str:
        name = _errno.errorcode.get(exc.errno, "") if exc.errno else ""
        return f"{exc.strerror or exc}" + (f" ({name})" if name else "")

    try:
        return ReportWritten(report, write_report(report, path), False)
    except OSError as exc:
        reason = f"{path}: cannot write the report: {why(exc)}"
    fb = fallback_report_path(path, tmp_dir)
    fault = {"t_s": None, "kind": "report", "detail": reason, "phase": report.end_phase or report.phase}
    phase = report.phase if not report.completed else (report.end_phase or report.phase)
    rep = replace(report, completed=False, phase=phase, faults=tuple(report.faults) + (fault,),
                  error=report.error or reason,
                  report_fallback={"path": str(fb), "wanted": str(path), "reason": reason})
    try:
        return ReportWritten(rep, write_report(rep, fb), True, reason)
    except OSError as exc:
        return ReportWritten(rep, None, True, f"{reason}; fallback {fb}: {why(exc)}")
