"""The mission runner: the I/O shell around ``companion.flight.core.FlightCore``.

The flight itself (procedure, references, controller, monitor) is the pure
``FlightCore``: vehicle messages in, messages out. This module only wires it
to a ``Connection``:

- before the vehicle clock runs, our HEARTBEAT once a wall second (so a
  ``udpin`` vehicle learns our address);
- every message received goes to the core in arrival order; what the core
  queues is sent at once (in lockstep the vehicle waits for the answer);
- the .tlog is stamped on the vehicle's clock: the first frame's vehicle time
  is mapped onto the wall time it arrived, every later record is that plus
  the vehicle time elapsed (so log tools see the flight's real duration);
- liveness: no message, or a vehicle clock that does not advance, for
  ``link_timeout_s`` wall seconds ends the flight (``FlightCore.link_lost``);
- link health (``companion.flight.health``): in companion control, jitter or
  loss that the inner loop cannot take hands it to the vehicle (``degrade``);
- SIGINT/SIGTERM: ``FlightCore.interrupt`` (land or hold), the flight is
  pumped until that is done, report.json is written by the caller; a second
  signal stops at once;
- the .tlog: a write that fails (ENOSPC, EIO) or a file that ``TlogWriter.check``
  (about once a wall second) finds deleted, replaced or not growing is an
  output fault (``FlightCore.output_fault``): land or hold like a lost link,
  and go on flying until that is done.
"""

from __future__ import annotations

import gc
import logging
import math
import os
import signal
import threading
import time
from dataclasses import dataclass

from mavcore.errors import LinkError, UnsafeMessage
from mavcore.link.command_rules import command_name

_log = logging.getLogger("companion")
from .flight.config import RunnerConfig  # noqa: F401  (re-export)
from .flight.core import (LAUNCH_TOLERANCE_M, PHASES, UNUSED_STREAMS, ActuatorOut,  # noqa: F401
                          FlightCore, FlightInputs)
from .flight.health import LinkHealth
from .flight.log import FlightLog  # noqa: F401  (re-export)
from .flight.reporting import flight_report
from .trajectory.reference import RefSample, climb_duration_s, pointing_at, setpoint_yaw_enu, smooth_segment
from .progress import Progress
from .report import FlightReport

_PHASE_CODE = {p: i for i, p in enumerate(PHASES)}
#: Wall seconds between checks that the .tlog on disk is still ours and growing.
TLOG_CHECK_INTERVAL_S = 1.0


@dataclass
class FlightResult:
    """What ``MissionRunner.run`` returns: the report and the (decimated) per-frame log."""

    report: FlightReport
    log: FlightLog


