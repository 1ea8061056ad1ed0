"""Flight metrics from a recording alone (no mission, no re-run): pure and streaming.

``MetricsAccumulator`` is fed the decoded messages of a .tlog in order
(``vehicle(msg)`` for the vehicle's, ``companion(msg)`` for the companion's)
and holds a few running sums whatever the flight's length; ``result()``
gives the ``FlightMetrics``. It works on any MAVLink log with the vehicle's
usual telemetry (a companion flight, or a foreign log of vehicle messages
only, e.g. MAVProxy's).

Time is the vehicle's (the messages' own ``time_usec``/``time_boot_ms``), not
the .tlog stamps: a foreign logger stamps by its wall clock, which does not
run at the vehicle's rate in a lockstep simulation. A step of the vehicle
clock backwards by more than 1 s or forwards by more than
``MAX_CLOCK_STEP_S`` (a reboot, a gap) is counted in ``clock_jumps`` and not
integrated.

Sources, best first (``position_source``):

- ``sim_truth``: ODOMETRY, which the bundled SITL fills with its true state
  (the same source the flight report uses);
- ``estimate:LOCAL_POSITION_NED``: the vehicle's local position;
- ``estimate:GLOBAL_POSITION_INT``: the vehicle's global position (1e-7 deg,
  mm), put in the local frame through HOME_POSITION when the log has one
  (otherwise distances only, about the first fix).

The reference (``reference_source``) is the companion's recorded
SET_POSITION_TARGET_LOCAL_NED, else the vehicle's POSITION_TARGET_LOCAL_NED
echo. Tracking error = |position - reference| at each reference sample
(the position sample of the same vehicle time; a sample up to 0.25 s older is
carried forward with its velocity), in the window: EXTENDED_SYS_STATE
IN_AIR (not TAKEOFF nor LANDING; armed when the log has no landed state),
from ``settle_s`` after lift-off. The window is wider than the flight
report's (the trajectory phase only, which the recording does not mark): the
end of the climb, the hold and the hover count here. The minimum clearance
(non-downward DISTANCE_SENSOR) is taken over the same window. Flight time: time with EXTENDED_SYS_STATE in air
(``landed_state`` IN_AIR, TAKEOFF or LANDING), else armed time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from mavcore.autopilot import from_heartbeat

from mavcore import frames
from ..flight.core import PHASE_CODE
from ..flight.log import ErrorStats, FlightLog
from ..flight.setup_record import SETUP_TEXT_ID
from mavcore import codec

#: STATUSTEXT prefix of the companion's replanning announcements (issue 8's replanner).
REPLAN_PREFIX = "companion: replan"
#: Clock steps (s) beyond this are gaps, not flight.
MAX_CLOCK_STEP_S = 10.0
#: A position sample this much older than the reference (s) is not used.
MAX_PAIR_AGE_S = 0.25
#: Bounded lists in the result.
MAX_EVENTS = 200

_IN_AIR = (mavlink.MAV_LANDED_STATE_IN_AIR, mavlink.MAV_LANDED_STATE_TAKEOFF, mavlink.MAV_LANDED_STATE_LANDING)
_ARMED = mavlink.MAV_MODE_FLAG_SAFETY_ARMED
_DOWN = mavlink.MAV_SENSOR_ROTATION_PITCH_270
_NAN3 = (math.nan,) * 3
_NAN9 = (math.nan,) * 9
_NAN10 = (math.nan,) * 10
_SOURCES = ("sim_truth", "estimate:LOCAL_POSITION_NED", "estimate:GLOBAL_POSITION_INT")


@dataclass(frozen=True)
class ModeChange:
    """The vehicle's mode or armed state changed (HEARTBEAT) at vehicle time ``t_s``."""

    t_s: float | None
    mode: str
    armed: bool

    def to_dict(self) -> dict:
        return {"t_s": self.t_s, "mode": self.mode, "armed": self.armed}


