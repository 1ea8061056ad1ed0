"""The companion's view of the vehicle, kept from the vehicle's messages (pure: no I/O).

``VehicleView`` holds what the messages say (the vehicle clock and sensor
period from the frame marker, HEARTBEAT's flight stack, arming and mode,
EXTENDED_SYS_STATE's landed state, the LOCAL_POSITION_NED fix, the ATTITUDE
estimate, the SITL's ground truth from ODOMETRY, STATUSTEXTs, the closest
rangefinder reading) and the handler of each message type that updates it
(``handlers``). What a message means for the flight goes where it belongs:
the ``FlightMonitor`` sees HEARTBEAT, EXTENDED_SYS_STATE and STATUSTEXT and
its violations go to ``react``; DISTANCE_SENSOR readings are sent on as
OBSTACLE_DISTANCE (``companion.link.obstacle_distance``) and handed to the
replanner; the frame marker (HIGHRES_IMU, or ArduCopter's RAW_IMU in SI
units) and the service answers go to the flight procedure
(``companion.flight.core.FlightCore``), whose hooks are ``on_frame`` and
``on_service``.

Frames: the wire is NED/FRD; the view is ENU/FLU (``pos``, ``vel``, ``R``).
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from mavcore import autopilot as autopilots
from mavcore import codec

from ..link.obstacle_distance import ObstacleDistancePublisher, encode_obstacle_distance

_SENSOR_DOWN = mavlink.MAV_SENSOR_ROTATION_PITCH_270
#: Phases in which rangefinder readings count (the replanner's, the closest-reading statistic).
RANGE_PHASES = ("trajectory", "hover", "hold", "divert")
#: STATUSTEXTs kept (the .tlog has them all).
MAX_STATUSTEXTS = 200


class SiImu:
    """RAW_IMU's fields in HIGHRES_IMU's units (m/s^2, rad/s, gauss; body FRD),
    ArduPilot's scaling: accel * 9.80665 / 1000, gyro / 1000, mag / 1000."""

    __slots__ = ("time_usec", "xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro", "xmag", "ymag", "zmag")
    _KA = 9.80665e-3

    def __init__(self, m) -> None:
        ka = self._KA
        self.time_usec = m.time_usec
        self.xacc, self.yacc, self.zacc = m.xacc * ka, m.yacc * ka, m.zacc * ka
        self.xgyro, self.ygyro, self.zgyro = m.xgyro * 1e-3, m.ygyro * 1e-3, m.zgyro * 1e-3
        self.xmag, self.ymag, self.zmag = m.xmag * 1e-3, m.ymag * 1e-3, m.zmag * 1e-3


