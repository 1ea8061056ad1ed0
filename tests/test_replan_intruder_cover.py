"""Low obstacles seen in time (companion.replan.intruder_cover): hand-worked cases.

One beam facing the direction of travel (body x), 24 deg wide; the vehicle's
centre 1.5 m over flat ground; clearance sphere keep = 0.5 + 0.442 m; braking
1 m/s^2; delay 0.05 s (20 Hz) + 0.1 s. The speed a range R allows for a stop
c short of it: v^2 / 2 + 0.15 v = R - c.
"""

import math

import numpy as np
import pytest

from companion.replan.coverage_check import Beam, CONTROL_DELAY_S
from companion.replan.intruder_cover import depression_interval, ground_tangent, low_allowed_speed
from mavcore import frames

KEEP = 0.942
TAU = 0.05 + CONTROL_DELAY_S


def _beam(pitch_down_deg: float, vfov_deg: float, max_m: float = 6.0) -> Beam:
    R = frames.euler_zyx2rotmat(0.0, math.radians(pitch_down_deg), 0.0)
    return Beam(0, np.asarray(R, dtype=float), math.tan(math.radians(12.0)),
                math.tan(math.radians(0.5 * vfov_deg)), max_m, 0.05)


def _v(range_m: float, c: float) -> float:
    return -TAU + math.sqrt(TAU * TAU + 2.0 * (range_m - c))


FORWARD = np.array([[1.0, 0.0, 0.0]])


def test_trace_of_a_pitched_beam_on_the_plane_of_travel():
    # pitched 6 deg down, 16 deg tall: depressions -2 .. 14 deg along its axis
    b = _beam(6.0, 16.0)
    lo, hi = depression_interval(FORWARD @ b.rotation_flu, b.rotation_flu[2, :], b.tan_half_h, b.tan_half_v)
    assert lo[0] == pytest.approx(math.tan(math.radians(-2.0)), abs=1e-12)
    assert hi[0] == pytest.approx(math.tan(math.radians(14.0)), abs=1e-12)
    # its steepest ray: 14 deg down, sin 14 of it downward
    assert ground_tangent(b.rotation_flu[2, :], b.tan_half_h, b.tan_half_v) == pytest.approx(
        math.sin(math.radians(14.0)), abs=1e-9)


def test_a_level_beam_never_sees_the_lowest_top_in_range():
    # +-5 deg: a top 0.942 m down is in view only beyond 0.942 / tan 5 = 10.8 m > 6 m
    v = low_allowed_speed(FORWARD, np.array([1.5]), (_beam(0.0, 10.0),), 1.0, KEEP, CONTROL_DELAY_S)
    assert v[0] == 0.0


def test_a_beam_pitched_down_sees_them_all_at_the_range():
    # +2 .. -14 deg: the lowest top is in view from 3.78 m, the ground 1.5 / sin 14 = 6.2 m
    # away is out of range: the range binds. A top level with the centre needs 6 - 0.942;
    # the check's depth grid takes the first step's far end sqrt(36 - (0.942/8)^2) with it
    v = low_allowed_speed(FORWARD, np.array([1.5]), (_beam(6.0, 16.0),), 1.0, KEEP, CONTROL_DELAY_S)
    assert _v(math.sqrt(36.0 - (KEEP / 8) ** 2), KEEP) - 1e-12 <= v[0] <= _v(6.0, KEEP)


def test_the_ground_hides_what_is_beyond_it():
    # -20 .. -30 deg: the ground is 1.5 / sin 30 = 3 m away; a top just below the centre is
    # in view from its upper edge, at depth D tan 20 and slant D / cos 20 < 3: D < 3 cos 20
    v = low_allowed_speed(FORWARD, np.array([1.5]), (_beam(25.0, 10.0),), 1.0, KEEP, CONTROL_DELAY_S)
    assert v[0] == pytest.approx(_v(3.0 * math.cos(math.radians(20.0)), KEEP), rel=1e-9)


def test_returns_near_the_ground_are_the_ground():
    # the replanner takes a return within 0.2 m of the nearest ground in view for the
    # ground: the view ends 0.2 m short of the 3 m, D / cos 20 < 2.8
    v = low_allowed_speed(FORWARD, np.array([1.5]), (_beam(25.0, 10.0),), 1.0, KEEP, CONTROL_DELAY_S,
                          ground_band_m=0.2)
    assert v[0] == pytest.approx(_v(2.8 * math.cos(math.radians(20.0)), KEEP), rel=1e-9)


def test_terrain_rising_ahead_closes_the_view():
    # the slope rises 0.25 m per m ahead: the steepest ray (14 deg down) meets it at
    # s = 1.5 / (tan 14 + 0.25) = 3.0 m, nearer than where the lowest top comes into view (3.78 m)
    s = np.arange(0.25, 6.01, 0.25)
    drop = (1.5 - 0.25 * s)[None, :]
    b = (_beam(6.0, 16.0),)
    assert low_allowed_speed(FORWARD, np.array([1.5]), b, 1.0, KEEP, CONTROL_DELAY_S, (s, drop))[0] == 0.0
    flat = (s, np.full((1, s.size), 1.5))
    assert low_allowed_speed(FORWARD, np.array([1.5]), b, 1.0, KEEP, CONTROL_DELAY_S, flat)[0] > 3.0


def test_nothing_lower_fits_on_the_ground():
    v = low_allowed_speed(FORWARD, np.array([0.0]), (_beam(0.0, 10.0),), 1.0, KEEP, CONTROL_DELAY_S)
    assert v[0] == math.inf
