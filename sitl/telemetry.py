"""What the SITL's vehicle reports: one encoder per telemetry message (pure).

``VehicleTelemetry`` turns the state of the simulation, the flight stack and
the battery at the current sensor frame into MAVLink messages: an encoder per
message id (``encoders``), and for the streams sent every frame a packer with
its argument builder (``fast``: ``mavcore.codec`` fast packing, no message
object). The frame marker is the personality's (PX4 HIGHRES_IMU, ArduCopter
RAW_IMU with SCALED_IMU2 beside it): ``frame_imu_id``, ``frame_imu_pack``,
``frame_imu_args``. The default stream rates (``DEFAULT_RATES_HZ``) and
``telemetry_service``, which puts the encoders under the stream schedule
(``mavcore.services.telemetry``: ``StreamSchedule``, ``TelemetryServer``) are
here too; handing a frame's messages to the links is ``sitl.server``.

No sockets, no clock: the vehicle time is the simulation's, the wall-clock
epoch of SYSTEM_TIME is given at construction.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from mavcore import codec
from mavcore.services.telemetry import StreamSchedule, TelemetryServer, interval_us

ID = mavlink

CAPABILITIES = (mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
                | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2)

_SENSORS = (mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
            | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
            | mavlink.MAV_SYS_STATUS_SENSOR_GPS | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
            | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
            | mavlink.MAV_SYS_STATUS_SENSOR_YAW_POSITION | mavlink.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
            | mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
            | mavlink.MAV_SYS_STATUS_SENSOR_PROXIMITY | mavlink.MAV_SYS_STATUS_AHRS
            | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY)
_PREARM = mavlink.MAV_SYS_STATUS_PREARM_CHECK
_GEOFENCE = mavlink.MAV_SYS_STATUS_GEOFENCE


#: SCALED_IMU2 rate of the ArduCopter personality (Hz; its RAW_SENS stream group).
SCALED_IMU2_HZ = 10.0

#: Default stream rates (Hz; 0: off), in the order the streams go out within a frame
#: (docs/mavlink.md; changeable by MAV_CMD_SET_MESSAGE_INTERVAL).
DEFAULT_RATES_HZ = {
    ID.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    ID.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    ID.MAVLINK_MSG_ID_BATTERY_STATUS: 1.0,
    ID.MAVLINK_MSG_ID_SYSTEM_TIME: 1.0,
    ID.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 5.0,
    ID.MAVLINK_MSG_ID_ATTITUDE: 50.0,
    ID.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 50.0,
    ID.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 50.0,
    ID.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 10.0,
    ID.MAVLINK_MSG_ID_GPS_RAW_INT: 5.0,
    ID.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: 10.0,
    ID.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    ID.MAVLINK_MSG_ID_ODOMETRY: 0.0,        # ground truth, off unless requested
}


def telemetry_service(vehicle, mav, wall_epoch_us: int):
    """The vehicle's telemetry: ``(VehicleTelemetry, StreamSchedule, TelemetryServer)``.

    ``vehicle``: ``sitl.vehicle.Vehicle``; ``mav``: ``() -> MAVLink``;
    ``wall_epoch_us``: SYSTEM_TIME's wall clock at vehicle time 0. The
    schedule starts at ``DEFAULT_RATES_HZ`` plus the personality's streams
    (ArduCopter's SCALED_IMU2), the frame marker's interval fixed at the
    sensor period.
    """
    v = vehicle
    period = v.sim.sensor_period_us
    defaults = {mid: interval_us(hz) for mid, hz in DEFAULT_RATES_HZ.items()}
    intervals = dict(defaults)
    telemetry = VehicleTelemetry(v.sim, v.stack, v.battery, v.autopilot, v.origin, v.home_enu_m, v.seed,
                                 wall_epoch_us, v.nav_state, mav, intervals)
    schedule = StreamSchedule(intervals, period, defaults, fixed_us={telemetry.frame_imu_id: period})
    server = TelemetryServer(schedule, telemetry.encoders, telemetry.fast,
                             (telemetry.frame_imu_pack, telemetry.frame_imu_args), telemetry.range_messages)
    return telemetry, schedule, server


class VehicleTelemetry:
    """The vehicle's telemetry encoders at the current frame.

    Parameters
    ----------
    sim : sitl.sim.Simulation
    stack : sitl.flightstack.FlightStack
    battery : sitl.battery.Battery
    autopilot : mavcore.autopilot.Autopilot
    origin : codec.GeoOrigin
    home_enu_m : (3,) array
    seed : int
        The simulation's seed (AUTOPILOT_VERSION's uid).
    wall_epoch_us : int
        Wall-clock time (us since the Unix epoch) at vehicle time 0 (SYSTEM_TIME).
    nav_state : callable
        ``frame -> NavState``: what the flight stack knows (estimate or truth).
    mav : callable
        ``() -> MAVLink``: the encoder to build messages with.
    intervals : dict
        The stream table: the personality's extra streams are added to it.

    ``frame`` (the current ``SensorFrame``) and ``setpoint`` (the flight
    stack's, for POSITION_TARGET_LOCAL_NED) are set each frame (``new_frame``).
    """

    def __init__(self, sim, stack, battery, autopilot, origin, home_enu_m, seed: int, wall_epoch_us: int,
                 nav_state, mav, intervals: dict) -> None:
        self.sim, self.stack, self.battery, self.autopilot = sim, stack, battery, autopilot
        self.origin, self.home_enu_m, self.seed = origin, home_enu_m, int(seed)
        self.wall_epoch_us = int(wall_epoch_us)
        self.nav_state = nav_state
        self.mav = mav
        self.frame = None
        self.setpoint = None
        #: The latest reading of each rangefinder (sensor id -> reading), for REQUEST_MESSAGE.
        self.last_ranges: dict = {}
        #: DISTANCE_SENSOR turned off (SET_MESSAGE_INTERVAL -1).
        self.ranges_off = False
        self.encoders = {
            ID.MAVLINK_MSG_ID_HEARTBEAT: self.heartbeat,
            ID.MAVLINK_MSG_ID_SYS_STATUS: self._enc_sys_status,
            ID.MAVLINK_MSG_ID_BATTERY_STATUS: self._enc_battery,
            ID.MAVLINK_MSG_ID_SYSTEM_TIME: self._enc_system_time,
            ID.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: self._enc_ext_state,
            ID.MAVLINK_MSG_ID_ATTITUDE: self._enc_attitude,
            ID.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: self._enc_attitude_q,
            ID.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self._enc_lpos,
            ID.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self._enc_gpos,
            ID.MAVLINK_MSG_ID_GPS_RAW_INT: self._enc_gps,
            ID.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: self._enc_target,
            ID.MAVLINK_MSG_ID_HOME_POSITION: self.home,
            ID.MAVLINK_MSG_ID_HIGHRES_IMU: self._enc_imu,
            ID.MAVLINK_MSG_ID_AUTOPILOT_VERSION: self.version,
            ID.MAVLINK_MSG_ID_ODOMETRY: self._enc_truth,
        }
        self._frame_imu_setup(intervals)
        self.fast = {
            ID.MAVLINK_MSG_ID_LOCAL_POSITION_NED: (codec.PACK_LOCAL_POSITION_NED, self._lpos_args),
            ID.MAVLINK_MSG_ID_ATTITUDE: (codec.PACK_ATTITUDE, self._attitude_args),
            ID.MAVLINK_MSG_ID_ODOMETRY: (codec.PACK_ODOMETRY, self._odometry_args),
            ID.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: (codec.PACK_ATTITUDE_QUATERNION, self._attitude_q_args),
        }

    def new_frame(self, frame, setpoint) -> None:
        """The frame just stepped (and the flight stack's setpoint): what the encoders report."""
        self.frame = frame
        self.setpoint = setpoint
        if frame.ranges:
            for r in frame.ranges:
                self.last_ranges[r.sensor_id] = r

    def range_messages(self, frame, out: list) -> None:
        """Append DISTANCE_SENSOR of each rangefinder reading of ``frame`` to ``out`` as
        ``(packer, payload)`` (none while turned off by SET_MESSAGE_INTERVAL -1)."""
        if self.ranges_off:
            return
        tb = frame.time_us // 1000
        pack = codec.PACK_DISTANCE_SENSOR
        for r in frame.ranges:
            out.append((pack, codec.distance_sensor_args(tb, r)))

    def _attitude_source(self):
        """(R row-major 9-tuple, body rates FLU) reported in ATTITUDE*: the
        estimate, or the truth with ``sim.onboard_state: truth``."""
        e = self.frame.estimate if self.frame is not None else None
        if e is not None:
            return e.R, e.omega_flu_rad_s
        pl = self.sim.plant
        return pl.R, pl.w

    def heartbeat(self):
        st = self.stack
        return codec.heartbeat(self.mav(), st.armed, st.custom_mode, st.system_status, self.autopilot.mav_autopilot)

    def _enc_sys_status(self):
        health = _SENSORS
        s = self.nav_state(self.frame)
        if s.landed and s.tilt_rad < math.radians(30.0):
            health |= _PREARM
        # geofence: always present (PX4), enabled with a stored fence, healthy unless breached
        enabled = _SENSORS | _PREARM | (_GEOFENCE if self.stack.fence is not None else 0)
        if not self.stack.fence_breached:
            health |= _GEOFENCE
        b = self.battery
        return codec.sys_status(self.mav(), _SENSORS | _PREARM | _GEOFENCE, enabled, health, b.voltage_v,
                                b.current_a, b.remaining)

    def _enc_battery(self):
        b = self.battery
        return codec.battery_status(self.mav(), b.cells, b.voltage_v, b.current_a, b.consumed_ah,
                                    b.consumed_wh, b.remaining)

    def _enc_system_time(self):
        t = self.sim.time_us
        return self.mav().system_time_encode(self.wall_epoch_us + t, t // 1000)

    def _enc_ext_state(self):
        return self.mav().extended_sys_state_encode(mavlink.MAV_VTOL_STATE_UNDEFINED, self.stack.landed_state)

    def _enc_attitude(self):
        return codec.attitude(self.mav(), self.sim.time_us // 1000, *self._attitude_source())

    def _enc_attitude_q(self):
        return codec.attitude_quaternion(self.mav(), self.sim.time_us // 1000, *self._attitude_source())

    def _enc_lpos(self):
        f = self.frame
        return codec.local_position_ned(self.mav(), f.pos_time_us // 1000, f.pos_enu_m, f.vel_enu_m_s)

    def _enc_gpos(self):
        f = self.frame
        s = self.nav_state(f)
        return codec.global_position_int(self.mav(), f.time_us // 1000, self.origin, self.home_enu_m,
                                         s.pos_enu_m, s.vel_enu_m_s, s.yaw_enu_rad)

    def _enc_gps(self):
        f = self.frame
        return codec.gps_raw_int(self.mav(), f.time_us, self.origin, f.pos_enu_m, f.vel_enu_m_s)

    def _enc_target(self):
        if self.setpoint is None:
            return None
        return codec.position_target_local_ned(self.mav(), self.sim.time_us // 1000, self.setpoint)

    def home(self):
        return codec.home_position(self.mav(), self.origin, self.home_enu_m, self.sim.time_us)

    # The per-frame argument builders read float tuples: the frame's
    # measurement slots and the plant's state (= ``self.frame.truth``, see
    # ``_nav_state``), not the arrays ``SensorFrame``/``TrueState`` build lazily.
    def _imu_args(self):
        f = self.frame
        return codec.highres_imu_args(f.time_us, f._acc, f._gyro, f._mag,
                                      self.origin.alt_m + self.sim.plant.p[2])

    def _enc_imu(self):
        return mavlink.MAVLink_highres_imu_message(*self._imu_args())

    def _raw_imu_args(self):
        f = self.frame
        return codec.raw_imu_args(f.time_us, f._acc, f._gyro, f._mag)

    def _enc_raw_imu(self):
        return mavlink.MAVLink_raw_imu_message(*self._raw_imu_args())

    def _enc_scaled_imu2(self):
        f = self.frame
        return codec.scaled_imu2(self.mav(), f.time_us // 1000, f._acc, f._gyro, f._mag)

    def _lpos_args(self):
        f = self.frame
        return codec.local_position_ned_args(f.pos_time_us // 1000, f._pos, f._vel)

    def _attitude_q_args(self):
        return codec.attitude_quaternion_args(self.sim.time_us // 1000, *self._attitude_source())

    def _odometry_args(self):
        pl = self.sim.plant
        return codec.odometry_truth_args(self.frame.time_us, pl.p, pl.v, pl.R, pl.w)

    def _enc_odometry(self):
        return mavlink.MAVLink_odometry_message(*self._odometry_args())

    def _attitude_args(self):
        return codec.attitude_args(self.sim.time_us // 1000, *self._attitude_source())

    def _enc_truth(self):
        t = self.frame.truth
        return codec.odometry_truth(self.mav(), self.frame.time_us, t.pos_enu_m, t.vel_enu_m_s, t.R,
                                    t.omega_flu_rad_s)

    def version(self):
        uid = (0x5A17 << 32) | (self.seed & 0xFFFFFFFF)
        ap = self.autopilot
        caps = CAPABILITIES if ap.param_bytewise else (
            CAPABILITIES & ~mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
            | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST)
        return self.mav().autopilot_version_encode(
            caps, ap.flight_sw_version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, uid)

    def _frame_imu_setup(self, intervals: dict) -> None:
        """The sensor-frame message (the lockstep frame marker) is the personality's:
        PX4 HIGHRES_IMU; ArduCopter RAW_IMU, with SCALED_IMU2 beside it."""
        if self.autopilot.imu_message == "RAW_IMU":
            self.frame_imu_id = ID.MAVLINK_MSG_ID_RAW_IMU
            self.frame_imu_pack, self.frame_imu_args = codec.PACK_RAW_IMU, self._raw_imu_args
            s2 = ID.MAVLINK_MSG_ID_SCALED_IMU2
            intervals[s2] = int(round(1e6 / SCALED_IMU2_HZ))
            self.encoders[s2] = self._enc_scaled_imu2
            self.encoders[ID.MAVLINK_MSG_ID_RAW_IMU] = self._enc_raw_imu
        else:
            self.frame_imu_id = ID.MAVLINK_MSG_ID_HIGHRES_IMU
            self.frame_imu_pack, self.frame_imu_args = codec.PACK_HIGHRES_IMU, self._imu_args
