"""The companion's view of the vehicle (``companion.flight.inbox.VehicleView``): each message
type's update, by hand-worked values, without a flight core."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.flight.inbox import VehicleView


class _Monitor:
    """What the view tells the monitor: each call recorded, no violation."""

    def __init__(self):
        self.mode_name = None
        self.calls = []

    def on_heartbeat(self, t, armed, mode, status):
        self.calls.append(("heartbeat", t, armed, mode))

    def on_landed_state(self, t, state):
        self.calls.append(("landed", t, state))

    def on_statustext(self, t, severity, text):
        self.calls.append(("text", t, text))


class _Replanner:
    def __init__(self):
        self.ranges = []

    def on_range(self, t, r):
        self.ranges.append((t, r.distance_m))


def received(encode, sysid=1, compid=1):
    """A message as the companion receives it from (sysid, compid): packed and parsed."""
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    return mavlink.MAVLink(None).parse_char(encode(mav).pack(mav))


def view(phase="trajectory", replanner=None):
    frames, services, sent = [], [], []
    enc = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    v = VehicleView(1, _Monitor(), lambda viol: None, lambda: phase, sent.append, enc, frames.append,
                    services.append, replanner)
    return v, v.handlers(), frames, services


def imu(t_us, gyro=(0.0, 0.0, 0.0)):
    return received(lambda m: m.highres_imu_encode(t_us, 0.1, 0.2, -9.8, *gyro, 0.2, 0.0, 0.4, 0, 0, 0, 0, 0))


def test_local_position_ned_is_kept_in_enu():
    v, h, _, _ = view()
    h["LOCAL_POSITION_NED"](received(lambda m: m.local_position_ned_encode(2500, 1.0, 2.0, -3.0, 0.5, -0.25, 1.5)))
    # NED (x north, y east, z down) -> ENU (east, north, up)
    assert v.pos == (2.0, 1.0, 3.0) and v.vel == (-0.25, 0.5, -1.5)
    assert v.nav_t == pytest.approx(2.5) and v.pos_ms == 2500 and v.pos_new


def test_the_frame_marker_sets_the_clock_and_the_sensor_period_and_goes_to_the_procedure():
    v, h, frames, _ = view()
    first = imu(1_000_000)
    h["HIGHRES_IMU"](first)
    assert frames == [first] and v.t_s is None       # the procedure takes the frame (``frame``) ...
    v.frame(first)
    assert v.period_us is None and v.t_first_s == pytest.approx(1.0)   # ... one marker: no period yet
    t_us, t, gyro, acc, mag = v.frame(imu(1_004_000, (0.1, 0.2, 0.3)))
    assert (v.period_us, v.n_frames, v.t_us) == (4000, 2, 1_004_000) and t == pytest.approx(1.004)
    # body FRD -> FLU: y and z negated
    assert gyro == pytest.approx((0.1, -0.2, -0.3)) and acc == pytest.approx((0.1, -0.2, 9.8))
    assert mag == pytest.approx((0.2, -0.0, -0.4)) and v.imu == (acc, mag)


def test_raw_imu_is_the_frame_only_of_an_ardupilot_vehicle_and_is_scaled_to_si():
    v, h, frames, _ = view()
    raw = received(lambda m: m.raw_imu_encode(3_000_000, 1000, 0, -1000, 500, 0, 0, 200, 0, -400))
    h["RAW_IMU"](raw)
    assert frames == []                              # no HEARTBEAT yet: spoken to as PX4 (HIGHRES_IMU)
    h["HEARTBEAT"](received(lambda m: m.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR,
                                                         mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 4, 4)))
    assert v.autopilot.key == "ardupilot" and v.custom_mode == 4
    h["RAW_IMU"](raw)
    h["HIGHRES_IMU"](imu(3_004_000))                 # ArduCopter's frame marker is RAW_IMU
    assert len(frames) == 1
    m = frames[0]
    # 1000 milli-g = 9.80665 m/s^2, 500 mrad/s = 0.5 rad/s, 200 milligauss = 0.2 gauss
    assert (m.xacc, m.zacc, m.xgyro, m.xmag, m.zmag) == pytest.approx((9.80665, -9.80665, 0.5, 0.2, -0.4))


def test_heartbeat_of_another_component_is_not_the_vehicle():
    v, h, _, _ = view()
    armed = mavlink.MAV_MODE_FLAG_SAFETY_ARMED | mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    hb = lambda m: m.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, armed, 6 << 16, 4)  # noqa: E731
    h["HEARTBEAT"](received(hb, compid=100))         # a camera of system 1
    assert v.vstate is None and not v.armed and v.monitor.calls == []
    h["HEARTBEAT"](received(hb))
    assert v.armed and v.custom_mode == 6 << 16 and v.autopilot.key == "px4"
    assert v.monitor.mode_name == v.autopilot.mode_name and v.monitor.calls[0][2:] == (True, 6 << 16)


def test_rangefinder_readings_count_in_the_flying_phases_and_not_looking_down():
    rp = _Replanner()
    v, h, _, _ = view("trajectory", rp)
    v.frame(imu(5_000_000))

    def reading(cm, orientation):
        return received(lambda m: m.distance_sensor_encode(5000, 10, 1200, cm, 0, 1, orientation, 0))

    h["DISTANCE_SENSOR"](reading(400, mavlink.MAV_SENSOR_ROTATION_NONE))
    h["DISTANCE_SENSOR"](reading(150, mavlink.MAV_SENSOR_ROTATION_PITCH_270))   # the downward one
    assert v.min_range_m == pytest.approx(4.0)
    assert rp.ranges == [(5.0, pytest.approx(4.0)), (5.0, pytest.approx(1.5))]
    v2, h2, _, _ = view("takeoff", rp)
    v2.frame(imu(5_000_000))
    h2["DISTANCE_SENSOR"](reading(300, mavlink.MAV_SENSOR_ROTATION_NONE))
    assert v2.min_range_m is None and len(rp.ranges) == 2


def test_service_answers_go_to_the_procedure():
    v, h, _, services = view()
    ack = received(lambda m: m.command_ack_encode(mavlink.MAV_CMD_NAV_LAND, mavlink.MAV_RESULT_ACCEPTED))
    h["COMMAND_ACK"](ack)
    assert services == [ack] and v.vstate is None