@dataclass(frozen=True)
class TextEvent:
    """A STATUSTEXT at vehicle time ``t_s`` (``source``: "vehicle" or "companion")."""

    t_s: float | None
    source: str
    severity: int
    text: str

    def to_dict(self) -> dict:
        return {"t_s": self.t_s, "source": self.source, "severity": self.severity, "text": self.text}


@dataclass(frozen=True)
class TrackingMetrics:
    """Position error against the recorded reference (see the module docstring).

    Attributes
    ----------
    max_error_m, rms_error_m : float or None
        None without samples.
    n_samples : int
    settle_s : float
        Seconds after lift-off before samples count.
    position_source : str or None
        Where the position came from (``sim_truth`` or ``estimate:...``).
    reference_source : str or None
        ``companion setpoints`` or ``vehicle setpoint echo``; None: no reference recorded.
    estimated : bool
        The position is the vehicle's estimate, not truth.
    """

    max_error_m: float | None
    rms_error_m: float | None
    n_samples: int
    settle_s: float
    position_source: str | None
    reference_source: str | None
    estimated: bool

    def to_dict(self) -> dict:
        return {"max_error_m": self.max_error_m, "rms_error_m": self.rms_error_m, "n_samples": self.n_samples,
                "settle_s": self.settle_s, "position_source": self.position_source,
                "reference_source": self.reference_source, "estimated": self.estimated}


@dataclass(frozen=True)
class FlightMetrics:
    """What a recording says about its flight (vehicle time, SI units).

    Attributes
    ----------
    duration_s : float
        First to last sensor frame (HIGHRES_IMU), like the report's ``sim_time_s``
        (gaps over ``MAX_CLOCK_STEP_S`` and clock jumps left out); first to last
        timed message when the log has no HIGHRES_IMU.
    n_frames : int
        HIGHRES_IMU messages.
    flight_time_s : float
        Time in the air (``flight_time_source``: ``landed_state`` or ``armed``).
    flight_time_source : str or None
    armed_time_s : float
    time_in_mode_s : dict
        Vehicle time per mode name (the stack's, ``mavcore.autopilot``).
    mode_changes : tuple of ModeChange
        The first ``MAX_EVENTS`` changes of mode or armed state.
    distance_m, horizontal_distance_m : float or None
        Path length from ``position_source`` over the whole recording.
    position_source : str or None
    estimated : bool
        Distances and tracking come from the vehicle's estimate.
    tracking : TrackingMetrics
    min_clearance_m : float or None
        Smallest valid non-downward DISTANCE_SENSOR reading in the window.
    replanning_events : int
        Companion STATUSTEXTs starting with ``REPLAN_PREFIX``.
    events : tuple of TextEvent
        STATUSTEXTs of the vehicle and of the companion (its setup record left
        out), the first ``MAX_EVENTS``.
    n_vehicle_messages, n_companion_messages : int
    clock_jumps : int
    """

    duration_s: float
    n_frames: int
    flight_time_s: float
    flight_time_source: str | None
    armed_time_s: float
    time_in_mode_s: dict
    mode_changes: tuple
    distance_m: float | None
    horizontal_distance_m: float | None
    position_source: str | None
    estimated: bool
    tracking: TrackingMetrics
    min_clearance_m: float | None
    replanning_events: int
    events: tuple
    n_vehicle_messages: int
    n_companion_messages: int
    clock_jumps: int

    def to_dict(self) -> dict:
        return {
            "duration_s": self.duration_s, "n_frames": self.n_frames, "flight_time_s": self.flight_time_s,
            "flight_time_source": self.flight_time_source, "armed_time_s": self.armed_time_s,
            "time_in_mode_s": dict(self.time_in_mode_s), "mode_changes": [m.to_dict() for m in self.mode_changes],
            "distance_m": self.distance_m, "horizontal_distance_m": self.horizontal_distance_m,
            "position_source": self.position_source, "estimated": self.estimated,
            "tracking": self.tracking.to_dict(), "min_clearance_m": self.min_clearance_m,
            "replanning_events": self.replanning_events, "events": [e.to_dict() for e in self.events],
            "n_vehicle_messages": self.n_vehicle_messages, "n_companion_messages": self.n_companion_messages,
            "clock_jumps": self.clock_jumps,
        }


