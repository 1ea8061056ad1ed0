"""The mission runner: fly a planned trajectory against a MAVLink vehicle.

Sequence (every time is the vehicle's, from HIGHRES_IMU ``time_usec``)::

    connect    send heartbeats until the vehicle's HEARTBEAT (1/1) arrives
    setup      learn the sensor period from two HIGHRES_IMU frames; request
               LOCAL_POSITION_NED (and the SITL's ground-truth ODOMETRY) at
               every frame with MAV_CMD_SET_MESSAGE_INTERVAL
    upload     the way-points as a MAVLink mission (MISSION_INT protocol)
    preflight  stream setpoints (hold where the vehicle is) for ``preflight_s``
               (PX4 only enters OFFBOARD with a setpoint stream present);
               DO_SET_MODE OFFBOARD, ARM
    takeoff    smooth segments (7th-order, C3 smoothstep): a vertical climb
               from the ground position to the height of the trajectory's
               first point, then a level transfer to that point (the vehicle
               may start anywhere free); launched within
               ``LAUNCH_TOLERANCE_M`` of the first point (``companion demo``
               sets it down there), just the climb to that point
    hold       hover there ``hold_s`` (the takeoff transient dies out)
    trajectory the planned trajectory
    hover      ``hover_s`` at its last point
    landing    NAV_LAND: the vehicle's own controller descends; it disarms
               itself once landed (or we send ARM_DISARM(0))

Setpoints (SET_POSITION_TARGET_LOCAL_NED: position, velocity, acceleration,
yaw from the pointing direction) are streamed at ``setpoint_hz`` of vehicle
time from preflight to landing, in both control modes.

``control="companion"``: every HIGHRES_IMU is answered by the geometric
controller's motor commands in HIL_ACTUATOR_CONTROLS (lockstep flag set,
``time_usec`` echoed). Before arming and during the landing the answer is a
tick with four NaN (the vehicle's own controller flies), so the whole run is
in lockstep and deterministic. ``control="vehicle"``: only NaN ticks; the
vehicle's controller tracks the setpoints.

Tracking error: the position reported by the vehicle's ground truth (the
bundled SITL's ODOMETRY, see ``companion.link.codec.decode_odometry``), or,
when the vehicle refuses to send it, LOCAL_POSITION_NED (then the report
says ``truth_source: estimate``), minus the reference at the same vehicle time.

Pure helpers (``smooth_segment``, ``setpoint_yaw_enu``) come first; the
``MissionRunner`` shell does the I/O.
"""

from __future__ import annotations

import math
import os
import time
from array import array
from dataclasses import dataclass, field

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from .control.geometric import GeometricController
from .errors import CommandRejected, LinkError
from .link import codec
from .link.connection import Connection
from .link.mission_upload import upload_mission
from .progress import Progress
from .report import FlightReport, ReplanningStats, tracking_stats
from .vehicle import GRAVITY_M_S2, VehicleConfig

PHASES = ("connect", "setup", "upload", "preflight", "takeoff", "hold", "trajectory", "hover", "landing", "done")
_PHASE_CODE = {p: i for i, p in enumerate(PHASES)}

_SENSOR_DOWN = mavlink.MAV_SENSOR_ROTATION_PITCH_270

#: A vehicle armed within this horizontal distance (m) of the trajectory's
#: first point climbs straight to it (no separate level transfer).
LAUNCH_TOLERANCE_M = 0.05

#: Streams the runner never reads (muted by ``companion demo``).
UNUSED_STREAMS = (mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
                  mavlink.MAVLINK_MSG_ID_GPS_RAW_INT, mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED)


# --- pure helpers ------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RefSample:
    """A reference sample: position and its four derivatives (ENU) and the pointing direction.

    ``p`` m, ``v`` m/s, ``a`` m/s^2, ``jerk`` m/s^3, ``snap`` m/s^4, ``s``
    unit pointing vector (eq. 21); all float tuples (3,). ``target``: the
    pointing target S_p handed to the controller (None: the mission's).
    """

    p: tuple
    v: tuple
    a: tuple
    jerk: tuple
    snap: tuple
    s: tuple
    target: tuple | None = None


