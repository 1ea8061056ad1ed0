"""The stopping point of the avoiding reference (``Replanner._shape``, docs/replan.md "The
stopping point") and the way out of a clearance the vehicle stopped inside
(``companion.replan.margin_exit``).

Scene as tests/test_replan_rows.py: one row, cells x in [5.0, 5.2], y in [0, 5.0], canopy
2 m, flat ground; R = 0.4, clearance 0.5: the guard keeps 0.85 m from the row (0.9 m less
half a cell), so the row's clearance begins at x = 4.15 beside its face.
"""

from __future__ import annotations

import types

import numpy as np
import pytest

from mavcore.maps.grid import ElevationModel, OccupancyGrid
from companion.replan.margin_exit import margin_exit
from companion.replan.replanner import STOP_MARGIN_M, Replanner
from companion.replan.shaper import ReferenceShaper
from mavcore.mission.replan import ReplanConfig
from companion.safety import Guard, GuardConfig, SafetyScene

R, C = 0.4, 0.5
REQ_ROW = R + C - 0.05
FACE_X = 5.0
DT = 0.004


def _box(lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)

    def dist(points):
        p = np.asarray(points, float).reshape(-1, 3)
        e = np.maximum(np.maximum(lo - p, p - hi), 0.0)
        return np.sqrt((e * e).sum(axis=1))
    return dist


def _guard(obstacle_distance=None) -> Guard:
    occ = np.zeros((100, 100), bool)
    occ[0:50, 50:52] = True
    grid = OccupancyGrid(occ, ~occ, 0.1)
    dem = ElevationModel(np.zeros((11, 11)), 0.0, 0.0, 1.0)
    cfg = GuardConfig(airframe_radius_m=R, terrain_clearance_m=C, row_clearance_m=C, obstacle_clearance_m=C,
                      accel_m_s2=1.0, delay_s=0.2)
    return Guard(cfg, SafetyScene.from_maps(grid, dem, 2.0), obstacle_distance)


def _shaping(guard):
    """What ``_shape`` and ``_govern_rows`` read, on a bare object (a whole replanner needs
    a plan); braking at half the 1 m/s^2 limit, as the replanner's governor does."""
    rp = types.SimpleNamespace(guard=guard, shaper=ReferenceShaper(1.0, 2.0), n_stop_limited=0, _brake=0.5,
                               cfg=ReplanConfig(accel_m_s2=1.0, jerk_m_s3=2.0), emergency=False,
                               n_emergency_brakes=0, _evading=False, _emergency_why="",
                               _gate_since=None, _t_s=0.0, _brake_stepped=False,
                               known=types.SimpleNamespace(ground_z=lambda x, y: 0.0))     # flat, z = 0
    for name in ("_shape", "_govern_rows", "_allowed_speed", "_least_room", "_set_emergency", "_calm",
                 "_height_band", "_wall_speed"):
        setattr(rp, name, types.MethodType(getattr(Replanner, name), rp))
    return rp


def _step(rp, cmd):
    """One frame of ``_shape`` on the vehicle's clock."""
    rp._t_s += DT
    return rp._shape(DT, cmd)


def _fly(rp, rows: Guard, seconds=6.0):
    """Flight 15's shape: the mode asks for 0.8 m/s toward the row's face and 0.6 m/s along
    it, and the row governor (``_govern_rows``, the command's law) limits the approach; the
    reference starts 2.3 m from the face at 0.8 m/s, still accelerating toward it at
    0.6 m/s^2 (its brake from there ends 4.07 m: the rule holds at the start)."""
    rp.shaper.reset((2.7, 1.0, 1.0), (0.8, 0.0, 0.0), (0.6, 0.0, 0.0), (0.0, 0.0, 0.0))
    out = []
    for _ in range(int(seconds / DT)):
        P = np.array(rp.shaper.p)
        rp.guard = rows
        cmd = rp._govern_rows(P, np.array([0.8, 0.6, 0.0]))
        rp.guard = rp.judge
        out.append(_step(rp, cmd).p)
    return np.array(out)


def test_the_shaped_reference_stops_before_the_row_whose_approach_the_command_limits():
    rows = _guard()
    plain = _shaping(None)
    plain.judge = None
    p0 = _fly(plain, rows)
    # without the rule the shaper's lag carries the reference into the row's clearance,
    # the command governed all along: 0.81 m from the face
    assert (FACE_X - p0[:, 0]).min() < REQ_ROW - 0.03
    rp = _shaping(rows)
    rp.judge = rows
    p = _fly(rp, rows)
    # with it: never inside the clearance (distance to the face, hand: 5.0 - x) ...
    assert (FACE_X - p[:, 0]).min() >= REQ_ROW
    # ... and not held back far beyond its margin: it comes within 0.15 m of the clearance
    # plus STOP_MARGIN_M, and still flies along the row
    assert (FACE_X - p[:, 0]).min() <= REQ_ROW + STOP_MARGIN_M + 0.15
    assert p[-1, 1] - p[0, 1] > 1.5
    assert rp.n_stop_limited > 0