class _Track:
    """One position source: latest sample, path length, tracking error."""

    __slots__ = ("t", "p", "v", "dist", "hdist", "n", "errors")

    def __init__(self, settle_s: float) -> None:
        self.t = None
        self.p = None
        self.v = None
        self.dist = 0.0
        self.hdist = 0.0
        self.n = 0
        self.errors = ErrorStats(settle_s)

    def add(self, t: float, p: tuple, v: tuple) -> None:
        q = self.p
        if q is not None:
            dx, dy, dz = p[0] - q[0], p[1] - q[1], p[2] - q[2]
            h = dx * dx + dy * dy
            self.hdist += math.sqrt(h)
            self.dist += math.sqrt(h + dz * dz)
        self.t, self.p, self.v = t, p, v
        self.n += 1

    def at(self, t: float):
        """The position at ``t`` (the latest sample, carried forward with its velocity), or None."""
        if self.p is None or self.t is None:
            return None
        dt = t - self.t
        if abs(dt) <= 0.002 or self.v is None:
            return self.p if abs(dt) <= MAX_PAIR_AGE_S else None
        if not -0.002 <= dt <= MAX_PAIR_AGE_S:
            return None
        p, v = self.p, self.v
        return (p[0] + v[0] * dt, p[1] + v[1] * dt, p[2] + v[2] * dt)