def smooth_segment(p0, p1, duration_s: float, t_s: float):
    """Rest-to-rest segment from ``p0`` to ``p1`` (ENU, m) in ``duration_s``.

    The 7th-order smoothstep ``sigma(tau) = 35 tau^4 - 84 tau^5 + 70 tau^6 -
    20 tau^7`` has zero velocity, acceleration and jerk at both ends, so the
    controller's feed-forward (which uses jerk and snap, eq. 31) is
    continuous into and out of the segment. Peak speed ``35/16 |p1 - p0| /
    duration_s`` at mid-time.

    Returns
    -------
    (p, v, a, jerk, snap) : five float tuples (3,), ENU SI units, at ``t_s``
    (clamped to [0, duration_s]).
    """
    T = float(duration_s)
    tau = min(max(t_s / T, 0.0), 1.0)
    t2, t3 = tau * tau, tau * tau * tau
    t4 = t2 * t2
    s0 = t4 * (35.0 - 84.0 * tau + 70.0 * t2 - 20.0 * t3)
    s1 = t3 * (140.0 - 420.0 * tau + 420.0 * t2 - 140.0 * t3) / T
    s2 = t2 * (420.0 - 1680.0 * tau + 2100.0 * t2 - 840.0 * t3) / T ** 2
    s3 = tau * (840.0 - 5040.0 * tau + 8400.0 * t2 - 4200.0 * t3) / T ** 3
    s4 = (840.0 - 10080.0 * tau + 25200.0 * t2 - 16800.0 * t3) / T ** 4
    d = (p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2])
    return (
        (p0[0] + s0 * d[0], p0[1] + s0 * d[1], p0[2] + s0 * d[2]),
        (s1 * d[0], s1 * d[1], s1 * d[2]),
        (s2 * d[0], s2 * d[1], s2 * d[2]),
        (s3 * d[0], s3 * d[1], s3 * d[2]),
        (s4 * d[0], s4 * d[1], s4 * d[2]),
    )


def pointing_at(p, target) -> tuple:
    """Unit vector from ``p`` toward ``target`` (eq. 21), ENU; +y if they coincide."""
    u = (target[0] - p[0], target[1] - p[1], target[2] - p[2])
    n = math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
    return (0.0, 1.0, 0.0) if n < 1e-9 else (u[0] / n, u[1] / n, u[2] / n)


def setpoint_yaw_enu(s, a_enu_m_s2, gravity_m_s2: float = GRAVITY_M_S2) -> float:
    """Heading (ENU, rad from east, CCW) of the body x axis the controller would command.

    With ``b3d`` the feed-forward thrust direction ``unit(a + g e3)``,
    ``b2d = unit(s - (s.b3d) b3d)`` (eq. 22) and ``b1d = b2d x b3d``; the yaw
    is the heading of ``b1d``. Pointing straight along b3d falls back to
    the heading of +y (b1d = east).
    """
    b3 = (a_enu_m_s2[0], a_enu_m_s2[1], a_enu_m_s2[2] + gravity_m_s2)
    n = math.sqrt(b3[0] ** 2 + b3[1] ** 2 + b3[2] ** 2)
    b3 = (b3[0] / n, b3[1] / n, b3[2] / n)
    c = s[0] * b3[0] + s[1] * b3[1] + s[2] * b3[2]
    b2 = (s[0] - c * b3[0], s[1] - c * b3[1], s[2] - c * b3[2])
    if b2[0] ** 2 + b2[1] ** 2 + b2[2] ** 2 < 1e-12:
        return 0.0
    b1 = (b2[1] * b3[2] - b2[2] * b3[1], b2[2] * b3[0] - b2[0] * b3[2], b2[0] * b3[1] - b2[1] * b3[0])
    return math.atan2(b1[1], b1[0])


def climb_duration_s(distance_m: float, speed_m_s: float, min_s: float = 3.0) -> float:
    """Duration of a smooth segment whose peak speed (35/16 of the mean) is ``speed_m_s``."""
    return max(min_s, 35.0 / 16.0 * distance_m / speed_m_s)


