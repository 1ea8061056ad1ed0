"""What a flight is measured by, and its report (pure: no I/O).

``FlightRecorder`` keeps, frame by frame, the tracking error statistics
(``companion.flight.log.ErrorStats``: each new position measurement against
the reference of the frame it was taken at), the monitor's tracking and
navigation-age checks, the coverage path flown (``PathCoverage``), the
smallest true clearance to the unknown obstacles, and the decimated
per-frame ``FlightLog``. ``flight_report`` assembles report.json's
``FlightReport`` (docs/report-json.md) from the flight core and its recorder.
"""

from __future__ import annotations

import math
from collections import deque

from ..report import FlightReport, ReplanningStats, TrackingStats
from .coverage import PathCoverage
from .log import ErrorStats, FlightLog

#: Frames of reference kept to match late position measurements (0.5 s at 250 Hz).
REF_HISTORY_FRAMES = 128
_NAN3 = (math.nan, math.nan, math.nan)
_NAN9 = (math.nan,) * 9
_NAN_CTRL = (math.nan,) * 10


class FlightRecorder:
    """The flight's measurements (see the module docstring).

    Parameters
    ----------
    cfg : companion.flight.config.RunnerConfig
        ``settle_s`` (error statistics).
    inputs : companion.flight.core.FlightInputs
        ``path_xy_m``, ``coverage_fraction``, ``obstacle_clearance``.
    monitor : companion.flight.monitor.FlightMonitor
    react : callable
        ``Violation -> None``.
    view : companion.flight.inbox.VehicleView
        Where the measurements come from.
    phase_code : dict
        Phase name -> the number in the log's phase column.
    flying : tuple of str
        The phases in which the vehicle flies under our reference (clearance and nav-age checks).
    """

    def __init__(self, cfg, inputs, monitor, react, view, phase_code: dict, flying: tuple) -> None:
        self.phase_code = phase_code
        self.flying = flying
        self.inputs = inputs
        self.monitor = monitor
        self.react = react
        self.view = view
        self.log = FlightLog()
        self.errors = ErrorStats(cfg.settle_s)
        self.coverage = None if inputs.path_xy_m is None else PathCoverage(inputs.path_xy_m)
        #: (frame time us, reference position, phase) of the last frames: a measurement is
        #: compared with the reference of its own time (a late datagram is not an error)
        self._ref_hist: deque = deque(maxlen=REF_HISTORY_FRAMES)
        #: The last tracking error (m), for the progress line.
        self.last_err = None
        self.min_clearance = None       # (true clearance m, t_s, obstacle index, position) from ODOMETRY

    def _matched_ref(self, t_us: int | None, by_ms: bool):
        """(frame time s, reference position, phase) of the frame at ``t_us`` (or its
        millisecond); None when it is not among the last ``REF_HISTORY_FRAMES``."""
        if t_us is None:
            return None
        for tf, p, ph in reversed(self._ref_hist):
            if (tf // 1000 == t_us // 1000) if by_ms else (tf == t_us):
                return tf * 1e-6, p, ph
            if tf < t_us - 1000:
                break
        return None

    def record(self, t: float, phase: str, ref, out, t_traj: float) -> None:
        """Error statistics, monitor checks, coverage and one (decimated) FlightLog row
        of the frame at ``t`` (s) in ``phase``, its reference ``ref`` and controller
        output ``out`` (or None); ``t_traj`` the start of the trajectory phase.

        The error compares each new measurement of the position (ODOMETRY, else
        LOCAL_POSITION_NED) with the reference of the frame it was taken at: in
        lockstep the same frame; on a real-time link a late or reordered
        datagram would otherwise count the vehicle's travel during the delay."""
        vw = self.view
        self._ref_hist.append((vw.t_us, ref.p, phase))
        if vw.odom is not None:
            vw.truth_update()
        if vw.truth is not None:
            truth, new, t_meas, by_ms = vw.truth, vw.truth_new, vw.truth_t_us, False
            vw.truth_new = False
        else:
            truth, new, by_ms = vw.pos, vw.pos_new, True
            t_meas = None if vw.pos_ms is None else vw.pos_ms * 1000
        vw.pos_new = False
        if truth is not None and new:
            match = self._matched_ref(t_meas, by_ms)
            if match is not None:
                t_m, p, ph = match
                err = math.sqrt((truth[0] - p[0]) ** 2 + (truth[1] - p[1]) ** 2 + (truth[2] - p[2]) ** 2)
                self.last_err = err
                if ph == "trajectory":
                    self.errors.add(t_m, err)
                    if self.coverage is not None and vw.n_frames % 4 == 0:
                        self.coverage.visit(truth[0], truth[1])
                    v = self.monitor.on_tracking(t_m, t_traj, err, vw.truth_source)
                    if v is not None:
                        self.react(v)
        if self.inputs.obstacle_clearance is not None and vw.truth_source == "sim_truth" and phase in self.flying \
                and vw.truth is not None and vw.n_frames % 2 == 0:
            c, k = self.inputs.obstacle_clearance(vw.truth, vw.truth_t_us)
            mc = self.min_clearance
            if mc is None or c < mc[0]:
                self.min_clearance = (float(c), t, k, tuple(float(x) for x in vw.truth))
        if phase in self.flying:
            v = self.monitor.on_nav_age(t, vw.nav_t)
            if v is not None:
                self.react(v)
        log = self.log
        if log.wants():
            est = vw.pos if vw.pos is not None else _NAN3
            R = vw.R
            log.append((t, self.phase_code[phase]), ref.p, truth if truth is not None else _NAN3, est,
                       _NAN9 if R is None else R, _NAN_CTRL if out is None else out, ref.s)
        else:
            log.n_offered += 1

    def coverage_flown(self, completed: bool = False) -> float | None:
        """Coverage flown so far: the plan's coverage times the fraction of its
        coverage path flown (``PathCoverage``); without a path, the plan's
        coverage if the flight completed, else None. The one source of the
        figure: report.json, the progress line and the summaries read it."""
        cov = self.inputs.coverage_fraction
        if cov is None:
            return None
        if self.coverage is not None:
            return cov * self.coverage.fraction()
        return cov if completed else None


def replanning_stats(recorder: FlightRecorder, min_range_m, replanner, mode) -> ReplanningStats:
    """report.json ``replanning``: the true clearance, the closest rangefinder
    reading ``min_range_m``, and the replanner's statistics (``mode``: its
    last mode) when it flew."""
    mc = recorder.min_clearance
    clearance = dict(min_clearance_m=None if mc is None else mc[0],
                     clearance_source=None if mc is None else "sim_truth",
                     min_clearance_t_s=None if mc is None else mc[1],
                     min_clearance_obstacle=None if mc is None else mc[2],
                     min_range_m=min_range_m)
    if replanner is None:
        return ReplanningStats(enabled=False, **clearance)
    st = replanner.stats
    d = st.to_dict()
    return ReplanningStats(enabled=True, events=st.events, max_lateral_deviation_m=st.max_lateral_deviation_m,
                           extra_path_m=st.extra_path_m, max_climb_m=st.max_climb_m,
                           min_obstacle_range_m=st.min_obstacle_range_m, event_list=tuple(d["event_list"]),
                           readings=st.readings, unknown_hits=st.unknown_hits,
                           ignored_readings=st.ignored_readings, mode=mode,
                           coverage_skipped=tuple(d["coverage_skipped"]), max_height_agl_m=st.max_height_agl_m,
                           ceiling_agl_m=st.ceiling_agl_m, **clearance)


def flight_report(core, wall_s: float, tlog: str | None, link_stats: dict | None = None) -> FlightReport:
    """report.json's ``FlightReport`` of the flight flown by ``core``
    (``companion.flight.core.FlightCore``) so far, ``wall_s`` wall seconds long,
    recorded in ``tlog``, with the runner's ``link_stats``."""
    rec = core.recorder
    vw = core.view
    es = rec.errors
    cfg = core.cfg
    tr = TrackingStats(es.max_m, es.rms_m, cfg.settle_s, es.n, vw.truth_source, es.t_start_s)
    sim_s = (vw.t_s - vw.t_first_s) if vw.t_s is not None and vw.t_first_s is not None else 0.0
    completed = core.phase == "done" and core.monitor.ok and core.error is None
    flown = None
    if rec.coverage is not None:
        flown = rec.coverage.fraction()
    v = core.monitor.first
    if completed:
        phase = core.phase
    else:
        phase = core.failed_phase if core.failed_phase is not None else core.phase
    inputs = core.inputs
    return FlightReport(
        completed=completed,
        control=cfg.control,
        sim_time_s=float(sim_s),
        wall_time_s=float(wall_s),
        tracking=tr,
        replanning=replanning_stats(rec, vw.min_range_m, core.replanner, core.replan_mode),
        coverage_fraction=rec.coverage_flown(completed),
        tlog=tlog,
        mission=inputs.mission_name,
        phase=phase,
        end_phase=core.phase,
        error=core.error if core.error is not None else (v.detail if v is not None else None),
        real_time_factor=(sim_s / wall_s) if wall_s > 0 else None,
        n_frames=vw.n_frames,
        trajectory_duration_s=float(inputs.trajectory.tf - inputs.trajectory.t0),
        crashed=core.monitor.crash is not None,
        crash=core.monitor.crash,
        violation=None if v is None else v.to_dict(),
        planned_coverage_fraction=inputs.coverage_fraction,
        path_flown_fraction=flown,
        degraded=core.degraded,
        interrupted=core.interrupted,
        link=link_stats,
        resumed_from_s=core.resumed_from_s,
        control_in_use=core.control_mode,
        control_mode_changes=tuple(dict(c) for c in core.control_mode_changes),
        faults=tuple(dict(f) for f in core.faults),
        guard=None if core.guard is None else core.guard.to_dict(),
        sensor_coverage=core.sensor_coverage,
    )