class MetricsAccumulator:
    """Streaming ``FlightMetrics`` (module docstring).

    Parameters
    ----------
    settle_s : float
        Tracking samples count from this long after lift-off (s).
    log : FlightLog or None
        When given, one row per reference sample is offered to it (for the
        figures of ``companion.flight_plot``; desired attitude unknown: NaN).
    vehicle_component : int
        The autopilot's component id (HEARTBEATs of other components are not the vehicle's).
    """

    def __init__(self, settle_s: float = 5.0, log: FlightLog | None = None, vehicle_component: int = 1) -> None:
        self.settle_s = float(settle_s)
        self.log = log
        self.vcomp = int(vehicle_component)
        self.t = None                 # the vehicle clock (s)
        self.clock_jumps = 0
        self.t_imu_last = None
        self.frames_s = 0.0           # sensor-frame time flown (gaps and clock jumps left out)
        self.t_first = None
        self.n_frames = 0
        self.n_vehicle = self.n_companion = 0
        self.armed = False
        self.mode = None
        self.landed = None            # EXTENDED_SYS_STATE landed_state, None until seen
        self.t_air = None             # first lift-off (vehicle time)
        self.flight_s = self.armed_s = 0.0
        self.time_in_mode: dict = {}
        self.mode_changes: list = []
        self.events: list = []
        self.n_replan = 0
        self.min_clearance = None
        self.tracks = {s: _Track(self.settle_s) for s in _SOURCES}
        self._odom = None             # the latest ODOMETRY (decoded for the log rows only)
        self._att = None              # the latest ATTITUDE's R (tuple of 9)
        self._home_geo = None         # geodetic pose of the local origin (from HOME_POSITION)
        self._gpos_origin = None      # the first fix (the frame of the distances until HOME_POSITION)
        self._gpos_geo = None
        self._ref_source = None
        M = mavlink
        self._handlers = {
            M.MAVLINK_MSG_ID_HIGHRES_IMU: self._imu,
            M.MAVLINK_MSG_ID_RAW_IMU: self._imu,           # ArduCopter's sensor frame
            M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self._lpos,
            M.MAVLINK_MSG_ID_ODOMETRY: self._odometry,
            M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self._gpos,
            M.MAVLINK_MSG_ID_HEARTBEAT: self._heartbeat,
            M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: self._ext_state,
            M.MAVLINK_MSG_ID_DISTANCE_SENSOR: self._distance,
            M.MAVLINK_MSG_ID_STATUSTEXT: self._vehicle_text,
            M.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: self._echo,
            M.MAVLINK_MSG_ID_HOME_POSITION: self._home,
            M.MAVLINK_MSG_ID_ATTITUDE: self._attitude,
        }

    #: Vehicle message ids the metrics read (others need not be decoded).
    MSG_IDS = frozenset((mavlink.MAVLINK_MSG_ID_HIGHRES_IMU, mavlink.MAVLINK_MSG_ID_RAW_IMU,
                         mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                         mavlink.MAVLINK_MSG_ID_ODOMETRY, mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
                         mavlink.MAVLINK_MSG_ID_HEARTBEAT, mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                         mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR, mavlink.MAVLINK_MSG_ID_STATUSTEXT,
                         mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED, mavlink.MAVLINK_MSG_ID_HOME_POSITION,
                         mavlink.MAVLINK_MSG_ID_ATTITUDE))

    # --- the clock ------------------------------------------------------------------

    def _clock(self, t: float) -> None:
        last = self.t
        if last is None:
            self.t = self.t_first = t
            return
        dt = t - last
        if dt <= 0.0:
            if dt < -1.0:
                self.clock_jumps += 1
                self.t = t
            return
        self.t = t
        if dt > MAX_CLOCK_STEP_S:
            self.clock_jumps += 1
            return
        if self.armed:
            self.armed_s += dt
        if self._in_air():
            self.flight_s += dt
        m = self.mode
        if m is not None:
            self.time_in_mode[m] = self.time_in_mode.get(m, 0.0) + dt

    def _in_air(self) -> bool:
        return self.landed in _IN_AIR if self.landed is not None else self.armed

    def _settled(self, t: float) -> bool:
        """Inside the metrics' window: in the air (not taking off or landing), ``settle_s`` after lift-off."""
        flying = self.landed == mavlink.MAV_LANDED_STATE_IN_AIR if self.landed is not None else self.armed
        return flying and self.t_air is not None and t >= self.t_air + self.settle_s

    # --- vehicle messages --------------------------------------------------------------

    def vehicle(self, msg, msgid: int | None = None) -> None:
        """One message of the vehicle (any component of its system); ``msgid``
        when the caller knows it. Every vehicle message counts; only ``MSG_IDS`` are read."""
        self.n_vehicle += 1
        h = self._handlers.get(msg.get_msgId() if msgid is None else msgid)
        if h is not None:
            h(msg)

    def count_vehicle(self) -> None:
        """A vehicle message not decoded (not in ``MSG_IDS``)."""
        self.n_vehicle += 1

    def _imu(self, m) -> None:
        t = m.time_usec * 1e-6
        self._clock(t)
        last = self.t_imu_last
        if last is not None and 0.0 < t - last <= MAX_CLOCK_STEP_S:
            self.frames_s += t - last
        self.t_imu_last = t
        self.n_frames += 1

    def _lpos(self, m) -> None:
        t = m.time_boot_ms * 1e-3
        if not self.n_frames:          # the sensor frames (HIGHRES_IMU) carry the clock when there are any
            self._clock(t)
        # NED -> ENU (codec.decode_local_position_ned, inlined: 250 Hz)
        self.tracks["estimate:LOCAL_POSITION_NED"].add(t, (m.y, m.x, -m.z), (m.vy, m.vx, -m.vz))

    def _odometry(self, m) -> None:
        if m.get_srcComponent() != self.vcomp:
            return
        t = m.time_usec * 1e-6
        if not self.n_frames:
            self._clock(t)
        self._odom = m
        self.tracks["sim_truth"].add(t, (m.y, m.x, -m.z), None)    # NED -> ENU (codec.decode_odometry_pose)

    def _gpos(self, m) -> None:
        g = codec.decode_global_position_int(m)
        t = g.time_boot_ms * 1e-3
        if not self.n_frames:
            self._clock(t)
        geo = (g.lat_deg, g.lon_deg, g.alt_m)
        if self._gpos_origin is None:
            self._gpos_origin = geo
        self._gpos_geo = geo
        self.tracks["estimate:GLOBAL_POSITION_INT"].add(t, self._gpos_local(geo), g.vel_enu_m_s)

    def _gpos_local(self, geo) -> tuple:
        """ENU (m) of a geodetic fix: about the local origin once HOME_POSITION gave it, else the first fix."""
        origin = self._home_geo if self._home_geo is not None else self._gpos_origin
        return tuple(float(c) for c in frames.geodetic2enu(*geo, *origin))

    def _home(self, m) -> None:
        if self._home_geo is not None:
            return
        # The local origin is the geodetic point the home's local offset away from the home.
        h = codec.decode_home_position(m)
        x, y, z = h.pos_enu_m
        self._home_geo = tuple(float(c) for c in frames.enu2geodetic(-x, -y, -z, h.lat_deg, h.lon_deg, h.alt_m))
        tr = self.tracks["estimate:GLOBAL_POSITION_INT"]
        if tr.p is not None:   # the next step is measured in the new frame
            tr.p = self._gpos_local(self._gpos_geo)

    def _attitude(self, m) -> None:
        if not self.n_frames:
            self._clock(m.time_boot_ms * 1e-3)
        self._att = tuple(codec.decode_attitude(m).R_enu_flu.ravel().tolist())

    def _heartbeat(self, m) -> None:
        if m.get_srcComponent() != self.vcomp or m.autopilot == mavlink.MAV_AUTOPILOT_INVALID:
            return
        armed = bool(m.base_mode & _ARMED)
        ap = from_heartbeat(m.autopilot)      # the stack's own mode names (PX4, ArduCopter)
        mode = ap.mode_name(m.custom_mode) if ap is not None else f"MODE({int(m.custom_mode)})"
        if mode != self.mode or armed != self.armed:
            if len(self.mode_changes) < MAX_EVENTS:
                self.mode_changes.append(ModeChange(self.t, mode, armed))
            self.mode = mode
            self.armed = armed
        if self.landed is None and armed:
            self._lift_off()

    def _ext_state(self, m) -> None:
        self.landed = int(m.landed_state)
        if self.landed in _IN_AIR:
            self._lift_off()

    def _lift_off(self) -> None:
        """The first time in the air: tracking samples count from ``settle_s`` later."""
        if self.t_air is None and self.t is not None:
            self.t_air = self.t
            for tr in self.tracks.values():
                tr.errors.start(self.t)

    def _distance(self, m) -> None:
        if not self.n_frames:
            self._clock(m.time_boot_ms * 1e-3)
        if m.orientation == _DOWN or self.t is None or not self._settled(self.t):
            return
        r = codec.decode_distance_sensor(m).distance_m
        if math.isfinite(r) and (self.min_clearance is None or r < self.min_clearance):
            self.min_clearance = r

    def _vehicle_text(self, m) -> None:
        self._text("vehicle", m)

    def _text(self, source: str, m) -> None:
        if len(self.events) < MAX_EVENTS:
            self.events.append(TextEvent(self.t, source, int(m.severity), str(m.text)))

    def _echo(self, m) -> None:
        if self._ref_source == "companion setpoints":
            return
        self._ref_source = "vehicle setpoint echo"
        self._reference(m)

    # --- companion messages ------------------------------------------------------------

    def companion(self, msg) -> None:
        """One message the companion sent (decoded; only setpoints and STATUSTEXT are read)."""
        self.n_companion += 1
        k = msg.get_type()
        if k == "SET_POSITION_TARGET_LOCAL_NED":
            self._ref_source = "companion setpoints"
            self._reference(msg)
        elif k == "STATUSTEXT":
            if getattr(msg, "id", 0) == SETUP_TEXT_ID:
                return
            text = str(msg.text)
            if text.startswith(REPLAN_PREFIX):
                self.n_replan += 1
            self._text("companion", msg)

    def count_companion(self) -> None:
        """A companion message that is not decoded (actuator commands, heartbeats, ...)."""
        self.n_companion += 1

    def _reference(self, m) -> None:
        t = m.time_boot_ms * 1e-3
        p_ref = (m.y, m.x, -m.z)       # NED -> ENU (codec.decode_position_target_local_ned, inlined)
        in_air = self._in_air()
        if self._settled(t) and all(math.isfinite(c) for c in p_ref):
            for s, tr in self.tracks.items():
                if s == "estimate:GLOBAL_POSITION_INT" and self._home_geo is None:
                    continue   # about the first fix, not the local frame of the reference
                p = tr.at(t)
                if p is not None:
                    tr.errors.add(t, math.sqrt((p[0] - p_ref[0]) ** 2 + (p[1] - p_ref[1]) ** 2
                                               + (p[2] - p_ref[2]) ** 2))
        log = self.log
        if log is not None:
            if log.wants():
                self._log_row(t, p_ref, in_air)
            else:
                log.n_offered += 1

    def _log_row(self, t: float, p_ref: tuple, in_air: bool) -> None:
        truth = self.tracks["sim_truth"].at(t)
        est = self.tracks["estimate:LOCAL_POSITION_NED"].at(t)
        R = self._att
        if self._odom is not None:
            R = codec.decode_odometry_pose(self._odom)[1]
        phase = PHASE_CODE["trajectory" if self._settled(t) else ("takeoff" if in_air else "preflight")]
        self.log.append((t, phase), p_ref, truth or est or _NAN3, est or _NAN3, R or _NAN9, _NAN10, _NAN3)

    # --- the result ------------------------------------------------------------------------

    def result(self) -> FlightMetrics:
        best = next((s for s in _SOURCES if self.tracks[s].n >= 2), None)
        track_src = next((s for s in _SOURCES if self.tracks[s].errors.n > 0), None)
        es = self.tracks[track_src].errors if track_src is not None else None
        tracking = TrackingMetrics(
            max_error_m=None if es is None else es.max_m,
            rms_error_m=None if es is None else es.rms_m,
            n_samples=0 if es is None else es.n,
            settle_s=self.settle_s,
            position_source=track_src,
            reference_source=self._ref_source,
            estimated=track_src is not None and track_src != "sim_truth",
        )
        if self.n_frames:
            duration = self.frames_s
        else:
            duration = (self.t - self.t_first) if self.t is not None else 0.0
        bt = self.tracks[best] if best is not None else None
        return FlightMetrics(
            duration_s=float(duration),
            n_frames=self.n_frames,
            flight_time_s=self.flight_s,
            flight_time_source=("landed_state" if self.landed is not None
                                else ("armed" if self.mode_changes else None)),
            armed_time_s=self.armed_s,
            time_in_mode_s=dict(self.time_in_mode),
            mode_changes=tuple(self.mode_changes),
            distance_m=None if bt is None else bt.dist,
            horizontal_distance_m=None if bt is None else bt.hdist,
            position_source=best,
            estimated=best is not None and best != "sim_truth",
            tracking=tracking,
            min_clearance_m=self.min_clearance,
            replanning_events=self.n_replan,
            events=tuple(self.events),
            n_vehicle_messages=self.n_vehicle,
            n_companion_messages=self.n_companion,
            clock_jumps=self.clock_jumps,
        )
