"""OBSTACLE_DISTANCE packing (companion/link/obstacle_distance.py) and its decoding
by the SITL (mavcore/codec/vehicle_end.py), with hand-worked sectors.

Sector i is centred i * 5 deg clockwise of forward (body FRD); a beam looking
theta deg to the left (FLU azimuth +theta) is centred on FRD -theta = 360 - theta.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore import frames
from mavcore.codec import Range, sensor_rotation_flu
from companion.link.obstacle_distance import (UNKNOWN_CM, ObstacleDistancePublisher, encode_obstacle_distance,
                                              pack_sectors, sector_beam)
from mavcore.codec import decode_obstacle_distance


def _rot_flu(yaw_left_deg, pitch_down_deg=0.0):
    R = frames.euler_zyx2rotmat(0.0, math.radians(pitch_down_deg), math.radians(yaw_left_deg))
    return tuple(np.asarray(R).ravel().tolist())


def _range(sensor_id, R, d_m, hfov_deg, max_m=6.0, min_m=0.1, no_return=False):
    return Range(0, sensor_id, math.nan if no_return else d_m, min_m, max_m, 100, math.radians(hfov_deg),
                 math.radians(10.0), math.nan, no_return, R)


def _readings():
    return [
        _range(0, _rot_flu(0.0), 3.0, 24.0),                   # forward, 24 deg: sectors 70, 71, 0, 1, 2
        _range(1, _rot_flu(90.0), math.nan, 0.0, no_return=True),  # left, a ray: sector 54 (270 deg), free
        _range(2, _rot_flu(-22.0), 2.5, 3.0),                  # 22 deg right, 3 deg: no centre inside; nearest 4
        _range(3, _rot_flu(-5.0), 2.0, 4.0),                   # 5 deg right: sector 1, under the forward beam
        _range(4, _rot_flu(180.0, 4.0), 4.0, 2.0),             # backward, 4 deg down (field +-5): sector 36, 4 cos 4
        _range(7, _rot_flu(135.0, 9.0), 5.8, 24.0),            # back-left, 9 deg down (4-14): the ground, left out
        _range(5, sensor_rotation_flu(25), 1.5, 5.0, max_m=20.0),   # down: not in the horizontal picture
        _range(6, _rot_flu(-90.0), 5.0, 0.0, max_m=10.0, min_m=0.2),  # right, 10 m: sector 18
    ]


def _expected_cm():
    want = [UNKNOWN_CM] * 72
    for i in (70, 71, 0, 2):
        want[i] = 300
    want[1] = 200                                  # the smaller of 3.00 and 2.00 m
    want[4] = 250
    want[54] = 600                                 # its own 6 m: free up to there (the message's max is 10 m)
    want[36] = int(round(400 * math.cos(math.radians(4.0))))    # 399
    want[18] = 500
    return want


def test_pack_sectors_by_hand():
    beams = [b for b in (sector_beam(r) for r in _readings()) if b is not None]
    assert len(beams) == 6                          # the down-looking one and the low one are left out
    s = pack_sectors(beams)
    assert list(s.distances_cm) == _expected_cm()
    assert (s.min_cm, s.max_cm) == (10, 1000)
    # no return from the longest sensor: "no obstacle" (max_distance + 1)
    s = pack_sectors([sector_beam(_range(6, _rot_flu(-90.0), math.nan, 0.0, max_m=10.0, no_return=True))])
    assert s.distances_cm[18] == 1001 and s.distances_cm.count(UNKNOWN_CM) == 71


def test_packed_message_decodes_in_the_sitl_to_the_same_sectors():
    beams = [b for b in (sector_beam(r) for r in _readings()) if b is not None]
    enc = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    buf = encode_obstacle_distance(enc, 12_345_000, pack_sectors(beams)).pack(enc)
    msg = mavlink.MAVLink(None).parse_char(buf)
    assert msg.get_type() == "OBSTACLE_DISTANCE" and msg.frame == mavlink.MAV_FRAME_BODY_FRD
    assert msg.increment_f == 5.0 and msg.angle_offset == 0.0 and msg.time_usec == 12_345_000
    dec = decode_obstacle_distance(msg)
    assert dec.azimuth_flu_rad.shape == (72,) and dec.half_width_rad == pytest.approx(math.radians(2.5))
    # sector 18 is 90 deg clockwise (right): FLU azimuth -90 deg; sector 54 left: +90 deg
    assert dec.azimuth_flu_rad[0] == 0.0
    assert dec.azimuth_flu_rad[18] == pytest.approx(-math.pi / 2) and dec.azimuth_flu_rad[54] == pytest.approx(
        math.pi / 2)
    want = np.array(_expected_cm(), dtype=float)
    expect_m = np.where(want == UNKNOWN_CM, math.nan, want / 100.0)
    np.testing.assert_array_equal(dec.distance_m, expect_m)
    # and back: each decoded distance sits in the sector the beam's direction falls in
    for r in _readings():
        b = sector_beam(r)
        if b is None or math.isnan(b.horizontal_m):
            continue
        off = np.abs((dec.azimuth_flu_rad - b.azimuth_flu_rad + math.pi) % (2 * math.pi) - math.pi)
        assert dec.distance_m[int(np.argmin(off))] <= round(b.horizontal_m, 2)


def test_sitl_decoder_reads_the_other_conventions():
    enc = mavlink.MAVLink(None)
    d = [UNKNOWN_CM] * 72
    d[0], d[1], d[2] = 150, 2001, 5                 # an obstacle, nothing, closer than min_distance
    m = enc.obstacle_distance_encode(0, 0, d, 10, 20, 2000, 0.0, -30.0, mavlink.MAV_FRAME_BODY_FRD)
    dec = decode_obstacle_distance(mavlink.MAVLink(None).parse_char(m.pack(enc)))
    # uint8 increment 10 deg: 36 sectors used; offset -30: sector 0 is 30 deg left
    assert dec.distance_m.shape == (36,)
    assert dec.azimuth_flu_rad[0] == pytest.approx(math.radians(30.0))
    assert dec.azimuth_flu_rad[3] == pytest.approx(0.0, abs=1e-12)
    assert dec.distance_m[0] == 1.5 and math.isinf(dec.distance_m[1]) and dec.distance_m[2] == 0.2
    assert np.isnan(dec.distance_m[3:]).all()
    m = enc.obstacle_distance_encode(0, 0, d, 5, 20, 2000, 0.0, 0.0, mavlink.MAV_FRAME_GLOBAL)
    assert decode_obstacle_distance(mavlink.MAVLink(None).parse_char(m.pack(enc))) is None


def test_publisher_runs_at_10_hz_on_the_vehicle_clock_and_drops_stale_readings():
    pub = ObstacleDistancePublisher()
    fwd = _range(0, _rot_flu(0.0), 3.0, 24.0)
    left = _range(1, _rot_flu(90.0), 2.0, 24.0)
    sent = [t for t in np.arange(0.0, 1.0, 0.05) if pub.on_range(float(t), fwd) is not None]
    assert len(sent) == 10 and np.allclose(np.diff(sent), 0.1)     # 20 Hz readings, 10 Hz messages
    pub.on_range(1.0, left)
    # 0.6 s later only the forward beam keeps reading: the left one is no evidence any more
    s = pub.on_range(1.6, fwd)
    assert s.distances_cm[0] == 300 and s.distances_cm[54] == UNKNOWN_CM
    s = pub.on_range(1.7, left)
    assert s.distances_cm[54] == 200


def test_sitl_decoder_survives_any_field_values():
    rng = np.random.default_rng(15)
    enc = mavlink.MAVLink(None)
    specials = [0.0, -0.0, math.nan, math.inf, -math.inf, 1e-30, 1e30, -5.0, 361.0, 360.0]
    for _ in range(300):
        d = [int(x) for x in rng.integers(0, 65536, 72)]
        inc_f = float(rng.choice(specials + [float(rng.uniform(-400, 400))]))
        off = float(rng.choice(specials + [float(rng.uniform(-1e4, 1e4))]))
        m = enc.obstacle_distance_encode(0, int(rng.integers(0, 256)), d, int(rng.integers(0, 256)),
                                         int(rng.integers(0, 65536)), int(rng.integers(0, 65536)), inc_f, off,
                                         int(rng.choice([0, 1, 12, 255])))
        dec = decode_obstacle_distance(mavlink.MAVLink(None).parse_char(m.pack(enc)))
        if dec is not None:
            n = dec.distance_m.shape[0]
            assert 1 <= n <= 72 and dec.azimuth_flu_rad.shape == (n,)
            assert np.all(np.abs(dec.azimuth_flu_rad) <= math.pi) and dec.half_width_rad > 0.0
            assert not np.any(dec.distance_m < 0.0)