def test_far_from_everything_the_command_is_flown_as_shaped():
    rp, plain = _shaping(_guard()), _shaping(None)
    for sh in (rp, plain):
        sh.shaper.reset((1.0, 8.0, 1.5), (0.5, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    a = np.array([_step(rp, (1.0, 0.2, 0.0)).p for _ in range(200)])
    b = np.array([_step(plain, (1.0, 0.2, 0.0)).p for _ in range(200)])
    assert np.array_equal(a, b) and rp.n_stop_limited == 0


def test_the_way_out_of_an_obstacle_clearance_is_straight_away_from_its_face():
    # a box whose face is y = 7; stopped 0.5 m from it (the clearance is 0.9 m): with a 0.3 m
    # margin less 2 cm (off the step grid) the nearest point out is 1.18 m from the face: the
    # first 5 cm step beyond 0.68 m straight along +y, 0.70 m
    g = _guard(_box((4.0, 6.0, 0.0), (8.0, 7.0, 3.0)))
    leg = margin_exit(g, (6.0, 7.5, 1.5), 0.6, 2.9, 0.28)
    assert leg[0] == pytest.approx([6.0, 7.5, 1.5])
    assert leg[1] == pytest.approx([6.0, 8.2, 1.5], abs=1e-9)
    # already out: no leg
    assert margin_exit(g, (6.0, 8.5, 1.5), 0.6, 2.9, 0.3) is None


def test_no_way_out_through_the_ceiling_or_closer_to_something_else():
    # over the box's top (z = 2.0) at 2.5 m, 0.5 m above it, ceiling 2.6 m: up is barred; the
    # box spans x 4..8, y 6..7, so the nearest level way out is across its narrow side,
    # +y or -y from y = 6.5: out where the distance to the box reaches 1.2 m
    g = _guard(_box((4.0, 6.0, 0.0), (8.0, 7.0, 2.0)))
    leg = margin_exit(g, (6.0, 6.5, 2.5), 0.6, 2.6, 0.3)
    end = leg[1]
    assert end[2] == pytest.approx(2.5)
    # the end is the first 5 cm step 1.2 m out: horizontal offset h from the face with
    # h^2 + 0.5^2 >= 1.2^2, h >= 1.091 m, so |dy| = 0.5 + 1.10 = 1.60 m
    assert abs(end[1] - 6.5) == pytest.approx(1.60, abs=1e-9) and end[0] == pytest.approx(6.0)


def test_inside_its_margin_the_reference_may_creep_to_the_clearance_not_into_it():
    # at rest 2 cm inside the stopping point's margin (0.87 m from the face; the band is
    # 0.85-0.90 m), the command asks 0.02 m/s toward the row and 0.3 m/s along it for 3 s:
    # judged afresh every frame, a closing allowed per frame adds up (5 mm a frame let a climb
    # creep 0.15 m into a row's clearance); it may close to the clearance, never into it
    rp = _shaping(_guard())
    rp.shaper.reset((FACE_X - (REQ_ROW + 0.02), 1.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    p = np.array([_step(rp, (0.02, 0.3, 0.0)).p for _ in range(int(3.0 / DT))])
    # (the 2 mm: the brake predicted every 0.05 s runs a little short of the frame-stepped
    # one that is flown)
    assert (FACE_X - p[:, 0]).min() >= REQ_ROW - 0.002
    assert p[-1, 1] - p[0, 1] > 0.5                       # along the row it goes on


def test_inside_the_clearance_the_reference_does_not_close():
    # 2 cm inside the row's clearance itself (the map grew, or a mode handed over there): the
    # same command; closer only by the prediction's millimetres, and along the row it goes on
    # (every candidate keeping the state's last 1 mm/s toward the face fails the rule, even
    # braking: the one that comes least close is flown, never a stall)
    rp = _shaping(_guard())
    rp.shaper.reset((FACE_X - (REQ_ROW - 0.02), 1.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    p = np.array([_step(rp, (0.02, 0.3, 0.0)).p for _ in range(int(3.0 / DT))])
    assert (FACE_X - p[:, 0]).min() >= REQ_ROW - 0.02 - 0.003
    assert p[-1, 1] - p[0, 1] > 0.5


def test_no_command_takes_the_reference_over_the_ceiling():
    # every mode's command passes the height band in ``_shape``, whatever pushed it (a
    # give-way's row governor over a row's top pushed up through the 3 m ceiling: fresh seed
    # 20261224 along, flight 16). Asked to climb at 0.5 m/s for 4 s from 2.5 m (flat ground,
    # the ceiling at 3 m, its wall 0.1 m inside): it climbs to the wall and no higher than
    # the ceiling; started 0.2 m over the ceiling with a level command, it comes back under
    cfg = ReplanConfig()
    rp = _shaping(_guard())
    rp.shaper.reset((1.0, 1.0, 2.5), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    z = np.array([_step(rp, (0.0, 0.3, 0.5)).p[2] for _ in range(int(4.0 / DT))])
    assert z.max() <= cfg.ceiling_agl_m
    assert z[-1] >= cfg.ceiling_agl_m - 0.1 - 0.05                # it did climb, to the wall
    rp.shaper.reset((1.0, 1.0, cfg.ceiling_agl_m + 0.2), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    z = np.array([_step(rp, (0.0, 0.3, 0.0)).p[2] for _ in range(int(4.0 / DT))])
    assert z[-1] <= cfg.ceiling_agl_m
