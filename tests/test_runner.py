"""companion.runner pure helpers: the takeoff segment, the setpoint yaw, the flight log."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.runner import FlightLog, climb_duration_s, pointing_at, setpoint_yaw_enu, smooth_segment


def test_smooth_segment_ends_at_rest_and_derivatives_are_consistent():
    p0, p1, T = (1.0, 2.0, 0.0), (4.0, -2.0, 1.5), 3.0
    p, v, a, j, s = smooth_segment(p0, p1, T, 0.0)
    assert p == pytest.approx(p0) and v == pytest.approx((0, 0, 0)) and a == pytest.approx((0, 0, 0))
    assert j == pytest.approx((0, 0, 0))
    p, v, a, j, s = smooth_segment(p0, p1, T, T)
    assert p == pytest.approx(p1) and v == pytest.approx((0, 0, 0), abs=1e-12)
    assert a == pytest.approx((0, 0, 0), abs=1e-12) and j == pytest.approx((0, 0, 0), abs=1e-12)
    # each derivative is the central difference of the one before it
    h = 1e-5
    for t in (0.4, 1.5, 2.7):
        lo, hi = smooth_segment(p0, p1, T, t - h), smooth_segment(p0, p1, T, t + h)
        mid = smooth_segment(p0, p1, T, t)
        for k in range(4):
            fd = (np.array(hi[k]) - np.array(lo[k])) / (2 * h)
            np.testing.assert_allclose(fd, mid[k + 1], rtol=1e-5, atol=1e-6)
    # peak speed 35/16 of the mean, at mid-time
    v_mid = np.linalg.norm(smooth_segment(p0, p1, T, T / 2)[1])
    assert v_mid == pytest.approx(35 / 16 * math.dist(p0, p1) / T)
    assert climb_duration_s(2.0, 1.0) == pytest.approx(35 / 16 * 2.0)
    assert climb_duration_s(0.1, 1.0) == 3.0


def test_setpoint_yaw_from_pointing():
    # hover, pointing north: b2d = north, b1d = north x up = east -> ENU yaw 0
    assert setpoint_yaw_enu((0.0, 1.0, 0.0), (0.0, 0.0, 0.0)) == pytest.approx(0.0)
    # pointing west: b1d = west x up = north -> yaw +90 deg
    assert setpoint_yaw_enu((-1.0, 0.0, 0.0), (0.0, 0.0, 0.0)) == pytest.approx(math.pi / 2)
    # pointing east and slightly down: same heading as level east (b1d = south)
    s = np.array((1.0, 0.0, -0.3)) / math.hypot(1.0, 0.3)
    assert setpoint_yaw_enu(s, (0.0, 0.0, 0.0)) == pytest.approx(-math.pi / 2)
    # a forward acceleration tilts b3d but the heading of b1d stays put
    assert setpoint_yaw_enu((0.0, 1.0, 0.0), (0.0, 2.0, 0.0)) == pytest.approx(0.0, abs=1e-12)
    assert pointing_at((0, 0, 1), (3, 4, 1)) == pytest.approx((0.6, 0.8, 0.0))


def test_flight_log_rows_from_flat_buffer():
    log = FlightLog()
    n = len(FlightLog.COLUMNS)
    assert log.array().shape == (0, n)
    rows = [tuple(float(k * 100 + j) for j in range(n)) for k in range(3)]
    for r in rows:
        log.data.extend(r)
    a = log.array()
    assert a.shape == (3, n)
    assert log.rows == rows
    np.testing.assert_array_equal(log.column("ref_y"), [k * 100 + FlightLog.COLUMNS.index("ref_y") for k in range(3)])
    log.data.extend((1.0, 2.0))            # a partial row is a bug, not data
    with pytest.raises(ValueError):
        log.array()
