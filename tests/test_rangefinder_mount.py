"""Rangefinders on the airframe: mounting offsets and CUSTOM orientations
(sitl/sensors.py) against hand-worked distances, and their DISTANCE_SENSOR
fields (mavcore/codec/vehicle_end.py): the FRD quaternion both ways, covariance, no return."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore import frames
from mavcore.mission.sim import NoiseConfig, ObstacleConfig, RangefinderConfig, SimConfig
from mavcore import codec
from sitl.sensors import RangeReading, SensorSuite, fan_directions_flu, mount_rotation_flu
from sitl.world import World

QUIET = NoiseConfig(vector_variance=0.0, gyro_variance=0.0, range_std_m=0.0)
C15, S15 = math.cos(math.radians(15.0)), math.sin(math.radians(15.0))
C30, S30 = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
H = math.sqrt(0.5)


def _rf(**kw):
    return RangefinderConfig(id=kw.pop("id", 0), hfov_deg=0.0, vfov_deg=0.0, max_m=30.0, **kw)


def _reading(cfg, world, p, R=np.eye(3)):
    suite = SensorSuite(SimConfig(noise=QUIET, rangefinders=(cfg,)), world, np.random.default_rng(0))
    return suite.range_reading(suite.rangefinders[0], tuple(p), tuple(np.asarray(R, dtype=float).ravel()))


def _Ry(a):   # about body y (FLU: left), a > 0 turns x toward -z
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _Rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# --- mounting rotation ----------------------------------------------------------------


def test_custom_euler_and_quaternion_give_the_same_beam():
    down30 = _rf(orientation=100, rotation_flu_deg=(0.0, 30.0, 0.0))
    q = _rf(orientation=100, quaternion_flu_wxyz=(C15, 0.0, S15, 0.0))      # 30 deg about +y
    beam = fan_directions_flu(down30)[0]
    np.testing.assert_allclose(beam, (C30, 0.0, -S30), atol=1e-15)           # forward and 30 deg down
    np.testing.assert_allclose(mount_rotation_flu(q), mount_rotation_flu(down30), atol=1e-15)
    left_up = fan_directions_flu(_rf(orientation=100, rotation_flu_deg=(0.0, -30.0, 90.0)))[0]
    np.testing.assert_allclose(left_up, (0.0, C30, S30), atol=1e-15)         # left and 30 deg up
    # a quaternion given unnormalised is the same rotation
    q2 = _rf(orientation=100, quaternion_flu_wxyz=(2 * C15, 0.0, 2 * S15, 0.0))
    np.testing.assert_allclose(mount_rotation_flu(q2), mount_rotation_flu(q), atol=1e-15)


def test_custom_fan_spans_the_sensor_axes():
    """Roll 90 turns the sensor's horizontal field of view into the vertical."""
    cfg = RangefinderConfig(id=0, orientation=100, rotation_flu_deg=(90.0, 0.0, 0.0), hfov_deg=20.0, vfov_deg=0.0)
    rays = fan_directions_flu(cfg)
    t = math.tan(math.radians(10.0))
    assert len(rays) == 3
    np.testing.assert_allclose(sorted(r[2] for r in rays[1:]), [-t / math.hypot(1, t), t / math.hypot(1, t)],
                               atol=1e-15)
    assert all(abs(r[1]) < 1e-15 for r in rays)


# --- hand-worked distances ---------------------------------------------------------------


def test_down_sensor_below_the_centre():
    r = _reading(_rf(orientation=25, position_flu_m=(0.0, 0.0, -0.1)), World.build(), (3.0, 4.0, 2.0))
    assert r.distance_m == pytest.approx(1.9)


def test_forward_down_custom_from_its_mount():
    cfg = _rf(orientation=100, rotation_flu_deg=(0.0, 30.0, 0.0), position_flu_m=(0.2, 0.0, -0.05))
    r = _reading(cfg, World.build(), (0.0, 0.0, 2.0))
    assert r.distance_m == pytest.approx(1.95 / S30)                          # 3.9 m of slant range


def test_offset_turns_with_the_heading():
    wall = World.build(obstacles=(ObstacleConfig("box", x=0.0, y=6.0, height=5.0, size_x=10.0, size_y=2.0),))
    # heading north: body x = world y; the nose sensor sits 0.2 m further north than the centre
    r = _reading(_rf(orientation=0, position_flu_m=(0.2, 0.0, 0.5)), wall, (0.0, 0.0, 1.0), _Rz(math.pi / 2))
    assert r.distance_m == pytest.approx(5.0 - 0.2)
    # heading east, the left sensor (orientation 6) 0.15 m to the left of the centre looks north
    r = _reading(_rf(orientation=6, position_flu_m=(0.0, 0.15, 0.0)), wall, (0.0, 0.0, 1.0))
    assert r.distance_m == pytest.approx(5.0 - 0.15)


