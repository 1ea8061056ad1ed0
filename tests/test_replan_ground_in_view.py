"""The ground anywhere in a beam's field of view explains a return
(``KnownMap.ground_in_view_m``): a side beam of a vehicle pitched 15 deg is
rolled 15 deg about its own axis, and its field of view meets the ground first
at a corner, where neither the axis nor the edge midpoints look (lossy
real-time flights of ``tests/test_outcomes_e2e.py`` with the low ring: ground
returns 5-5.8 m away at a corner, read as obstacles beyond the map)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavcore.maps.grid import ElevationModel, OccupancyGrid
from companion.coverage.freespace import erode_free_space
from companion.replan import KnownMap


def _km(slope=0.0):
    occ = np.zeros((100, 100), dtype=bool)
    grid = OccupancyGrid(occupied=occ, free=~occ, resolution_m=0.1)
    dem = ElevationModel(np.array([[0.0, slope * 20.0], [0.0, slope * 20.0]]), x0_m=-5.0, y0_m=-5.0, cellsize_m=20.0)
    return KnownMap.build(grid, dem, erode_free_space(grid, 0.5), 2.0, 0.2)


def _frame(pitch_down_deg, roll_deg, yaw_deg=0.0):
    """(axis, h_axis, v_axis) ENU of a beam pitched down, then rolled about its own axis."""
    p, r, y = (math.radians(v) for v in (pitch_down_deg, roll_deg, yaw_deg))
    # sensor frame: x the beam, y left, z up; roll about x, pitch down about y, yaw about z
    Rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    Ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    Rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    M = Rz @ Ry @ Rx
    return tuple(M[:, 0]), tuple(M[:, 1]), tuple(M[:, 2])


def _brute(slope, o, axis, h, v, half_h, half_v, n=601):
    """Nearest ground over a dense grid of directions filling the field of view, each
    met with the terrain exactly (the DEM of ``_km``, bilinear between its cell centres at
    x = -5 and 15 m, is the plane z = slope (x + 5) there):
    independent of the projection."""
    a, b = math.tan(half_h), math.tan(half_v)
    ys, zs = np.meshgrid(np.linspace(-a, a, n), np.linspace(-b, b, n))
    d = np.stack([np.ones_like(ys), ys, zs], -1).reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1)[:, None]
    w = d @ np.column_stack([axis, h, v]).T
    # o_z + t w_z = slope (o_x + t w_x + 5)
    den = w[:, 2] - slope * w[:, 0]
    num = slope * (o[0] + 5.0) - o[2]
    with np.errstate(divide="ignore"):
        t = num / den
    t = t[(den < 0) & (t > 0)]
    return float(t.min()) if t.size else math.inf


HALF_H, HALF_V = math.radians(12.0), math.radians(5.0)


def test_level_beam_sees_flat_ground_along_its_lower_edge():
    km = _km()
    axis, h, v = _frame(0.0, 0.0)
    assert km.ground_in_view_m((0.0, 0.0, 1.5), axis, h, v, HALF_H, HALF_V) == pytest.approx(
        1.5 / math.sin(HALF_V), rel=1e-12)


@pytest.mark.parametrize("pitch,roll", [(10.0, 0.0), (10.0, -15.0), (7.5, 15.3), (0.0, 30.0), (20.0, 5.0)])
def test_flat_ground_matches_a_dense_search(pitch, roll):
    km = _km()
    o = (0.0, 0.0, 1.5)
    axis, h, v = _frame(pitch, roll, 37.0)
    got = km.ground_in_view_m(o, axis, h, v, HALF_H, HALF_V)
    want = _brute(0.0, o, axis, h, v, HALF_H, HALF_V)
    # the grid of directions is a step of 0.04 deg: its minimum is a hair above the true one
    assert got <= want + 1e-9 and want - got < 0.01 * want


def test_a_rolled_beam_sees_the_ground_first_at_a_corner():
    """Pitched 7.5 deg down, rolled 15 deg: the axis and the lower edge midpoint meet
    the ground farther than the lowest corner does."""
    km = _km()
    axis, h, v = _frame(7.5, 15.0)
    t = km.ground_in_view_m((0.0, 0.0, 1.5), axis, h, v, HALF_H, HALF_V)
    low_edge = np.array(axis) - math.tan(HALF_V) * np.array(v)
    low_edge /= np.linalg.norm(low_edge)
    assert t < 1.5 / -low_edge[2] - 0.3


def test_sloped_ground_matches_a_dense_search():
    km = _km(slope=0.1)                      # rising 10 % toward +x
    o = (5.0, 0.0, 1.5 + km.height(5.0, 0.0))            # every hit within x -5..15 m, on the plane
    for pitch, roll, yaw in ((10.0, 0.0, 0.0), (10.0, 12.0, 0.0), (8.0, -10.0, 180.0), (12.0, 5.0, 90.0)):
        axis, h, v = _frame(pitch, roll, yaw)
        got = km.ground_in_view_m(o, axis, h, v, HALF_H, HALF_V)
        want = _brute(0.1, o, axis, h, v, HALF_H, HALF_V)
        # a planar slope: the tangent plane is the terrain, so the same as flat (0.04 deg steps)
        assert got <= want + 1e-9 and want - got < 0.01 * want, (pitch, roll, yaw, got, want)


def test_a_beam_above_the_horizon_sees_no_ground():
    km = _km()
    axis, h, v = _frame(-10.0, 0.0)
    assert km.ground_in_view_m((0.0, 0.0, 1.5), axis, h, v, HALF_H, HALF_V) == math.inf


def test_replanner_explains_the_corner_ground_and_not_a_nearer_return():
    """A beam rolled 15 deg: the ground in view at t explains a return at t; a return
    0.5 m nearer (an obstacle in front of the ground) is not explained."""
    from companion.replan.perception import BeamEvidence
    from companion.replan.replanner import Replanner
    km = _km()
    axis, h, v = _frame(7.5, 15.0)
    o = (0.0, 0.0, 1.5)
    t = km.ground_in_view_m(o, axis, h, v, HALF_H, HALF_V)

    def ev(d):
        hit = tuple(o[i] + d * axis[i] for i in range(3))
        return BeamEvidence(o, axis, h, v, HALF_H, HALF_V, d, hit, d, ())

    rp = Replanner.__new__(Replanner)
    rp.known = km
    assert Replanner._explained(rp, ev(t))
    assert Replanner._explained(rp, ev(t + 0.5))
    assert not Replanner._explained(rp, ev(t - 0.5))