class VehicleView:
    """What the vehicle's messages say of it (see the module docstring).

    Parameters
    ----------
    target_component : int
        The vehicle's component: HEARTBEAT and ODOMETRY of others are ignored.
    monitor : companion.flight.monitor.FlightMonitor
    react : callable
        ``Violation -> None``: what the flight does about a violation.
    phase : callable
        ``() -> str``: the flight's phase (rangefinder readings count in ``RANGE_PHASES``).
    emit : callable
        ``msg -> None``: queue a message to the vehicle (OBSTACLE_DISTANCE).
    enc : MAVLink
        The encoder of what we send.
    on_frame, on_service : callable
        ``msg -> None``: the procedure's per-frame step (after ``frame`` has
        updated the clock) and its service transaction.
    replanner : companion.replan.Replanner or None
        Gets the rangefinder readings and needs the vehicle's attitude estimate.

    Attributes
    ----------
    t_us, t_s : int, float or None
        The vehicle clock: the last frame marker's time (None before the first).
    t_first_s : float or None
    period_us : int or None
        The sensor period, learnt from two frame markers.
    n_frames : int
    armed : bool
        As the vehicle reports it (the procedure also sets it on its own ARM/DISARM).
    vstate, custom_mode, autopilot, landed_state
        HEARTBEAT (decoded), its custom mode, the flight stack it names (from
        the first one), EXTENDED_SYS_STATE's landed state.
    pos, vel : (3,) tuple ENU m, m/s, or None
        The last LOCAL_POSITION_NED; ``nav_t`` its time (s), ``pos_ms`` (ms),
        ``pos_new`` whether unread by the tracking statistics.
    imu : ((3,), (3,)) or None
        Accelerometer and magnetometer (FLU) of the last frame.
    truth : (3,) tuple or None
        The SITL's true position (ODOMETRY, decoded by ``truth_update``);
        ``truth_t_us`` its time, ``truth_new`` unread; ``R`` the attitude
        for the log (truth, else the vehicle's ATTITUDE).
    truth_source : str
        "sim_truth" once ODOMETRY comes, else "estimate".
    R_est, att_t, att_w
        The vehicle's attitude estimate (ATTITUDE, row-major 9-tuple ENU<-FLU),
        its time (s) and body rates (FLU rad/s).
    statustext : list of str
        The vehicle's texts (the first ``MAX_STATUSTEXTS``).
    min_range_m : float or None
        Smallest non-downward rangefinder reading in ``RANGE_PHASES``.
    """

    def __init__(self, target_component: int, monitor, react, phase, emit, enc, on_frame, on_service,
                 replanner=None) -> None:
        self.tc = int(target_component)
        self.monitor = monitor
        self.react = react
        self.phase = phase
        self.emit = emit
        self.enc = enc
        self.on_frame = on_frame
        self.on_service = on_service
        self.replanner = replanner
        #: What the rangefinders see, sent on as OBSTACLE_DISTANCE for the vehicle's own
        #: collision prevention (``companion.link.obstacle_distance``).
        self.obstacles_out = ObstacleDistancePublisher()
        self.t_us: int | None = None
        self.t_s: float | None = None
        self.t_first_s: float | None = None
        self._imu_times: list[int] = []
        self.period_us: int | None = None
        self.n_frames = 0
        self.armed = False
        self.vstate = None
        self.custom_mode: int | None = None
        self.autopilot: autopilots.Autopilot | None = None   # the vehicle's stack, from its first HEARTBEAT
        self.landed_state = mavlink.MAV_LANDED_STATE_UNDEFINED
        self.pos = None
        self.vel = None
        self.nav_t = None
        self.pos_ms = None
        self.pos_new = False
        self.imu = None                 # (accel, mag) FLU of the last frame
        self.truth = None
        self.truth_t_us = None
        self.truth_new = False
        self.R = None                   # attitude for the log: truth (ODOMETRY) or the vehicle's ATTITUDE
        self.odom = None
        self.truth_source = "estimate"
        self.R_est = None               # the vehicle's attitude estimate (ATTITUDE): poses of readings
        self.att_t = None               # ... its time (s) and body rates (FLU rad/s)
        self.att_w = (0.0, 0.0, 0.0)
        self.statustext: list[str] = []
        self.min_range_m = None

    def handlers(self) -> dict:
        """Message type -> handler; ``COMMAND_ACK``, ``MISSION_*`` and ``PARAM_VALUE`` go to ``on_service``."""
        service = self.on_service
        return {
            "HIGHRES_IMU": self._on_highres_imu,
            "RAW_IMU": self._on_raw_imu,
            "LOCAL_POSITION_NED": self._on_local_position,
            "ODOMETRY": self._on_odometry,
            "ATTITUDE": self._on_attitude,
            "HEARTBEAT": self._on_heartbeat,
            "EXTENDED_SYS_STATE": self._on_ext_state,
            "DISTANCE_SENSOR": self._on_distance,
            "STATUSTEXT": self._on_statustext,
            "COMMAND_ACK": service,
            "MISSION_REQUEST_INT": service,
            "MISSION_REQUEST": service,
            "MISSION_ACK": service,
            "PARAM_VALUE": service,
        }

    # --- the frame marker: the vehicle clock and the IMU -------------------------------------

    def frame(self, m) -> tuple:
        """The clock and IMU of frame marker ``m`` (HIGHRES_IMU units, body FRD);
        returns ``(t_us, t_s, gyro, acc, mag)``, the vectors FLU."""
        t_us = int(m.time_usec)
        t = t_us * 1e-6
        if self.period_us is None:
            self._imu_times.append(t_us)
            if len(self._imu_times) >= 2 and self._imu_times[-1] > self._imu_times[-2]:
                self.period_us = self._imu_times[-1] - self._imu_times[-2]
        if self.t_first_s is None:
            self.t_first_s = t
        self.t_us = t_us
        self.t_s = t
        self.n_frames += 1
        gyro = (m.xgyro, -m.ygyro, -m.zgyro)      # FRD -> FLU: y, z negated
        acc = (m.xacc, -m.yacc, -m.zacc)
        mag = (m.xmag, -m.ymag, -m.zmag)
        self.imu = (acc, mag)
        return t_us, t, gyro, acc, mag

    def _on_highres_imu(self, m) -> None:
        ap = self.autopilot
        if ap is None or ap.imu_message == "HIGHRES_IMU":
            self.on_frame(m)

    def _on_raw_imu(self, m) -> None:
        """ArduCopter's sensor frame: RAW_IMU in milli-g, mrad/s, milligauss -> SI."""
        ap = self.autopilot
        if ap is not None and ap.imu_message == "RAW_IMU":
            self.on_frame(SiImu(m))

    # --- navigation and truth ----------------------------------------------------------------

    def _on_local_position(self, m) -> None:
        self.pos = (m.y, m.x, -m.z)          # NED -> ENU (codec.decode_local_position_ned, inlined)
        self.vel = (m.vy, m.vx, -m.vz)
        self.nav_t = m.time_boot_ms * 1e-3
        self.pos_ms = int(m.time_boot_ms)
        self.pos_new = True

    def _on_odometry(self, m) -> None:
        if m.get_srcComponent() != self.tc:
            return
        # Decoded when used (``truth_update``, after the frame's answer was
        # queued): the controller never reads the true state.
        self.odom = m
        self.truth_source = "sim_truth"

    def truth_update(self) -> None:
        """Decode the last ODOMETRY (if a new one came): ``truth``, ``R``, ``truth_t_us``."""
        m = self.odom
        if m is not None:
            self.odom = None
            self.truth, self.R = codec.decode_odometry_pose(m)
            self.truth_t_us = int(m.time_usec)
            self.truth_new = True

    def _on_attitude(self, m) -> None:
        if self.truth_source != "sim_truth" or self.replanner is not None:
            R = tuple(codec.decode_attitude(m).R_enu_flu.ravel().tolist())
            self.R_est = R
            self.att_t = m.time_boot_ms * 1e-3
            self.att_w = (m.rollspeed, -m.pitchspeed, -m.yawspeed)     # FRD -> FLU
            if self.truth_source != "sim_truth":
                self.R = R

    # --- status, watched by the monitor ------------------------------------------------------

    def _on_heartbeat(self, m) -> None:
        if m.get_srcComponent() != self.tc:
            return
        vs = codec.decode_heartbeat(m)
        if self.autopilot is None:
            # The vehicle's flight stack decides the dialect (an unknown one is spoken to as PX4).
            self.autopilot = autopilots.from_heartbeat(m.autopilot) or autopilots.PX4_AUTOPILOT
            self.monitor.mode_name = self.autopilot.mode_name
        self.vstate = vs
        self.armed = vs.armed
        self.custom_mode = int(m.custom_mode)
        v = self.monitor.on_heartbeat(self.t_s, vs.armed, self.custom_mode, vs.system_status)
        if v is not None:
            self.react(v)

    def _on_ext_state(self, m) -> None:
        self.landed_state = int(m.landed_state)
        if self.t_s is not None:
            v = self.monitor.on_landed_state(self.t_s, self.landed_state)
            if v is not None:
                self.react(v)

    def _on_statustext(self, m) -> None:
        text = str(m.text)
        if len(self.statustext) < MAX_STATUSTEXTS:   # bounded: the .tlog has them all
            self.statustext.append(text)
        v = self.monitor.on_statustext(self.t_s, int(m.severity), text)
        if v is not None:
            self.react(v)

    # --- rangefinders ------------------------------------------------------------------------

    def _on_distance(self, m) -> None:
        if self.t_s is None:
            return
        try:
            r = codec.decode_distance_sensor(m)
        except (ValueError, ZeroDivisionError, OverflowError):
            return          # a malformed reading (e.g. a zero CUSTOM quaternion) is no evidence
        sectors = self.obstacles_out.on_range(self.t_s, r)
        if sectors is not None:
            self.emit(encode_obstacle_distance(self.enc, self.t_us, sectors))
        if self.phase() not in RANGE_PHASES:
            return
        if (m.orientation != _SENSOR_DOWN and math.isfinite(r.distance_m)
                and (self.min_range_m is None or r.distance_m < self.min_range_m)):
            self.min_range_m = r.distance_m
        if self.replanner is not None:
            self.replanner.on_range(self.t_s, r)