# --- configuration and results ---------------------------------------------------------


@dataclass(frozen=True)
class RunnerConfig:
    """How the runner flies (vehicle-clock seconds unless said otherwise).

    Attributes
    ----------
    control : str
        "companion" (geometric controller answers each frame) or "vehicle".
    setpoint_hz : float
        SET_POSITION_TARGET_LOCAL_NED rate (>= 20 Hz as PX4 requires).
    preflight_s : float
        Setpoint streaming before OFFBOARD is requested.
    climb_speed_m_s : float
        Peak speed of the vertical climb.
    transfer_speed_m_s : float
        Peak speed of the level transfer to the first point.
    hold_s, hover_s : float
        Hover before and after the trajectory.
    settle_s : float
        Tracking errors count from ``settle_s`` after the trajectory start.
    landing_timeout_s : float
        Vehicle time allowed for landing and disarming.
    link_timeout_s : float
        Wall-clock seconds without any message before ``LinkError``.
    request_truth : bool
        Ask the vehicle for its ground-truth ODOMETRY every frame.
    mute_streams : tuple of int
        Message ids to switch off (interval -1) at setup: telemetry the
        runner does not use, to save both sides the encoding and parsing
        (the demo mutes ATTITUDE_QUATERNION, GLOBAL_POSITION_INT, ...; leave
        empty when a ground station shares the vehicle's streams).
    spin_us : float
        Busy-poll this long (microseconds) for the vehicle's next frame
        before sleeping in the kernel (``Connection.spin_s``); used only on
        a machine with two or more cores, where the vehicle runs on another.
    """

    control: str = "companion"
    setpoint_hz: float = 50.0
    preflight_s: float = 1.0
    climb_speed_m_s: float = 1.0
    transfer_speed_m_s: float = 3.0
    hold_s: float = 1.0
    hover_s: float = 1.0
    settle_s: float = 5.0
    landing_timeout_s: float = 30.0
    link_timeout_s: float = 10.0
    request_truth: bool = True
    mute_streams: tuple[int, ...] = ()
    spin_us: float = 300.0

    def __post_init__(self) -> None:
        if self.control not in ("companion", "vehicle"):
            raise ValueError("control must be 'companion' or 'vehicle'")
        if not self.setpoint_hz >= 20.0:
            raise ValueError("setpoint_hz must be >= 20 (PX4 offboard)")
        if not self.spin_us >= 0.0:
            raise ValueError("spin_us must be >= 0")


@dataclass
class FlightLog:
    """Per-frame record of a flight (vehicle time), for plots and statistics.

    ``rows`` columns (see ``COLUMNS``): time, phase code, reference position,
    true (or estimated) position, measured position, true attitude as
    ``R_enu_flu`` rows flattened (9), desired attitude columns b1d, b2d, b3d
    (9), collective thrust f, pointing direction s (3).
    """

    COLUMNS = (["t", "phase"] + [f"ref_{c}" for c in "xyz"] + [f"true_{c}" for c in "xyz"]
               + [f"est_{c}" for c in "xyz"] + [f"R{i}{j}" for i in range(3) for j in range(3)]
               + [f"{b}_{c}" for b in ("b1d", "b2d", "b3d") for c in "xyz"] + ["f"]
               + [f"s_{c}" for c in "xyz"])
    #: The rows back to back (C doubles): appending floats to one growing
    #: buffer costs less per frame than building a row tuple.
    data: array = field(default_factory=lambda: array("d"))

    @property
    def rows(self) -> list[tuple]:
        """The rows as tuples (a copy)."""
        a = self.array()
        return [tuple(r) for r in a.tolist()]

    def array(self) -> np.ndarray:
        """(N, len(COLUMNS)) float array (NaN where a value was unknown)."""
        n = len(self.COLUMNS)
        if len(self.data) % n:
            raise ValueError("FlightLog: partial row")
        return np.frombuffer(self.data, dtype=float).reshape(-1, n).copy()

    def column(self, name: str) -> np.ndarray:
        return self.array()[:, self.COLUMNS.index(name)]


