"""The whole flight as a pure, event-driven state machine: MAVLink messages in,
MAVLink messages out.

``FlightCore`` holds no socket, file or clock. The runner (``companion.runner``)
hands it every message the vehicle sent, in order (``handle``), and sends what
it queued (``take_outbox``); ``companion replay`` feeds it a recorded .tlog
the same way and compares what it queues with what was recorded. So a flight
is a deterministic function of the vehicle's messages, and everything is timed
by the vehicle's clock (HIGHRES_IMU ``time_usec``).

Sequence::

    connect    the vehicle's HEARTBEAT (1/1)
    setup      learn the sensor period from two HIGHRES_IMU frames; request
               LOCAL_POSITION_NED (and the SITL's ground-truth ODOMETRY) at
               every frame, position streams at a low rate, mute the rest
               (MAV_CMD_SET_MESSAGE_INTERVAL)
    upload     the way-points as a MAVLink mission (MISSION_INT protocol)
    preflight  stream setpoints (hold where the vehicle is) for
               ``preflight_s`` (PX4 only enters OFFBOARD with a setpoint
               stream present); DO_SET_MODE OFFBOARD, ARM
    takeoff    smooth segments (7th-order, C3 smoothstep): a vertical climb
               from the ground position to the height of the trajectory's
               first point, then a level transfer to that point (launched
               within ``LAUNCH_TOLERANCE_M`` of the first point: just the climb)
    hold       hover there ``hold_s`` (the takeoff transient dies out)
    trajectory the planned trajectory (or the replanner's, see below)
    hover      ``hover_s`` at its last point
    landing    NAV_LAND: the vehicle's own controller descends; it disarms
               itself once landed (or we send ARM_DISARM(0))

The procedure is written as a generator (``_procedure``) that yields the
condition it waits for; ``handle`` resumes it after every message once its
condition holds. Commands wait for their COMMAND_ACK for
``command_timeout_s`` of vehicle time and are re-sent (TEMPORARILY_REJECTED:
retried after 0.5 s). Per sensor frame (``_on_imu``), in both control modes,
setpoints (SET_POSITION_TARGET_LOCAL_NED) are queued at ``setpoint_hz``; with
``control="companion"`` the geometric controller's motor commands answer every
frame (HIL_ACTUATOR_CONTROLS, lockstep flag, ``time_usec`` echoed), else a
tick with four NaN (the vehicle's own controller flies). With
``control="rates"`` the controller's body rates and normalised thrust
(SET_ATTITUDE_TARGET, ``companion.control.rates``) precede the NaN tick of
every frame from arming to landing, in place of the position setpoints (the
vehicle's rate loop flies; PX4 follows the last kind of offboard setpoint).

What the rangefinders see (every DISTANCE_SENSOR, any phase) is sent on as
OBSTACLE_DISTANCE at most 10 Hz (``companion.link.obstacle_distance``) for
the vehicle's own collision prevention.

Outcome: a ``FlightMonitor`` (``companion.flight.monitor``) watches from our
arming to our landing command; its first violation stops the flight with the
reaction it names (``end``, ``release``, ``land``/hold) and the flight is not
``completed``. ``interrupt`` (SIGINT/SIGTERM) and ``link_lost`` do the same
from outside. ``degrade`` hands the inner loop back to the vehicle's
controller (setpoints only) when the link can no longer carry it.

What the vehicle's messages say of it (clock, arming, mode, position, attitude,
truth) is ``companion.flight.inbox.VehicleView``, whose handlers the core's
``handle`` dispatches to; the error statistics, coverage, clearance, log and
report.json are ``companion.flight.reporting``. The core itself is the
procedure.

Truth: ODOMETRY (the SITL's ground truth) is decoded only after the frame's
answer is queued and only feeds the report's error statistics (and the
monitor's error bound); nothing the controller or the replanner sees comes
from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from ..control.geometric import Measurements, Reference

from ..control.observer import heading_from_accel_mag
from ..control.rates import normalised_thrust, vehicle_hover_thrust
from mavcore.errors import CommandRejected, LinkError
from mavcore import codec
from mavcore.services.command import COMMAND_SENDS, CommandClient, command_long
from mavcore.services.mission import MissionUploadClient
from mavcore.services.param_client import ParamReadClient
from mavcore.services.telemetry import stream_requests
from ..replan.perception import propagated_pose
from mavcore.vehicle import VehicleConfig
from .config import RunnerConfig
from .inbox import VehicleView
from .monitor import FlightMonitor, MonitorConfig, Violation
from .param_check import check_params
from .reporting import FlightRecorder
from .setup_record import MAV_SEVERITY_DEBUG, SETUP_TEXT_ID, setup_chunks
from ..trajectory.reference import (RefSample, TrajectoryWindow, at_rest, climb_duration_s, pointing_at,
                                    segments_sample, setpoint_yaw_enu, smooth_segment)

PHASES = ("connect", "setup", "upload", "preflight", "takeoff", "hold", "trajectory", "hover", "landing", "done",
          "holding", "released", "ended", "divert")
PHASE_CODE = {p: i for i, p in enumerate(PHASES)}
#: Phases in which the vehicle is meant to be flying under our reference.
FLYING = ("takeoff", "hold", "trajectory", "hover", "divert")
#: A refused landing is moved (``_landing_spot``) at most this many times, then the vehicle holds.
LANDING_MOVES = 3
#: After a move the vehicle hovers ``hover_s`` (as at the plan's end), then up to this much
#: longer (s) until it is settled, before its landing is checked again and the landing is
#: handed to the vehicle...
MOVE_SETTLE_S = 3.0
#: ... settled: below this speed (m/s) and this body rate (rad/s). A hand-over with the vehicle
#: still turning left the stack's controller a yaw it saturated the motors on (fresh seed
#: 20261219 flight 8: a 1.5 m move at 3 m/s, the landing handed over 0.04 s after it; the
#: vehicle fell from 2.9 m).
MOVE_REST_M_S = 0.1
MOVE_REST_RAD_S = 0.1

#: A vehicle armed within this horizontal distance (m) of the trajectory's
#: first point climbs straight to it (no separate level transfer).
LAUNCH_TOLERANCE_M = 0.05

#: Streams the runner never reads (muted by ``companion demo``).
UNUSED_STREAMS = (mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED)

#: Height error (m) within which an ArduCopter take-off (MAV_CMD_NAV_TAKEOFF) counts as done.
TAKEOFF_ALT_TOLERANCE_M = 0.3
#: Speed (m/s) under which the vehicle counts as at rest after an ArduCopter take-off: our
#: take-off reference then starts, at rest, where the vehicle is. Handed over while still
#: climbing (ArduCopter says "Takeoff complete" within NAV_MC_ALT_RAD, at up to ~2.7 m/s),
#: the velocity error alone made the thrust vector of eq. (23) point down (kv |v| > m g:
#: 30 x 2.54 = 76 N against 42.6 N), i.e. a demanded flip.
TAKEOFF_REST_SPEED_M_S = 0.2
_Z3 = (0.0, 0.0, 0.0)
#: The vehicle's ATTITUDE places the rangefinder readings while one came within this (s,
#: vehicle time); after a longer gap the companion's observer does (``_replan_pose``).
ATTITUDE_LIVE_S = 0.5
#: A replanned trajectory phase that the plan being flown (the first, or the last re-route or
#: rejoin installed) has not finished this factor times its duration left when installed, plus
#: ``REPLAN_TIME_EXTRA_S``, after it was installed is a failure (``replan_deadline``; the
#: replanner's own escape is time-bounded).
REPLAN_TIME_FACTOR = 3.0
REPLAN_TIME_EXTRA_S = 120.0


def replan_deadline(t_s: float, left_s: float, deadline_s: float = -math.inf) -> float:
    """Vehicle time (s) by which the trajectory phase must have finished, the plan being
    flown having ``left_s`` seconds left at ``t_s``: ``REPLAN_TIME_FACTOR`` times that plus
    ``REPLAN_TIME_EXTRA_S``, never earlier than ``deadline_s`` (the deadline before a
    re-route or a rejoin installed it: a new plan extends the deadline, never shortens it)."""
    return max(deadline_s, t_s + REPLAN_TIME_FACTOR * max(left_s, 0.0) + REPLAN_TIME_EXTRA_S)
#: STATUSTEXT prefix of the replanner's events (``companion.replay.metrics`` counts them).
REPLAN_PREFIX = "companion: replan "
#: STATUSTEXT prefix of the guard's refusals (docs/replan.md "The guard").
GUARD_PREFIX = "companion: guard: "


def replan_text(action: str, range_m: float | None, detail: str = "") -> str:
    """The STATUSTEXT of one replanning event (at most 50 characters)."""
    rng = "" if range_m is None or not math.isfinite(range_m) else f" {range_m:.2f} m"
    text = f"{REPLAN_PREFIX}{action}{rng}"
    if detail:
        text += ": " + detail
    return text[:50]


#: STATUSTEXT prefixes of the events that come from outside the core (replay re-injects them).
INTERRUPT_PREFIX = "companion: interrupted by "
DEGRADE_PREFIX = "companion: inner loop to vehicle: "
OUTPUT_FAULT_PREFIX = "companion: output fault: "
#: Phases before arming: an output fault there ends the flight on the ground.
BEFORE_ARMING = ("connect", "setup", "upload", "preflight")

#: STATUSTEXT (NOTICE) once per kind of measurement the observer had to skip.
OBSERVER_PREFIX = "companion: observer: "
OBSERVER_FAULT_TEXT = {"free_fall": "free fall, tilt on the gyro", "accel": "accel not finite, skipped",
                       "gyro": "gyro not finite, last rate held", "mag": "no usable mag, heading on gyro",
                       "fix": "position fix not finite, skipped", "time": "frame time not finite, skipped"}


@dataclass(frozen=True)
class FlightInputs:
    """What the core flies (ENU, map frame = the vehicle's local frame).

    Attributes
    ----------
    trajectory : companion.trajectory.Trajectory
        The reference.
    waypoints_p_enu_m : (N, 3) array
        Way-points uploaded as the MAVLink mission.
    home : (lat_deg, lon_deg, alt_m)
        Geodetic pose of the map origin (for MISSION_ITEM_INT).
    target_enu_m : (3,) sequence
        Pointing target S_p.
    mag_field_enu_gauss : (3,) sequence
        The local Earth field (the take-off heading is measured against it).
    mission_name : str
    coverage_fraction : float or None
        The plan's coverage of the field.
    path_xy_m : (M, 2) array or None
        The plan's 2D coverage path; the report's flown coverage is the
        planned coverage times the fraction of this path actually flown.
    replanner : companion.replan.Replanner or None
        Flies the trajectory phase around unknown obstacles (``replan``
        mission key); None: the trajectory is flown as planned.
    obstacle_clearance : callable or None
        ``f(pos_enu_m, t_us) -> (clearance_m, obstacle_index)``: the vehicle
        sphere's distance to the nearest unknown obstacle, from the SITL's
        geometry (``sim.obstacles``, and ``sim.movers`` where they are at the
        ODOMETRY's vehicle time ``t_us``). Applied to the true position (ODOMETRY)
        only, for the report's ``replanning.min_clearance_m``.
    transit_floor_z_m : float or None
        Lowest safe height (ENU z, m) of a straight level flight across the
        field: the take-off's transfer to the first point flies at least this
        high (``takeoff_segments``).
    setup : dict or None
        How this flight was set up (``companion.flight.setup_record``): sent
        at connection so the .tlog describes its own flight.
    guard : companion.safety.gate.GuardGate or None
        Every reference passes it before it is sent (``_guarded``), the plan and
        the take-off before arming, each new trajectory of the replanner, each
        landing (docs/replan.md "The guard"); None: references go out unchecked.
    """

    trajectory: object
    waypoints_p_enu_m: object
    home: tuple
    target_enu_m: tuple
    mag_field_enu_gauss: tuple = (0.0, 0.21, -0.42)
    mission_name: str = ""
    coverage_fraction: float | None = None
    path_xy_m: object = None
    setup: dict | None = None
    transit_floor_z_m: float | None = None
    replanner: object = None
    obstacle_clearance: object = None
    guard: object = None


@dataclass(frozen=True, slots=True)
class ActuatorOut:
    """One lockstep answer: HIL_ACTUATOR_CONTROLS for frame ``time_usec``
    (``motor_cmd`` None: four NaN, the vehicle's controller flies)."""

    time_usec: int
    motor_cmd: tuple | None
    armed: bool


def takeoff_segments(start, first, transit_floor_z_m, climb_speed_m_s: float, transfer_speed_m_s: float):
    """The take-off as rest-to-rest smooth segments ``[(p0, p1, duration_s), ...]`` (ENU).

    Launched within ``LAUNCH_TOLERANCE_M`` of the first point: one vertical
    climb to it. Otherwise: climb straight up to the transit height, fly
    level to above the first point, descend to it. The transit height is
    the highest of the first point, the start and ``transit_floor_z_m``
    (the highest terrain of the field plus the canopy and a clearance: a
    level flight there cannot touch a vine row); None: the first point's
    height (a field without rows).
    """
    start = tuple(float(c) for c in start)
    first = tuple(float(c) for c in first)
    if math.dist(start[:2], first[:2]) < LAUNCH_TOLERANCE_M:
        return [(start, first, climb_duration_s(math.dist(start, first), climb_speed_m_s))]
    z_t = max(first[2], start[2], transit_floor_z_m if transit_floor_z_m is not None else -math.inf)
    top = (start[0], start[1], z_t)
    over = (first[0], first[1], z_t)
    segs = [(start, top, climb_duration_s(z_t - start[2], climb_speed_m_s)),
            (top, over, climb_duration_s(math.dist(top, over), transfer_speed_m_s, 1.0))]
    if z_t - first[2] > 1e-6:
        segs.append((over, first, climb_duration_s(z_t - first[2], climb_speed_m_s)))
    return segs


class FlightCore:
    """Fly ``inputs`` (see the module docstring).

    Parameters
    ----------
    inputs : FlightInputs
    cfg : RunnerConfig
    vehicle : VehicleConfig
    controller : GeometricController or None
        Required for ``cfg.control == "companion"``.
    target_system, target_component : int
        The vehicle (1/1).
    """

    def __init__(self, inputs: FlightInputs, cfg: RunnerConfig, vehicle: VehicleConfig, controller=None,
                 target_system: int = 1, target_component: int = 1) -> None:
        if cfg.control in ("companion", "rates") and controller is None:
            raise ValueError(f"control={cfg.control!r} needs a controller")
        import numpy as np

        self.inputs = inputs
        self.cfg = cfg
        self.vehicle = vehicle
        self.ctrl = controller
        self.ts, self.tc = int(target_system), int(target_component)
        self.waypoints = np.asarray(inputs.waypoints_p_enu_m, dtype=float)
        self.target = tuple(float(x) for x in inputs.target_enu_m)
        self.home = tuple(float(h) for h in inputs.home)
        # Messages are built with a private encoder (no file): the runner packs
        # them with its own link (sequence numbers, signing).
        self.enc = mavlink.MAVLink(None, srcSystem=1, srcComponent=mavlink.MAV_COMP_ID_ONBOARD_COMPUTER)
        self.outbox: list = []
        self.monitor = FlightMonitor(MonitorConfig(cfg.max_tracking_error_m, cfg.settle_s,
                                                   max_nav_age_s=cfg.max_nav_age_s))
        self.phase = "connect"
        self.error: str | None = None
        self.finished = False
        # replanning (issue 8): the replanner flies the trajectory phase
        self.replanner = inputs.replanner
        #: The vehicle as its messages tell it, and their handlers (``companion.flight.inbox``).
        self.view = VehicleView(self.tc, self.monitor, self._react, lambda: self.phase, self._emit,
                                self.enc, self._on_imu, self._on_service_msg, self.replanner)
        #: Error statistics, coverage, clearance, the per-frame log (``companion.flight.reporting``).
        self.recorder = FlightRecorder(cfg, inputs, self.monitor, self._react, self.view, PHASE_CODE, FLYING)
        self.replan_mode = None
        self.replan_events = 0
        self._traj_deadline = math.inf
        self.n_control_faults = 0
        #: The observer's degraded frames per kind (``VelocityAidedObserver.faults``), as last seen.
        self.observer_faults: dict = {}
        self.n_stale_frames = 0
        self._controlling = False
        self.degraded: dict | None = None
        #: Who flies the inner loop, and each change: {t_s, from, to, reason}.
        self.control_mode = cfg.control
        self.control_mode_changes: list[dict] = []
        self._rates = cfg.control == "rates"
        #: Normalised hover thrust of ``--control rates``: MPC_THR_HOVER as read at setup, else the model's.
        self.hover_thrust = vehicle_hover_thrust(vehicle)
        #: ``--check-params``: each declared parameter outside what the flight needs: {name, value, problem, why}.
        self.param_warnings: list[dict] = []
        #: Output faults (the .tlog, the report): {t_s, kind, detail, phase}.
        self.faults: list[dict] = []
        #: The phase in which the first violation happened (report ``phase`` of a failed flight).
        self.failed_phase: str | None = None
        self.interrupted: str | None = None
        # the guard (issue 15): every reference passes it (``_guarded``)
        self.guard = inputs.guard
        #: The pre-flight sensor coverage check (``--sensor-gap``; report ``sensor_coverage``), set by who built us.
        self.sensor_coverage: dict | None = None
        self._guard_plan = None         # the replanner's plan last checked whole
        self._guard_tau0 = 0.0          # its clock at the start of the trajectory phase
        self._guard_stopped = False
        self._steering = False          # OFFBOARD/GUIDED set by us: our setpoints move the vehicle
        self._launch = None             # where the take-off (or a resume) began (ENU): a moved landing's home
        self._move = None               # (t0, Divert, pointing) of a moved landing in flight
        self._next_sp_t = -math.inf
        self._sp_dt = 1.0 / cfg.setpoint_hz
        self._hb_t = None
        self._init_schedule()
        self._init_protocol()
        #: Optional tap on the controller's inputs (tests check them against the link).
        self.input_tap = None


    def _init_schedule(self) -> None:
        """The procedure's schedule (vehicle seconds), set at arming."""
        self._t_arm = None
        self._segments: list[tuple] = []     # take-off: (p0, p1, T) smooth segments back to back
        self._takeoff_T = 0.0
        self._psi_arm = self._dpsi = 0.0
        self._t_hold = self._t_traj = self._t_hover = self._t_land = math.inf
        self._window: TrajectoryWindow | None = None
        self._hold_first = self._hold_last = self._preflight_ref = None
        self.resumed_from_s: float | None = None

    def _init_protocol(self) -> None:
        """The command / mission / parameter protocol plumbing of the procedure and the receive table."""
        self._client = None             # the service transaction under way (``_run``)
        #: The vehicle waits for every answer (the bundled SITL's SIM_LOCKSTEP = 1):
        #: link delay then costs wall time, not control (``companion.flight.health``).
        self.vehicle_lockstep = False
        self._proc = self._procedure()
        self._waiting = None
        self._dispatch = self.view.handlers()

    # --- the runner's face ----------------------------------------------------------

    def handle(self, m) -> None:
        """Process one message from the vehicle (in arrival order)."""
        if m.get_srcSystem() != self.ts:
            return
        ph = self.phase
        h = self._dispatch.get(m.get_type())
        if h is not None:
            h(m)
        if self._proc is not None:
            self._drive()
        if self.failed_phase is None and self.monitor.first is not None:
            self.failed_phase = ph

    def _note_failure(self, phase: str) -> None:
        if self.failed_phase is None and self.monitor.first is not None:
            self.failed_phase = phase

    @property
    def handled_types(self) -> frozenset:
        """Message types ``handle`` acts on; any other message leaves the core as it was
        (``companion replay`` does not even decode them)."""
        return frozenset(self._dispatch)

    def take_outbox(self) -> list:
        out = self.outbox
        self.outbox = []
        return out

    def interrupt(self, reason: str) -> None:
        """Stop the flight from outside (SIGINT/SIGTERM): land or hold, report not completed."""
        if self.finished:
            return
        ph = self.phase
        self.interrupted = reason
        # Said on the wire (and so in the .tlog, where replay finds it).
        self._emit(self.enc.statustext_encode(mavlink.MAV_SEVERITY_WARNING,
                                              f"{INTERRUPT_PREFIX}{reason}"[:50].encode()))
        self.monitor.fail(self.view.t_s, "interrupted", f"interrupted by {reason}", self.cfg.on_failure)
        self._note_failure(ph)
        self._stop(self.cfg.on_failure)

    def link_lost(self, detail: str) -> None:
        """The runner saw no message (or no vehicle clock) for too long: the flight ends."""
        if self.error is None:
            self.error = detail
        self.monitor.fail(self.view.t_s, "link", detail, "end")
        self._note_failure(self.phase)
        self._finish()

    def output_fault(self, kind: str, detail: str) -> None:
        """An output of the flight failed (``kind`` "tlog": a write error, the file
        deleted, replaced or not growing; docs/report-json.md ``faults``): a fault
        like a lost link. In the air the flight stops with the configured
        action (``on_failure``: land or hold) and goes on being flown until
        that is done; before arming it ends on the ground; while landing (or
        after) the landing goes on. The flight is not completed either way."""
        ph = self.phase
        self.faults.append({"t_s": self.view.t_s, "kind": kind, "detail": detail, "phase": ph})
        self._emit(self.enc.statustext_encode(mavlink.MAV_SEVERITY_CRITICAL,
                                              f"{OUTPUT_FAULT_PREFIX}{kind}"[:50].encode()))
        if self.error is None:
            self.error = detail
        in_air = self.view.armed and ph in FLYING
        if in_air:
            action = self.cfg.on_failure
        elif ph == "landing" and self.view.armed and not self.finished:
            action = "land"           # the landing under way goes on
        else:
            action = "end"            # on the ground before arming, or the flight is over
        self.monitor.fail(self.view.t_s, "output", detail, action, output=kind)
        self._note_failure(ph)
        if self.finished:
            return
        if in_air:
            self._stop(self.cfg.on_failure)
        elif ph in BEFORE_ARMING and not self.view.armed:
            if ph == "preflight":
                # OFFBOARD and the arming may be on their way with no answer yet:
                # a disarm (once; a disarmed vehicle just refuses it) so that
                # the vehicle is not left armed on the ground without setpoints.
                self._emit(command_long(self.enc, self.ts, self.tc, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (0,)))
            self._stop("end")
        # landing, holding, released: what is under way goes on

    def degrade(self, reason: str, **values) -> None:
        """Hand the inner loop back to the vehicle's controller (setpoints only)."""
        if self.degraded is not None or self.cfg.control != "companion":
            return
        self.degraded = {"t_s": self.view.t_s, "reason": reason, **values}
        self.control_mode_changes.append({"t_s": self.view.t_s, "from": self.control_mode, "to": "vehicle",
                                          "reason": reason, "phase": self.phase})
        self.control_mode = "vehicle"
        self._controlling = False
        self._emit(self.enc.statustext_encode(mavlink.MAV_SEVERITY_WARNING,
                                              f"{DEGRADE_PREFIX}{reason}"[:50].encode()))

    @property
    def heartbeat_wanted(self) -> bool:
        """Before the vehicle clock runs, the runner sends our HEARTBEAT by wall clock."""
        return self.view.t_s is None

    def heartbeat(self):
        return self.enc.heartbeat_encode(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID,
                                         0, 0, mavlink.MAV_STATE_ACTIVE)

    # --- procedure plumbing -------------------------------------------------------------

    def _emit(self, msg) -> None:
        self.outbox.append(msg)

    def _emit_all(self, msgs) -> None:
        self.outbox.extend(msgs)

    def _drive(self) -> None:
        while self._proc is not None:
            w = self._waiting
            if w is not None and not w():
                return
            try:
                self._waiting = next(self._proc)
            except StopIteration:
                self._proc = None
                self._waiting = None
            except CommandRejected as exc:
                self._procedure_failed("command_rejected", str(exc), result=exc.result)
            except LinkError as exc:
                self._procedure_failed("link", str(exc))

    def _procedure_failed(self, kind: str, detail: str, **values) -> None:
        self._proc = None
        self._waiting = None
        if self.error is None:
            self.error = detail
        # A failure while landing (or on the ground) ends the flight: landing
        # again would not help; in the air we land (or hold).
        action = "land" if self.view.armed and self.phase in FLYING else "end"
        self.monitor.fail(self.view.t_s, kind, detail, action, **values)
        self._stop(self.cfg.on_failure if action == "land" else action)

    def _run(self, client, effect=None):
        """Drive a client state machine of ``mavcore.services`` on the vehicle clock
        (generator; returns its outcome, raises its error). Its answers come in
        through ``_on_service_msg``; ``effect``: a predicate on the vehicle's
        reported state that ends a command without its ACK."""
        seen = (lambda: False) if effect is None else effect
        self._client = client
        try:
            self._emit_all(client.start(self.view.t_s))
            while not client.done:
                yield lambda: client.done or client.due(self.view.t_s, seen())
                self._emit_all(client.tick(self.view.t_s, seen()))
        finally:   # also when the procedure is closed (``_stop``) while it waits
            if self._client is client:
                self._client = None
        return client.outcome()

    def _command(self, command: int, params=(), what: str = "", retries: int | None = None, temp_retries: int = 0,
                 optional: bool = False, effect=None):
        """COMMAND_LONG until its COMMAND_ACK (generator; returns the ACK or None):
        ``mavcore.services.command.CommandClient``.

        ``effect``: a predicate on the vehicle's reported state that shows the
        command was carried out (say AUTO.LAND in HEARTBEAT). When it holds
        the command is done even without its ACK: over a lossy link the ACKs
        of every retry may be lost while the vehicle obeyed (20 % loss each
        way: a round trip fails 36 % of the time, and eight do 0.03 %).

        Raises CommandRejected on a final refusal, LinkError when unanswered
        after ``retries`` sends (unless ``optional``: then returns None).
        """
        client = CommandClient(self.enc, self.ts, self.tc, command, params, what, self.cfg.command_timeout_s,
                               COMMAND_SENDS if retries is None else retries, temp_retries, optional)
        return (yield from self._run(client, effect))

    def _upload(self, items: list, mission_type: int = mavlink.MAV_MISSION_TYPE_MISSION,
                retries: int = COMMAND_SENDS - 1):
        """The MISSION_INT upload (generator): ``mavcore.services.mission.MissionUploadClient``.
        Its re-sends in a row are a command's (``COMMAND_SENDS`` sends in all): once the vehicle's
        ACCEPTED is lost, each re-sent last item is one round trip."""
        return (yield from self._run(MissionUploadClient(self.enc, self.ts, self.tc, items, mission_type,
                                                         self.cfg.command_timeout_s, retries)))

    def _param_read(self, name: str, tries: int = 2):
        """PARAM_REQUEST_READ (generator): a ``ParamResult`` (``mavcore.services.param_client``),
        ``TIMED_OUT`` when the vehicle has no such parameter."""
        return (yield from self._run(ParamReadClient(self.enc, self.ts, self.tc, name, self.cfg.command_timeout_s,
                                                     tries, self.view.autopilot.param_bytewise)))

    def _set_interval(self, msg_id: int, interval_us: float, optional: bool = False):
        """SET_MESSAGE_INTERVAL (generator). ``optional``: a refusal, or no answer at all, ends
        it with None instead of stopping the flight; it is sent as often as any command
        (``COMMAND_SENDS``): a vehicle that answered the required request answers these, so
        silence is loss. With three sends, 20 % loss each way lost the truth request 0.8 % of
        the time and the report fell back to the estimate."""
        return (yield from self._command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, (msg_id, interval_us),
                                         "set message interval", optional=optional))

    # --- the procedure ------------------------------------------------------------------

    def _procedure(self):
        cfg = self.cfg
        yield lambda: self.view.vstate is not None
        self.phase = "setup"
        if self.inputs.setup is not None:
            for text, seq in setup_chunks(self.inputs.setup):
                self._emit(self.enc.statustext_encode(MAV_SEVERITY_DEBUG, text, SETUP_TEXT_ID, seq))
        yield lambda: self.view.period_us is not None
        for mid, interval, optional in stream_requests(self.view.period_us, cfg.request_truth, cfg.mute_streams,
                                                       cfg.low_rate_streams):
            yield from self._set_interval(mid, interval, optional=optional)
        lockstep = yield from self._param_read("SIM_LOCKSTEP")
        self.vehicle_lockstep = lockstep.ok and lockstep.value == 1
        if self._rates:
            hover = yield from self._param_read(self.view.autopilot.wire_name("MPC_THR_HOVER"))
            if hover.ok and 0.0 < hover.value <= 1.0:
                self.hover_thrust = float(hover.value)
        if cfg.check_params:
            self.param_warnings += yield from check_params(self._param_read, self.view.autopilot.param_checks,
                                                           self.enc, self._emit)
        yield lambda: self.view.pos is not None
        if self.view.armed:
            yield from self._attach()
            return

        self.phase = "upload"
        items = [codec.encode_mission_item_int(self.enc, i, p, *self.home, self.ts, self.tc, current=(i == 0))
                 for i, p in enumerate(self.waypoints)]
        yield from self._upload(items)

        # Setpoints must be streaming before OFFBOARD (PX4 rule): hold the ground position.
        self._window = TrajectoryWindow(self.inputs.trajectory, self.view.period_us * 1e-6, self.target)
        self._hold_first = at_rest(self._window.first())
        self._hold_last = at_rest(self._window.last())
        self._preflight_ref = self._static_ref(self.view.pos)
        self.phase = "preflight"
        if not self._guard_before_flight(self.inputs.trajectory, None):
            return
        t_ready = self.view.t_s + cfg.preflight_s
        yield lambda: self.view.t_s >= t_ready
        ap = self.view.autopilot
        yield from self._set_offboard_mode()
        yield from self._command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (1,), "arm", temp_retries=10)
        self.view.armed = True
        self.monitor.armed(self.view.t_s, ap.custom_mode(ap.offboard_mode))
        if ap.takeoff_by_command:
            yield from self._guided_takeoff()
        self._schedule(self.view.t_s)
        self.phase = "takeoff"
        yield lambda: self.phase == "landing"
        yield from self._land()

    def _set_offboard_mode(self):
        """DO_SET_MODE to the mode that tracks our setpoints (PX4 OFFBOARD, ArduCopter GUIDED)."""
        ap = self.view.autopilot
        yield from self._command(mavlink.MAV_CMD_DO_SET_MODE, ap.set_mode_params(ap.offboard_mode),
                                 f"set {ap.offboard_mode}", temp_retries=10)
        self._steering = True

    def _guided_takeoff(self):
        """ArduCopter: armed in GUIDED on the ground, setpoints do not lift the
        vehicle; MAV_CMD_NAV_TAKEOFF (param7: metres above home) climbs it to
        the take-off's first climb height, where our setpoints take over once
        it is there and at rest (``TAKEOFF_REST_SPEED_M_S``): the take-off
        reference (``_schedule``) starts at rest from the vehicle's position,
        so it must agree with the vehicle's velocity too."""
        x, y, z = self.view.pos
        seg = takeoff_segments(tuple(self.view.pos), self._hold_first.p, self.inputs.transit_floor_z_m,
                               self.cfg.climb_speed_m_s, self.cfg.transfer_speed_m_s)[0]
        top = float(seg[1][2])
        # Stream the climb's top meanwhile: the vehicle holds there once its take-off is done.
        self._preflight_ref = self._static_ref((x, y, top))
        yield from self._command(mavlink.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, math.nan, math.nan, math.nan, top - z),
                                 "takeoff", temp_retries=10)
        t_limit = self.view.t_s + self.cfg.landing_timeout_s

        def there() -> bool:
            v = self.view.vel
            return (abs(self.view.pos[2] - top) <= TAKEOFF_ALT_TOLERANCE_M and v is not None
                    and math.hypot(v[0], v[1], v[2]) <= TAKEOFF_REST_SPEED_M_S)

        yield lambda: there() or self.view.t_s >= t_limit
        if abs(self.view.pos[2] - top) > TAKEOFF_ALT_TOLERANCE_M:
            raise LinkError(f"vehicle did not climb to {top - z:.2f} m within {self.cfg.landing_timeout_s:g} s")
        if not there():
            raise LinkError(f"vehicle did not come to rest (under {TAKEOFF_REST_SPEED_M_S:g} m/s) at {top - z:.2f} m "
                            f"within {self.cfg.landing_timeout_s:g} s")

    def _schedule(self, t_arm: float) -> None:
        """The take-off/hold/trajectory/hover times, from arming at ``t_arm``."""
        cfg = self.cfg
        first = self._hold_first
        self._t_arm = t_arm
        self._launch = tuple(float(c) for c in self.view.pos)
        self._segments = takeoff_segments(tuple(self.view.pos), first.p, self.inputs.transit_floor_z_m,
                                          cfg.climb_speed_m_s, cfg.transfer_speed_m_s)
        self._takeoff_T = sum(seg[2] for seg in self._segments)
        self._t_hold = t_arm + self._takeoff_T
        # Heading of the body y axis (the pointing axis b2) at arming, measured
        # by the IMU (accelerometer + magnetometer); the takeoff turns it toward s0.
        s0 = first.s
        psi1 = math.atan2(s0[1], s0[0])
        imu = self.view.imu
        if imu is not None:
            psi0 = heading_from_accel_mag(imu[0], imu[1], self.inputs.mag_field_enu_gauss) + 0.5 * math.pi
        else:
            psi0 = psi1
        self._psi_arm = psi0
        self._dpsi = (psi1 - psi0 + math.pi) % (2.0 * math.pi) - math.pi
        self._t_traj = self._t_hold + cfg.hold_s
        self._t_hover = self._t_traj + self._window.duration_s
        self._t_land = self._t_hover + cfg.hover_s
        self.recorder.errors.start(self._t_traj)
        self._controlling = cfg.control in ("companion", "rates") and self.degraded is None

    def _land(self):
        """NAV_LAND, then wait for the vehicle to land and disarm (disarm it if needed)."""
        cfg = self.cfg
        if not (yield from self._landing_spot()):
            yield from self._abort_hold()
            return
        self.phase = "landing"
        self._controlling = False
        self.monitor.landing(self.view.t_s)
        yield from self._command(mavlink.MAV_CMD_NAV_LAND, (), "land", temp_retries=10, effect=self._landing_seen)
        t_limit = self.view.t_s + cfg.landing_timeout_s
        t_ground = None

        def landed() -> bool:
            nonlocal t_ground
            if not self.view.armed:
                return True
            if self.view.landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND:
                if t_ground is None:
                    t_ground = self.view.t_s
                return self.view.t_s - t_ground > 3.0
            return self.view.t_s >= t_limit

        yield landed
        if self.view.armed and self.view.landed_state != mavlink.MAV_LANDED_STATE_ON_GROUND:
            raise LinkError(f"vehicle did not land and disarm within {cfg.landing_timeout_s:g} s of vehicle time")
        if self.view.armed:
            yield from self._command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (0,), "disarm")
            self.view.armed = False
        if self.phase == "landing":
            self.phase = "done"
        self._finish()

    def _landing_seen(self) -> bool:
        """The vehicle reports its landing mode (HEARTBEAT: PX4 AUTO.LAND, ArduCopter
        LAND) or a landing (EXTENDED_SYS_STATE)."""
        ap = self.view.autopilot
        return ((ap is not None and self.view.custom_mode is not None
                 and ap.decode_mode(self.view.custom_mode) is ap.mode_for("LAND"))
                or self.view.landed_state == mavlink.MAV_LANDED_STATE_LANDING)

    def _stop(self, action: str) -> None:
        """React to a violation or an interruption (``Violation.action``)."""
        if self.finished:
            return
        if self._proc is not None:
            self._proc.close()
        self._waiting = None
        in_air = self.view.armed and self.phase in FLYING
        if action == "land" and in_air:
            self._proc = self._abort_land()
        elif action == "hold" and in_air:
            self._proc = self._abort_hold()
        elif action == "release" and self.view.armed:
            self._proc = self._release()
        elif self.phase == "landing" and self.view.armed and action != "end":
            self._proc = self._land()
        else:
            self._proc = None
            self._controlling = False
            self._finish()
            return
        self._drive()

    def _abort_land(self):
        yield from self._land()

    def _abort_hold(self):
        """The stack's hold mode (PX4 AUTO.LOITER, ArduCopter LOITER): the vehicle holds
        where it is under its own control; we let go."""
        self._controlling = False
        self.phase = "holding"
        self.monitor.landing(self.view.t_s)
        hold = self.view.autopilot.mode_for("LOITER").name
        yield from self._command(mavlink.MAV_CMD_DO_SET_MODE, self.view.autopilot.set_mode_params(hold),
                                 f"set {hold} (hold)", temp_retries=4)
        self._finish()

    def _release(self):
        """Somebody else flies the vehicle: stop commanding, watch until it is disarmed."""
        self._controlling = False
        self.phase = "released"
        self.monitor.landing(self.view.t_s)
        t_limit = self.view.t_s + self.cfg.landing_timeout_s
        yield lambda: not self.view.armed or self.view.t_s >= t_limit
        self._finish()

    def _attach(self):
        """The vehicle is already armed: refuse, land it, or resume the trajectory."""
        action = self.cfg.attach
        if action == "refuse":
            self.monitor.fail(self.view.t_s, "vehicle_not_ready",
                              "vehicle already armed at connection (use --attach resume|land)", "end")
            self._finish()
            return
        self.monitor.armed(self.view.t_s, self.view.custom_mode)
        if action == "land":
            self.monitor.fail(self.view.t_s, "attached", "attached to a flying vehicle and landed it", "land")
            self.phase = "hover"
            yield from self._land()
            return
        # resume: fly from where the vehicle is to the nearest way-point's
        # trajectory time, then on along the trajectory.
        import numpy as np

        self._window = TrajectoryWindow(self.inputs.trajectory, self.view.period_us * 1e-6, self.target)
        traj = self.inputs.trajectory
        wt = np.asarray(traj.waypoint_times_s, dtype=float)
        wp = np.asarray(traj.waypoint_targets[:, 0, :], dtype=float)
        from ..preflight import resume_index

        k = resume_index(wp, self.view.pos)
        if k is None or not math.isfinite(float(wt[k])):
            # no position (or a non-finite one): the nearest way-point is unknown
            self.monitor.fail(self.view.t_s, "attached", "attached to a flying vehicle whose position is not "
                              "finite: cannot resume, landed it", "land")
            self.phase = "hover"
            yield from self._land()
            return
        t_resume = float(wt[k])
        self.resumed_from_s = t_resume - traj.t0
        # the window starts at the resume time: a trajectory truncated in time
        self._window = TrajectoryWindow(_Shifted(traj, t_resume), self.view.period_us * 1e-6, self.target)
        self._hold_first = at_rest(self._window.first())
        self._hold_last = at_rest(self._window.last())
        self._preflight_ref = self._static_ref(self.view.pos)
        self.phase = "preflight"
        if not self._guard_before_flight(traj, t_resume):
            self.phase = "hover"
            yield from self._land()
            return
        t_ready = self.view.t_s + self.cfg.preflight_s
        yield lambda: self.view.t_s >= t_ready
        yield from self._set_offboard_mode()
        self.monitor.expect_mode(self.view.autopilot.custom_mode(self.view.autopilot.offboard_mode))
        self._schedule(self.view.t_s)
        if self.ctrl is not None:
            self.ctrl.reset()
        self.phase = "takeoff"
        yield lambda: self.phase == "landing"
        yield from self._land()

    def _finish(self) -> None:
        self._controlling = False
        self.finished = True
        self._proc = None
        self._waiting = None

    # --- what the procedure takes from the inbox (``companion.flight.inbox``) ----------------

    def _on_service_msg(self, m) -> None:
        """A command, mission or parameter answer: to the transaction under way."""
        if self._client is not None and self._proc is not None:
            self._emit_all(self._client.on_message(m, self.view.t_s))

    def _react(self, v: Violation) -> None:
        if v.action == "land":
            self._stop(self.cfg.on_failure)
        else:
            self._stop(v.action)

    def _on_imu(self, m) -> None:
        """One sensor frame: heartbeat, phase, reference, setpoints, the controller's
        answer (``ActuatorOut``), the recorder."""
        # The per-frame path (250 Hz, lockstep: the vehicle waits for our answer).
        vw = self.view
        t_us, t, gyro, acc, mag = vw.frame(m)
        hb = self._hb_t
        if hb is None or t - hb >= 1.0 or t < hb:
            self._hb_t = t
            self._emit(self.heartbeat())
        self._advance_phase(t)
        if self.replanner is not None and self.phase in ("hold", "trajectory", "hover", "divert"):
            self._replan_pose(t)
        ref = self._reference(t) if self.guard is None else self._guarded(t)
        cmd = None
        out = None
        if ref is not None:
            if t >= self._next_sp_t and not (self._rates and self._controlling):
                self._next_sp_t = t + self._sp_dt - 1e-9
                self._emit(codec.encode_set_position_target(
                    self.enc, t_us // 1000, ref.p, ref.v, ref.a, setpoint_yaw_enu(ref.s, ref.a), self.ts, self.tc))
            if self._controlling and vw.pos is not None:
                ctrl = self.ctrl
                tap = self.input_tap
                if tap is not None:
                    tap(t, gyro, acc, mag, vw.pos, vw.vel, vw.nav_t)
                try:
                    cmd = ctrl.command(t, Measurements(gyro, acc, mag, vw.pos, vw.vel, vw.nav_t),
                                       Reference(ref.p, ref.v, ref.a, ref.jerk, ref.snap, ref.target))
                    out = ctrl.last_desired
                    if self._rates:
                        # body rates and thrust before this frame's tick (which then carries no override)
                        self._emit(codec.encode_set_attitude_rates(
                            self.enc, t_us // 1000, ctrl.last_rate_cmd,
                            normalised_thrust(out[9], self.vehicle.mass_kg, self.hover_thrust), self.ts, self.tc))
                except (ValueError, ZeroDivisionError, OverflowError):
                    # a non-finite or degenerate measurement: let the vehicle fly this frame
                    self.n_control_faults += 1
        if cmd is None and self.ctrl is not None and vw.pos is not None and self.degraded is None:
            # Not flying the inner loop (yet): the observer still learns the gyro
            # bias and the fixes' noise, so control starts from a settled estimate.
            try:
                self.ctrl.observe(t, gyro, acc, mag, vw.pos, vw.vel, vw.nav_t)
            except (ValueError, ZeroDivisionError, OverflowError):
                self.n_control_faults += 1      # never out of the flight loop (the observer degrades itself)
        obs = self.ctrl.observer if self.ctrl is not None else None
        if obs is not None and obs.faults != self.observer_faults:
            self._observer_faults(obs.faults)
        self.outbox.append(ActuatorOut(t_us, None if self._rates else cmd, vw.armed))
        if ref is not None:
            self.recorder.record(t, self.phase, ref, out, self._t_traj)

    def _observer_faults(self, faults: dict) -> None:
        """Say on the wire, once per kind, that the observer skipped a measurement it could not use
        (``companion.control.observer``, "Degraded measurements"); keep the counts."""
        for kind, n in faults.items():
            if n and not self.observer_faults.get(kind):
                self._emit(self.enc.statustext_encode(mavlink.MAV_SEVERITY_NOTICE,
                                                      f"{OBSERVER_PREFIX}{OBSERVER_FAULT_TEXT[kind]}"[:50].encode()))
        self.observer_faults = dict(faults)

    # --- the reference, by phase ----------------------------------------------------------

    def _advance_phase(self, t: float) -> None:
        ph = self.phase
        if ph == "takeoff" and t >= self._t_hold:
            self.phase = ph = "hold"
        if ph == "hold" and t >= self._t_traj:
            self.phase = ph = "trajectory"
            if self.replanner is not None:
                self.replanner.start(self._t_traj)
                self._traj_deadline = replan_deadline(self._t_traj, self._window.duration_s)
        if ph == "trajectory" and t >= self._t_hover and self.replanner is None:
            self.phase = ph = "hover"
        if ph == "hover" and t >= self._t_land:
            self.phase = "landing"
            self._controlling = False

    def _reference(self, t: float) -> RefSample | None:
        ph = self.phase
        if ph == "trajectory":
            if self.replanner is not None:
                return self._replan_step(t)
            w = self._window
            return w.sample(int(round((t - self._t_traj) / w.dt_s)))
        if ph == "hold":
            return self._hold_first
        if ph == "hover":
            return self._hold_last
        if ph == "divert":
            # a moved landing (``_landing_spot``), the heading kept: a target far along the pointing
            if self._move is None:
                return self._static_ref(self.view.pos)
            t0, move, s = self._move
            p, v, a, j, sn = move.sample(t - t0)
            return RefSample(p, v, a, j, sn, s, (p[0] + 1e4 * s[0], p[1] + 1e4 * s[1], p[2] + 1e4 * s[2]))
        if ph == "takeoff":
            dt = t - self._t_arm
            p, v, a, j, s = segments_sample(self._segments, dt)
            # Turn the pointing direction smoothly from the heading at arming to
            # the trajectory's first pointing s0 and hand the controller a target
            # "at infinity" in that direction: the straight transfer may pass
            # through S_p itself, where pointing at it would flip the heading.
            sp = self._takeoff_pointing(dt)
            far = (p[0] + 1e4 * sp[0], p[1] + 1e4 * sp[1], p[2] + 1e4 * sp[2])
            return RefSample(p, v, a, j, s, sp, far)
        if ph == "preflight" and self._preflight_ref is not None:
            return self._preflight_ref
        return None

    # --- replanning (issue 8): the replanner flies the trajectory phase --------------------

    def _replan_pose(self, t: float) -> None:
        """The estimated pose of this frame for the rangefinder readings: the
        vehicle's ATTITUDE (its estimator's) while one came within
        ``ATTITUDE_LIVE_S``, carried to the frame's time with its body rates
        (readings wait for the measurements around their own time,
        ``replan.attitude_wait``); else the companion's observer while it
        flies the inner loop; else the raw vector pairs' rotation (never the
        truth); the last position carried with its velocity
        (``propagated_pose``). The vehicle's estimator first: on the realistic
        sensor profile its heading was within 4.1 deg of the truth where the
        observer's was off by up to 7.7 deg (8 deg just after take-off, whose
        phantoms the obstacle map keeps), and on the default profile both are
        within 0.7 deg (docs/replan.md "The attitude allowance"). Without
        either the raw pairs' degree of noise put returns from the rows off
        the rows."""
        if self.view.pos is None:
            return
        ctrl = self.ctrl
        est = ctrl.attitude_estimate() if self._controlling else None
        dt_R, w, att = 0.0, _Z3, None
        observer = est is not None and ctrl.observer is not None
        if self.view.R_est is not None and (t - self.view.att_t <= ATTITUDE_LIVE_S or not observer):
            R, dt_R, w = self.view.R_est, t - self.view.att_t, self.view.att_w
            att = (self.view.att_t, R, w)
        elif observer:
            R = est.R_enu_flu
        else:
            # no observer and no ATTITUDE: the rotation the two raw vector pairs
            # define (noisy: about a degree at the paper's noise)
            R = None if est is None else est.R_enu_flu
        if R is not None:
            p, R = propagated_pose(t - self.view.nav_t, self.view.pos, self.view.vel, dt_R, R, w)
            self.replanner.on_pose(t, p, R, att)

    def _replan_step(self, t: float) -> RefSample:
        rp = self.replanner
        pos = self.view.pos if self.view.pos is not None else self._hold_first.p
        vel = self.view.vel if self.view.vel is not None else _Z3
        st = rp.step(t, pos, vel)
        self.replan_mode = st.mode
        for e in st.events:
            self.replan_events += 1
            self._emit(self.enc.statustext_encode(mavlink.MAV_SEVERITY_NOTICE,
                                                  replan_text(e.action, e.obstacle_range_m, e.detail).encode()))
            if e.action in ("reroute", "rejoin"):
                # the deadline follows the plan being flown: a re-route may plan more than the
                # plan it replaces had left (the coverage left, round what blocks it), and the
                # timeout stopped such a plan being flown normally (obstacles-wide seed
                # 20261127, flight 10: 263 s after the start of a 45 s cut, 3 s before its end)
                self._traj_deadline = replan_deadline(t, rp.plan_end_s - t, self._traj_deadline)
        ref = st.ref
        if st.finished:
            # the (re)planned coverage is flown: hover at its end, then land
            self.phase = "hover"
            self._hold_last = at_rest(ref)
            self._t_hover = t
            self._t_land = t + self.cfg.hover_s
        elif st.hold:
            v = self.monitor.fail(t, "no_route", "replanner: no route around the obstacle, holding", "land",
                                  position_enu_m=[float(c) for c in pos])
            self._react(v)
        elif t > self._traj_deadline:
            v = self.monitor.fail(t, "replan_timeout",
                                  f"replanned trajectory not finished {t - self._t_traj:.0f} s after its start",
                                  "land", planned_s=self._window.duration_s)
            self._react(v)
        return ref

    # --- the guard (issue 15): one exit for every reference ---------------------------------

    def _guarded(self, t: float) -> RefSample | None:
        """This frame's reference through the guard (``companion.safety.gate``): a new
        trajectory of the replanner is checked whole, every sample in flight per frame;
        a refusal is answered by the gate's braked hover, then the flight stops
        (violation ``guard``, ``--on-failure``: a checked landing, or a hover)."""
        g = self.guard
        ph = self.phase
        if ph not in FLYING:
            return self._reference(t)
        if g.engaged:
            ref = g.dispose(t, None)[0]
            if g.at_rest and not self._guard_stopped:
                self._guard_stopped = True
                first = g.refusals[0] if g.refusals else {}
                self._react(self.monitor.fail(t, "guard", f"guard refused the {first.get('candidate', 'reference')}"
                                              f": {first.get('detail', '')}", "land"))
            return ref
        ref = self._reference(t)
        rp = self.replanner
        if rp is not None and self.phase == "trajectory" and rp.plan is not self._guard_plan:
            self._guard_plan = rp.plan
            v = g.check_trajectory(t, rp.plan.trajectory, t - self._t_traj + self._guard_tau0,
                                   getattr(rp.plan, "new_until_s", None))
            if not v.ok:
                self._guard_say(v)
                g.engage(t, ref)
                return g.brake(t)
        ref, v = g.dispose(t, ref, terrain=ph != "takeoff")
        if v is not None:
            self._guard_say(v)
        return ref

    def _guard_say(self, v) -> None:
        """Say a refusal on the wire, and give the mode its reason (a replanner with
        ``on_guard_refusal(verdict)`` gets the typed ``Verdict``)."""
        self._emit(self.enc.statustext_encode(mavlink.MAV_SEVERITY_WARNING,
                                              f"{GUARD_PREFIX}{v.detail}"[:50].encode()))
        hook = getattr(self.replanner, "on_guard_refusal", None)
        if hook is not None:
            hook(v)

    def _guard_before_flight(self, trajectory, t_from_s: float | None) -> bool:
        """The plan (from ``t_from_s``) and the take-off from here, checked before arming;
        False (the flight ends on the ground, violation ``guard``) when refused."""
        g = self.guard
        if g is None:
            return True
        v = g.check_trajectory(self.view.t_s, trajectory, t_from_s)
        if v.ok:
            first = self._hold_first.p
            v = g.check_takeoff(self.view.t_s, takeoff_segments(tuple(self.view.pos), first,
                                                                self.inputs.transit_floor_z_m,
                                                                self.cfg.climb_speed_m_s, self.cfg.transfer_speed_m_s))
        rp = self.replanner
        if rp is not None:
            self._guard_plan = rp.plan
            self._guard_tau0 = float(rp.plan.trajectory.t0)      # the replanner's clock (``Replanner.start``)
        if v.ok:
            return True
        self._guard_say(v)
        self.monitor.fail(self.view.t_s, "guard", f"guard refused the plan before arming: {v.detail}",
                          "land" if self.view.armed else "end")
        if not self.view.armed:
            self._finish()
        return False

    def _landing_spot(self):
        """(generator) True once the guard accepts a landing from where the vehicle is
        (``GuardGate.check_landing``). A refused landing is moved: the guard's braked hover
        brings the vehicle to rest, the gate finds the nearest spot whose landing and path it
        accepts (``companion.safety.divert``), the vehicle flies there (phase ``divert``,
        every frame disposed by the gate), settles, and the landing is checked again; at
        most ``LANDING_MOVES`` times. False (said on the wire, counted in report ``guard``):
        no spot found, or the companion does not steer the vehicle (attached, not in
        OFFBOARD): the vehicle hovers instead (AUTO.LOITER) and the flight is not completed."""
        g = self.guard
        if g is None or self.view.pos is None or not self.view.armed:
            return True
        moves = 0
        while True:
            v = g.check_landing(self.view.t_s, self.view.pos, self.view.vel if self.view.vel is not None else _Z3)
            if v.ok:
                return True
            self._guard_say(v)
            if not self._steering or moves >= LANDING_MOVES:
                break
            moves += 1
            # to rest on the guard's braked hover (the gate ends no flight for it: we land)
            self._guard_stopped = True
            if not g.engaged:
                g.engage(self.view.t_s, self._static_ref(self.view.pos))
            self._move = None
            self.phase = "divert"
            self._controlling = self.cfg.control in ("companion", "rates") and self.degraded is None
            t_limit = self.view.t_s + self.cfg.landing_timeout_s
            yield lambda: g.at_rest or self.view.t_s >= t_limit
            if not g.at_rest:
                break
            steps = g.find_landing(self.view.t_s, g.hold_point, self._launch, self.inputs.transit_floor_z_m,
                                   self.cfg.climb_speed_m_s, self.cfg.transfer_speed_m_s)
            while True:               # a few candidates a frame, hovering meanwhile
                try:
                    next(steps)
                except StopIteration as done:
                    d = done.value
                    break
                t_frame = self.view.t_s
                yield lambda: self.view.t_s > t_frame
            if d is None:
                break
            self._emit(self.enc.statustext_encode(
                mavlink.MAV_SEVERITY_WARNING,
                f"{GUARD_PREFIX}landing moved {d.path_m:.2f} m ({d.kind})"[:50].encode()))
            s = g.brake(self.view.t_s).s
            g.release(self.view.t_s)
            self._move = (self.view.t_s, d, s)
            t_end = self.view.t_s + d.duration_s
            yield lambda: g.engaged or self.view.t_s >= t_end
            t_hover = self.view.t_s + self.cfg.hover_s
            t_settle = t_hover + MOVE_SETTLE_S

            def settled() -> bool:
                if g.engaged or self.view.t_s >= t_settle:
                    return True
                w, r = self.view.vel, self.view.att_w
                return (self.view.t_s >= t_hover and w is not None and math.hypot(*w) <= MOVE_REST_M_S
                        and math.hypot(*r) <= MOVE_REST_RAD_S)
            yield settled
        self.monitor.fail(self.view.t_s, "guard", v.detail, "hold")
        return False

    def _takeoff_pointing(self, dt: float) -> tuple:
        s0 = self._hold_first.s
        T = self._takeoff_T
        sig = smooth_segment((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), T, dt)[0][0]
        psi = self._psi_arm + sig * self._dpsi
        h = math.sqrt(max(0.0, 1.0 - (sig * s0[2]) ** 2))
        return (h * math.cos(psi), h * math.sin(psi), sig * s0[2])

    def _static_ref(self, p) -> RefSample:
        p = tuple(float(c) for c in p)
        return RefSample(p, _Z3, _Z3, _Z3, _Z3, pointing_at(p, self.target))

class _Shifted:
    """A trajectory seen from ``t_start`` on (for resuming mid-flight)."""

    def __init__(self, traj, t_start: float) -> None:
        self._traj = traj
        self.t0 = float(t_start)
        self.tf = float(traj.tf)

    def sample(self, times):
        return self._traj.sample(times)