def test_offset_and_beam_follow_the_attitude():
    """Nose down 30 deg at 2 m: the nose sensor 0.2 m ahead sits 0.1 m lower
    and looks 30 deg down, so it reads 1.9 / sin 30 = 3.8 m."""
    r = _reading(_rf(orientation=0, position_flu_m=(0.2, 0.0, 0.0)), World.build(), (0.0, 0.0, 2.0),
                 _Ry(math.radians(30.0)))
    assert r.distance_m == pytest.approx(3.8)


# --- DISTANCE_SENSOR fields -------------------------------------------------------------------


@pytest.mark.parametrize("cfg, q_frd", [
    (_rf(orientation=0), (1.0, 0.0, 0.0, 0.0)),
    (_rf(orientation=25), (H, 0.0, -H, 0.0)),                    # PITCH_270 about FRD y
    (_rf(orientation=24), (H, 0.0, H, 0.0)),                     # PITCH_90
    (_rf(orientation=2), (H, 0.0, 0.0, H)),                      # YAW_90: right
    (_rf(orientation=6), (H, 0.0, 0.0, -H)),                     # YAW_270: left (w >= 0)
    (_rf(orientation=100, rotation_flu_deg=(0.0, 30.0, 0.0)), (C15, 0.0, -S15, 0.0)),   # FRD pitch -30
    # FLU yaw 90 pitch -30 = FRD yaw -90 pitch +30: q = qz(-90) qy(30), worked by hand
    (_rf(orientation=100, rotation_flu_deg=(0.0, -30.0, 90.0)), (H * C15, H * S15, H * S15, -H * C15)),
])
def test_mount_quaternion_in_frd_both_ways(cfg, q_frd):
    R_flu = mount_rotation_flu(cfg)
    q = codec.mount_quaternion_frd(R_flu)
    np.testing.assert_allclose(q, q_frd, atol=1e-12)
    np.testing.assert_allclose(codec.mount_rotation_flu_of(q), np.array(R_flu).reshape(3, 3), atol=1e-12)
    # MAVLink: zero rotation looks along body x; the quaternion turns x into the beam (FRD)
    beam_frd = frames.quat_wxyz2rotmat(q)[:, 0]
    np.testing.assert_allclose(beam_frd, frames.flu2frd(fan_directions_flu(cfg)[0]), atol=1e-12)


def _wire(reading):
    mav = mavlink.MAVLink(None, 1, 1)
    buf = codec.PACK_DISTANCE_SENSOR.pack(mav, codec.distance_sensor_args(1234, reading))
    return mavlink.MAVLink(None).decode(bytearray(buf))


def test_distance_sensor_fields_on_the_wire():
    R = mount_rotation_flu(_rf(orientation=100, rotation_flu_deg=(0.0, 30.0, 0.0)))
    m = _wire(RangeReading(9, 100, 3.9, 0.2, 12.0, math.radians(8.0), math.radians(4.0), R, 0.03))
    assert (m.id, m.orientation, m.current_distance, m.min_distance, m.max_distance) == (9, 100, 390, 20, 1200)
    assert m.covariance == 9 and m.signal_quality == 100 and m.time_boot_ms == 1234
    assert m.horizontal_fov == pytest.approx(math.radians(8.0)) and m.vertical_fov == pytest.approx(math.radians(4.0))
    np.testing.assert_allclose(m.quaternion, (C15, 0.0, -S15, 0.0), atol=1e-7)
    # no return: max + 1 cm, signal quality 1 (invalid)
    m = _wire(RangeReading(9, 100, None, 0.2, 12.0, 0.1, 0.1, R, 0.03))
    assert m.current_distance == 1201 and m.signal_quality == 1
    # covariance: 0 for a noiseless sensor, capped below 255 (unknown)
    assert _wire(RangeReading(1, 0, 1.0, 0.1, 10.0, 0.0, 0.0, noise_std_m=0.0)).covariance == 0
    assert _wire(RangeReading(1, 0, 1.0, 0.1, 10.0, 0.0, 0.0, noise_std_m=0.5)).covariance == 254


# --- mission keys ------------------------------------------------------------------------------


@pytest.mark.parametrize("kw, match", [
    (dict(orientation=100), "exactly one"),
    (dict(orientation=100, rotation_flu_deg=(0.0, 0.0, 0.0), quaternion_flu_wxyz=(1.0, 0.0, 0.0, 0.0)),
     "exactly one"),
    (dict(orientation=0, rotation_flu_deg=(0.0, 30.0, 0.0)), "orientation 100"),
    (dict(orientation=100, quaternion_flu_wxyz=(0.0, 0.0, 0.0, 0.0)), "zero"),
    (dict(orientation=0, position_flu_m=(20.0, 0.0, 0.0)), "position_flu_m"),
    (dict(orientation=8), "orientation must be one of"),
])
def test_rangefinder_config_rejects(kw, match):
    with pytest.raises(ValueError, match=match):
        RangefinderConfig(id=0, **kw)