class MissionRunner:
    """Fly ``inputs`` over ``conn`` (an open ``companion.link.Connection``).

    Parameters
    ----------
    conn : Connection
    core : FlightCore
    progress : Progress or None
    """

    def __init__(self, conn, core: FlightCore, progress: Progress | None = None) -> None:
        self.conn = conn
        self.core = core
        self.progress = progress or Progress(enabled=False)
        self._signal: str | None = None
        self._signals_seen = 0
        self._debug = False
        self._clock_offset_us: int | None = None

    # --- signals --------------------------------------------------------------------
    def _on_signal(self, signum, frame) -> None:
        self._signals_seen += 1
        self._signal = signal.Signals(signum).name

    def _install_signals(self):
        if threading.current_thread() is not threading.main_thread():
            return None
        old = {}
        for s in (signal.SIGINT, signal.SIGTERM):
            old[s] = signal.signal(s, self._on_signal)
        return old

    # --- the vehicle clock for the .tlog -----------------------------------------------
    def _stamp_us(self) -> int:
        t_us = self.core.view.t_us
        if t_us is None:
            return int(time.time() * 1e6)
        if self._clock_offset_us is None:
            self._clock_offset_us = int(time.time() * 1e6) - t_us
        return self._clock_offset_us + t_us

    # --- the loop ---------------------------------------------------------------------
    def _send_outbox(self) -> None:
        conn = self.conn
        for out in self.core.take_outbox():
            if self._debug and type(out) is not ActuatorOut and out.get_type() == "COMMAND_LONG":
                _log.debug("t=%.3f s: command %s %s", self.core.view.t_s or 0.0, command_name(out.command),
                           [out.param1, out.param2, out.param3, out.param4, out.param5, out.param6, out.param7])
            try:
                if type(out) is ActuatorOut:
                    conn.send_actuators(out.time_usec, out.motor_cmd, out.armed)
                else:
                    conn.send(out)
            except UnsafeMessage as exc:
                self._refused(out, exc)

    def _refused(self, out, exc: UnsafeMessage) -> None:
        """The link refused to send ``out`` (``mavcore.link.command_rules``): unusable
        motor commands become a tick without override and the vehicle's controller
        takes over (``degrade``); any other message stops the flight (land or hold)."""
        core = self.core
        if type(out) is ActuatorOut:
            self.conn.send_actuators(out.time_usec, None, out.armed)
            core.degrade(str(exc))
        elif core.interrupted is None and not core.finished:
            core.interrupt(str(exc))

    def run(self) -> FlightResult:
        """Fly; returns the report (``completed`` False with the reason on failure)."""
        core, conn, cfg = self.core, self.conn, self.core.cfg
        wall0 = time.monotonic()
        conn.frame_sync = True       # every frame is answered in lockstep: replies follow the next frame
        conn.spin_s = cfg.spin_us * 1e-6 if (os.cpu_count() or 1) >= 2 else 0.0
        conn.clock = self._stamp_us
        old = self._install_signals()
        # Everything built so far (modules, plan, trajectory, maps) lives for
        # the whole flight: out of the collector's sight, a full collection
        # only walks what the flight allocates (3-4 % of a frame's CPU otherwise).
        gc.freeze()
        health = None
        last_msg = last_clock = time.monotonic()
        last_t = None
        next_hb = 0.0
        next_show, shown = 0.0, None
        self._debug = _log.isEnabledFor(logging.DEBUG)
        n_texts, n_param_warnings, autopilot = 0, 0, None
        tlog = conn.tlog
        next_check = time.monotonic() + TLOG_CHECK_INTERVAL_S
        try:
            while not core.finished:
                now = time.monotonic()
                if self._signal is not None and core.interrupted is None:
                    core.interrupt(self._signal)
                    self._send_outbox()
                if self._signals_seen >= 2:
                    core.link_lost(f"stopped by a second {self._signal}")
                    break
                if core.heartbeat_wanted and now >= next_hb:
                    conn.send(core.heartbeat())
                    next_hb = now + 1.0
                msgs = conn.poll(0.05)
                now = time.monotonic()
                if msgs:
                    last_msg = now
                    for m in msgs:
                        core.handle(m)
                        if core.outbox:
                            self._send_outbox()
                    t = core.view.t_s
                    if t is not None and t != last_t:
                        last_t, last_clock = t, now
                        if cfg.control == "companion" and core.view.period_us:
                            if health is None:
                                health = LinkHealth(core.view.period_us * 1e-6, lockstep=core.vehicle_lockstep)
                            health.lockstep = core.vehicle_lockstep
                            why = health.observe(now, t)
                            if why is not None and core.phase in ("takeoff", "hold", "trajectory", "hover"):
                                core.degrade(why, jitter_p95_s=health.jitter_p95_s, frames_lost=health.n_lost)
                                self._send_outbox()
                if now - last_msg > cfg.link_timeout_s:
                    core.link_lost(f"{conn.url}: vehicle silent for {cfg.link_timeout_s:g} s "
                                   f"while in phase {core.phase}")
                elif core.view.t_s is not None and now - last_clock > cfg.link_timeout_s:
                    core.link_lost(f"{conn.url}: vehicle clock stopped for {cfg.link_timeout_s:g} s "
                                   f"while in phase {core.phase}")
                if tlog is not None and not core.faults:
                    if now >= next_check:
                        tlog.check()
                        next_check = now + TLOG_CHECK_INTERVAL_S
                    if tlog.fault is not None:
                        core.output_fault("tlog", tlog.fault)
                        self._send_outbox()
                if now >= next_show or core.phase != shown:   # 20 updates a second are enough
                    if core.phase != shown:
                        _log.info("t=%.3f s: phase %s", core.view.t_s or 0.0, core.phase)
                    if core.view.autopilot is not autopilot:
                        autopilot = core.view.autopilot
                        _log.info("vehicle: %s (from its HEARTBEAT)", autopilot.key)
                    while n_texts < len(core.view.statustext):
                        _log.info("vehicle says: %s", core.view.statustext[n_texts])
                        n_texts += 1
                    while n_param_warnings < len(core.param_warnings):
                        w = core.param_warnings[n_param_warnings]
                        _log.warning("parameter %s = %s: %s (%s)", w["name"], w["value"], w["problem"], w["why"])
                        n_param_warnings += 1
                    next_show, shown = now + 0.05, core.phase
                    self._show()
        except LinkError as exc:
            core.link_lost(str(exc))
        finally:
            gc.unfreeze()
            if old is not None:
                for s, h in old.items():
                    signal.signal(s, h)
            self._show(force=True)
            self.progress.close()
        wall = time.monotonic() - wall0
        stats = {"received": conn.n_received, "sent": conn.n_sent, "bad": conn.n_bad}
        stats.update(getattr(conn, "auth_stats", lambda: {})())
        if tlog is not None:
            # What is still buffered goes to disk now: a failure here is in the report too.
            if getattr(conn, "_flush_rx", None) is not None:
                conn._flush_rx()
            if tlog.check() is not None and not core.faults:
                core.output_fault("tlog", tlog.fault)
        return FlightResult(flight_report(core, wall, str(tlog.path) if tlog is not None else None, stats),
                            core.recorder.log)

    def _show(self, force: bool = False) -> None:
        core = self.core
        frac = 0.0
        if core.phase == "trajectory" and core.view.t_s is not None:
            frac = min((core.view.t_s - core._t_traj) / max(core._window.duration_s, 1e-9), 0.999)
        elif core.phase in ("hover", "landing", "done"):
            frac = 1.0
        err = core.recorder.last_err
        phase = core.phase
        if phase == "trajectory" and core.replan_mode not in (None, "follow"):
            phase = core.replan_mode          # avoid, climb, stop, reroute, rejoin, hold
        self.progress.update(phase, frac, err if err is not None and math.isfinite(err) else None,
                             core.replan_events,
                             core.view.t_s or 0.0, force=force, coverage=core.recorder.coverage_flown(),
                             control=core.control_mode)
