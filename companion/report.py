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
REPORT_FORMAT_VERSION = "1.0"


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
    """

    max_error_m: float | None
    rms_error_m: float | None
    settle_s: float
    n_samples: int = 0
    truth_source: str = "sim_truth"


@dataclass(frozen=True)
class ReplanningStats:
    """Reactive replanning summary.

    Attributes
    ----------
    events : int
        Number of replanning events (APF activations).
    min_clearance_m : float or None
        Smallest DISTANCE_SENSOR reading seen in flight (m); None if none seen.
    max_lateral_deviation_m : float
        Largest horizontal distance between the flown reference and the plan (m).
    """

    events: int = 0
    min_clearance_m: float | None = None
    max_lateral_deviation_m: float = 0.0


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


def write_report(report: FlightReport, path: str | Path) -> Path:
    """Write ``report`` as JSON to ``path`` atomically; returns the path."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".part")
    tmp.write_text(json.dumps(report.to_dict(), indent=2) + "\n", encoding="utf-8")
    os.replace(tmp, p)
    return p