@dataclass
class FlightResult:
    """What ``MissionRunner.run`` returns: the report and the per-frame log."""

    report: FlightReport
    log: FlightLog


_NAN3 = (math.nan, math.nan, math.nan)
_NAN9 = (math.nan,) * 9
_NAN_CTRL = (math.nan,) * 10


class MissionRunner:
    """Fly ``trajectory`` over ``conn`` (see the module docstring).

    Parameters
    ----------
    conn : Connection
        Open link (the runner sets ``conn.handler``).
    trajectory : companion.trajectory.Trajectory
        The reference (ENU, map frame = the vehicle's local frame).
    waypoints_p_enu_m : (N, 3) array
        Way-points uploaded as the MAVLink mission.
    home : (lat_deg, lon_deg, alt_m)
        Geodetic pose of the map origin (for MISSION_ITEM_INT).
    target_enu_m : (3,) array
        Pointing target S_p.
    vehicle : VehicleConfig
    controller : GeometricController or None
        Required for ``control="companion"``.
    config : RunnerConfig
    progress : Progress or None
    mission_name : str
    coverage_fraction : float or None
    """

    def __init__(self, conn: Connection, trajectory, waypoints_p_enu_m, home, target_enu_m,
                 vehicle: VehicleConfig, controller: GeometricController | None, config: RunnerConfig,
                 progress: Progress | None = None, mission_name: str = "", coverage_fraction=None) -> None:
        if config.control == "companion" and controller is None:
            raise ValueError("control='companion' needs a controller")
        self.conn = conn
        self.traj = trajectory
        self.waypoints = np.asarray(waypoints_p_enu_m, dtype=float)
        self.home = tuple(float(h) for h in home)
        self.target = tuple(float(x) for x in target_enu_m)
        self.vehicle = vehicle
        self.ctrl = controller
        self.cfg = config
        self.progress = progress or Progress(enabled=False)
        self.mission_name = mission_name
        self.coverage_fraction = coverage_fraction
        self.log = FlightLog()

        self._traj_t0, self._traj_tf = float(trajectory.t0), float(trajectory.tf)
        self.phase = "connect"
        self.t_s = None                 # vehicle time of the last frame (s)
        self._t_first = None
        self._imu_times: list[int] = []
        self.period_us: int | None = None
        self.n_frames = 0
        self.armed = False
        self.vstate = None
        self.landed_state = mavlink.MAV_LANDED_STATE_UNDEFINED
        self._pos = None
        self._vel = None
        self._nav_t = None
        self._truth = None
        self._R_true = None
        self._odom = None               # last ODOMETRY, not yet decoded
        self.truth_source = "estimate"
        self._controlling = False
        self._next_sp_t = -math.inf
        self._sp_dt = 1.0 / config.setpoint_hz
        self._errors_t: list[float] = []
        self._errors: list[float] = []
        self._last_err = None
        self.min_clearance_m = None
        self.statustext: list[str] = []
        self.n_control_faults = 0
        # phase schedule (vehicle seconds), set at arm time
        self._t_arm = None
        self._climb_from = None
        self._climb_T = 0.0
        self._transfer_T = 0.0
        self._climb_top = None
        self._t_hold = self._t_traj = self._t_hover = self._t_land = math.inf
        self._traj_cache = None
        self._dispatch = {
            "HIGHRES_IMU": self._on_imu,
            "LOCAL_POSITION_NED": self._on_local_position,
            "ODOMETRY": self._on_odometry,
            "ATTITUDE": self._on_attitude,
            "HEARTBEAT": self._on_heartbeat,
            "EXTENDED_SYS_STATE": self._on_ext_state,
            "DISTANCE_SENSOR": self._on_distance,
            "STATUSTEXT": self._on_statustext,
        }

    # --- message handlers -----------------------------------------------------------

    def on_message(self, m) -> None:
        h = self._dispatch.get(m.get_type())
        if h is not None and m.get_srcSystem() == self.conn.target_system:
            h(m)

    def _on_local_position(self, m) -> None:
        self._pos = (m.y, m.x, -m.z)          # NED -> ENU (codec.decode_local_position_ned, inlined)
        self._vel = (m.vy, m.vx, -m.vz)
        self._nav_t = m.time_boot_ms * 1e-3

    def _on_odometry(self, m) -> None:
        if m.get_srcComponent() != self.conn.target_component:
            return
        # Decoded when used (``_truth_update``, after the frame's answer went
        # out): the controller never reads the true state.
        self._odom = m
        self.truth_source = "sim_truth"

    def _truth_update(self) -> None:
        m = self._odom
        if m is not None:
            self._odom = None
            self._truth, self._R_true = codec.decode_odometry_pose(m)

    def _on_attitude(self, m) -> None:
        if self.truth_source != "sim_truth":
            self._R_true = tuple(codec.decode_attitude(m).R_enu_flu.ravel().tolist())

    def _on_heartbeat(self, m) -> None:
        if m.get_srcComponent() != self.conn.target_component:
            return
        self.vstate = codec.decode_heartbeat(m)
        self.armed = self.vstate.armed

    def _on_ext_state(self, m) -> None:
        self.landed_state = int(m.landed_state)

    def _on_distance(self, m) -> None:
        if self.phase not in ("trajectory", "hover", "hold") or m.orientation == _SENSOR_DOWN:
            return
        r = codec.decode_distance_sensor(m)
        if math.isfinite(r.distance_m) and (self.min_clearance_m is None or r.distance_m < self.min_clearance_m):
            self.min_clearance_m = r.distance_m

    def _on_statustext(self, m) -> None:
        self.statustext.append(str(m.text))

    def _on_imu(self, m) -> None:
        # The per-frame path (250 Hz, lockstep: the vehicle waits for our answer).
        t_us = int(m.time_usec)
        t = t_us * 1e-6
        conn = self.conn
        if self.period_us is None:
            self._imu_times.append(t_us)
            if len(self._imu_times) >= 2 and self._imu_times[-1] > self._imu_times[-2]:
                self.period_us = self._imu_times[-1] - self._imu_times[-2]
        if self._t_first is None:
            self._t_first = t
        self.t_s = t
        self.n_frames += 1
        conn.heartbeat_due(t)
        self._advance_phase(t)
        ref = self._traj_ref(t) if self.phase == "trajectory" else self._reference(t)
        cmd = None
        out = None
        if ref is not None:
            if t >= self._next_sp_t:
                self._next_sp_t = t + self._sp_dt - 1e-9
                conn.send(codec.encode_set_position_target(
                    conn.mav, t_us // 1000, ref.p, ref.v, ref.a, setpoint_yaw_enu(ref.s, ref.a),
                    conn.target_system, conn.target_component))
            if self._controlling and self._pos is not None:
                ctrl = self.ctrl
                try:
                    # GeometricController.update on float tuples (no Measurements /
                    # Reference / ControlOutput per frame); FLU = FRD with y, z negated.
                    cmd = ctrl.update_fast(t, (m.xgyro, -m.ygyro, -m.zgyro), (m.xacc, -m.yacc, -m.zacc),
                                           (m.xmag, -m.ymag, -m.zmag), self._pos, self._vel, self._nav_t,
                                           ref.p, ref.v, ref.a, ref.jerk, ref.snap, ref.target)
                    out = ctrl.last_desired
                except (ValueError, ZeroDivisionError, OverflowError):
                    # a non-finite or degenerate measurement: let the vehicle fly this frame
                    self.n_control_faults += 1
        conn.send_actuators(t_us, cmd, self.armed)
        if ref is not None:
            self._record(t, ref, out)

    def _record(self, t: float, ref: RefSample, out) -> None:
        """Append one FlightLog row; ``out``: the controller's ``last_desired`` (b1d, b2d, b3d, f) or None."""
        if self._odom is not None:
            self._truth_update()
        truth = self._truth if self._truth is not None else self._pos
        est = self._pos if self._pos is not None else _NAN3
        phase = self.phase
        if truth is not None:
            p = ref.p
            err = math.sqrt((truth[0] - p[0]) ** 2 + (truth[1] - p[1]) ** 2 + (truth[2] - p[2]) ** 2)
            self._last_err = err
            if phase == "trajectory":
                self._errors_t.append(t)
                self._errors.append(err)
        else:
            truth = _NAN3
        R = self._R_true
        ext = self.log.data.extend   # one flat row of FlightLog.COLUMNS
        ext((t, _PHASE_CODE[phase]))
        ext(ref.p)
        ext(truth)
        ext(est)
        ext(_NAN9 if R is None else R)
        ext(_NAN_CTRL if out is None else out)   # b1d, b2d, b3d (columns of R_d), f
        ext(ref.s)

    # --- the reference, by phase --------------------------------------------------------

    def _advance_phase(self, t: float) -> None:
        ph = self.phase
        if ph == "takeoff" and t >= self._t_hold:
            self.phase = "hold"
        if self.phase == "hold" and t >= self._t_traj:
            self.phase = "trajectory"
        if self.phase == "trajectory" and t >= self._t_hover:
            self.phase = "hover"
        if self.phase == "hover" and t >= self._t_land:
            self.phase = "landing"
            self._controlling = False

    def _reference(self, t: float) -> RefSample | None:
        ph = self.phase
        if ph == "trajectory":
            return self._traj_ref(t)
        if ph == "hold":
            return self._hold_first
        if ph == "hover":
            return self._hold_last
        if ph == "takeoff":
            dt = t - self._t_arm
            if dt < self._climb_T or self._transfer_T <= 0.0:
                p, v, a, j, s = smooth_segment(self._climb_from, self._climb_top, self._climb_T, dt)
            else:
                p, v, a, j, s = smooth_segment(self._climb_top, self._hold_first.p, self._transfer_T,
                                               dt - self._climb_T)
            # Turn the pointing direction smoothly from the heading at arming to
            # the trajectory's first pointing s0 and hand the controller a target
            # "at infinity" in that direction: the straight transfer may pass
            # through S_p itself, where pointing at it would flip the heading.
            sp = self._takeoff_pointing(dt)
            far = (p[0] + 1e4 * sp[0], p[1] + 1e4 * sp[1], p[2] + 1e4 * sp[2])
            return RefSample(p, v, a, j, s, sp, far)
        if ph == "preflight" and self._pos is not None:
            return self._preflight_ref
        return None

    def _takeoff_pointing(self, dt: float) -> tuple:
        s0 = self._hold_first.s
        T = self._climb_T + self._transfer_T
        sig = smooth_segment((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), T, dt)[0][0]
        psi = self._psi_arm + sig * self._dpsi
        h = math.sqrt(max(0.0, 1.0 - (sig * s0[2]) ** 2))
        return (h * math.cos(psi), h * math.sin(psi), sig * s0[2])

    def _build_trajectory_cache(self) -> None:
        """Sample the trajectory at every sensor frame once (vectorised), so a
        frame costs a list lookup instead of a polynomial evaluation."""
        dt = self.period_us * 1e-6
        n = int(math.floor((self._traj_tf - self._traj_t0) / dt + 1e-9)) + 2
        times = np.minimum(self._traj_t0 + dt * np.arange(n), self._traj_tf)
        smp = self.traj.sample(times)
        if smp.pointing is not None:
            s = smp.pointing
        else:
            d = np.asarray(self.target) - smp.p
            s = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
        self._traj_cache = [RefSample(*(tuple(r) for r in row)) for row in zip(
            smp.p.tolist(), smp.v.tolist(), smp.a.tolist(), smp.jerk.tolist(), smp.snap.tolist(), s.tolist())]
        self._traj_dt = dt

    def _traj_ref(self, t: float) -> RefSample:
        k = int(round((t - self._t_traj) / self._traj_dt))
        cache = self._traj_cache
        return cache[min(max(k, 0), len(cache) - 1)]

    def _static_ref(self, p) -> RefSample:
        z = (0.0, 0.0, 0.0)
        p = tuple(float(c) for c in p)
        return RefSample(p, z, z, z, z, pointing_at(p, self.target))

    # --- the procedure ----------------------------------------------------------------------

    def _pump_until(self, predicate, what: str) -> None:
        """Handle messages until ``predicate()``; LinkError after ``link_timeout_s`` of silence."""
        last = time.monotonic()
        next_show, shown = last, None
        conn = self.conn
        on = self.on_message
        while not predicate():
            msgs = conn.poll(0.05)
            now = time.monotonic()
            if msgs:
                last = now
                for m in msgs:
                    on(m)
            elif now - last > self.cfg.link_timeout_s:
                raise LinkError(f"{conn.url}: vehicle silent for {self.cfg.link_timeout_s:g} s while {what}")
            if now >= next_show or self.phase != shown:   # 20 updates a second are enough
                next_show = now + 0.05
                shown = self.phase
                self._show()

    def _show(self) -> None:
        frac = 0.0
        if self.phase == "trajectory" and self.t_s is not None:
            frac = (self.t_s - self._t_traj) / max(self._traj_tf - self._traj_t0, 1e-9)
        elif self.phase in ("hover", "landing", "done"):
            frac = 1.0
        self.progress.update(self.phase, frac, self._last_err, 0, self.t_s or 0.0)

    def _command_retry(self, command: int, params, what: str, tries: int = 10, wait_s: float = 0.5) -> None:
        """COMMAND_LONG, retried after ``wait_s`` of vehicle time while TEMPORARILY_REJECTED."""
        for i in range(tries):
            try:
                self.conn.command_long(command, params, what=what)
                return
            except CommandRejected as exc:
                if exc.result != mavlink.MAV_RESULT_TEMPORARILY_REJECTED or i == tries - 1:
                    raise
            t_until = (self.t_s or 0.0) + wait_s
            self._pump_until(lambda: self.t_s is not None and self.t_s >= t_until, what)

    def run(self) -> FlightResult:
        """Fly; returns the report (``completed`` False with ``error`` set on failure)."""
        wall0 = time.monotonic()
        conn = self.conn
        conn.handler = self.on_message
        # every frame is answered in lockstep: replies are handled with the next frame
        conn.frame_sync = True
        conn.spin_s = self.cfg.spin_us * 1e-6 if (os.cpu_count() or 1) >= 2 else 0.0
        error = None
        try:
            self._fly()
        except (LinkError, CommandRejected) as exc:
            error = str(exc)
        finally:
            self.progress.update(self.phase, 1.0 if self.phase == "done" else 0.0, self._last_err, 0,
                                 self.t_s or 0.0, force=True)
            self.progress.close()
        wall = time.monotonic() - wall0
        return FlightResult(self._report(wall, error), self.log)

    def _fly(self) -> None:
        conn, cfg = self.conn, self.cfg
        self.phase = "connect"
        self._show()
        hb = conn.wait_heartbeat(timeout_s=cfg.link_timeout_s)
        self.on_message(hb)
        self.phase = "setup"
        self._pump_until(lambda: self.period_us is not None, "waiting for HIGHRES_IMU frames")
        conn.set_message_interval(mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, self.period_us)
        if cfg.request_truth:
            try:
                conn.set_message_interval(mavlink.MAVLINK_MSG_ID_ODOMETRY, self.period_us, retries=1)
            except (CommandRejected, LinkError):
                pass   # not our SITL: track against LOCAL_POSITION_NED
        for mid in cfg.mute_streams:
            try:
                conn.set_message_interval(mid, -1, retries=1)
            except (CommandRejected, LinkError):
                pass
        self._pump_until(lambda: self._pos is not None, "waiting for LOCAL_POSITION_NED")

        self.phase = "upload"
        self._show()
        items = [codec.encode_mission_item_int(conn.mav, i, p, *self.home, conn.target_system,
                                               conn.target_component, current=(i == 0))
                 for i, p in enumerate(self.waypoints)]
        upload_mission(conn, items)

        # Setpoints must be streaming before OFFBOARD (PX4 rule): hold the ground position.
        self._preflight_ref = self._static_ref(self._pos)
        self._build_trajectory_cache()
        first = self._traj_cache[0]
        last = self._traj_cache[-1]
        self._hold_first = RefSample(first.p, (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, first.s)
        self._hold_last = RefSample(last.p, (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, last.s)
        self.phase = "preflight"
        t_ready = self.t_s + cfg.preflight_s
        self._pump_until(lambda: self.t_s >= t_ready, "streaming setpoints before OFFBOARD")
        self._command_retry(mavlink.MAV_CMD_DO_SET_MODE,
                            (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, codec.PX4_MAIN_MODE_OFFBOARD, 0),
                            "set OFFBOARD")
        self._command_retry(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (1,), "arm")
        self.armed = True

        # Schedule of the flight, in vehicle time from now.
        t_arm = self.t_s
        self._t_arm = t_arm
        self._climb_from = tuple(self._pos)
        if math.dist(self._pos[:2], first.p[:2]) < LAUNCH_TOLERANCE_M:
            # Launched under the first point (``companion demo``): one climb
            # straight to it, no level transfer.
            self._climb_top = tuple(first.p)
            self._transfer_T = 0.0
        else:
            self._climb_top = (self._pos[0], self._pos[1], max(first.p[2], self._pos[2]))
            self._transfer_T = climb_duration_s(math.dist(self._climb_top, first.p), cfg.transfer_speed_m_s, 1.0)
        self._climb_T = climb_duration_s(math.dist(self._climb_from, self._climb_top), cfg.climb_speed_m_s)
        self._t_hold = t_arm + self._climb_T + self._transfer_T
        # Heading of the body y axis (the pointing axis b2) at arming, from the
        # vehicle's attitude report; the takeoff turns it toward s0.
        s0 = first.s
        psi1 = math.atan2(s0[1], s0[0])
        self._truth_update()
        R = self._R_true   # row-major 9-tuple
        psi0 = psi1 if R is None else math.atan2(R[4], R[1])
        self._psi_arm = psi0
        self._dpsi = (psi1 - psi0 + math.pi) % (2.0 * math.pi) - math.pi
        self._t_traj = self._t_hold + cfg.hold_s
        self._t_hover = self._t_traj + (self._traj_tf - self._traj_t0)
        self._t_land = self._t_hover + cfg.hover_s
        self._controlling = cfg.control == "companion"
        self.phase = "takeoff"
        self._pump_until(lambda: self.phase == "landing", "flying")

        self._command_retry(mavlink.MAV_CMD_NAV_LAND, (), "land")
        t_limit = self.t_s + cfg.landing_timeout_s
        t_disarm_asked = None

        def landed_and_disarmed() -> bool:
            nonlocal t_disarm_asked
            if not self.armed:
                return True
            if self.t_s >= t_limit:
                raise LinkError(f"{conn.url}: vehicle did not land and disarm within "
                                f"{cfg.landing_timeout_s:g} s of vehicle time")
            on_ground = self.landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND
            if on_ground and t_disarm_asked is None:
                t_disarm_asked = self.t_s
            return False

        self._pump_until(lambda: landed_and_disarmed() or
                         (t_disarm_asked is not None and self.t_s - t_disarm_asked > 3.0), "landing")
        if self.armed:
            self._command_retry(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (0,), "disarm")
            self.armed = False
        self.phase = "done"

    def _report(self, wall_s: float, error: str | None) -> FlightReport:
        settle = self.cfg.settle_s
        tr = tracking_stats(self._errors_t, self._errors, self._t_traj if math.isfinite(self._t_traj) else 0.0,
                            settle, self.truth_source)
        sim_s = (self.t_s - self._t_first) if self.t_s is not None and self._t_first is not None else 0.0
        return FlightReport(
            completed=(self.phase == "done" and error is None),
            control=self.cfg.control,
            sim_time_s=float(sim_s),
            wall_time_s=float(wall_s),
            tracking=tr,
            replanning=ReplanningStats(0, self.min_clearance_m, 0.0),
            coverage_fraction=self.coverage_fraction,
            tlog=str(self.conn.tlog.path) if self.conn.tlog is not None else None,
            mission=self.mission_name,
            phase=self.phase,
            error=error,
            real_time_factor=(sim_s / wall_s) if wall_s > 0 else None,
            n_frames=self.n_frames,
            trajectory_duration_s=self._traj_tf - self._traj_t0,
        )
