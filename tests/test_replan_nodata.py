"""No data, no go (companion/replan/nodata.py; PX4's CP_GO_NO_DATA = 0).

Hand-worked: heading east (body x = east, body y = north). A forward beam
10 deg wide (half 5 deg) sees travel east and anything within 5 deg of it;
travel north (body +y) only a left beam.
"""

from __future__ import annotations

import math

import pytest

from companion.replan.nodata import NO_DATA_TIMEOUT_S, BeamFreshness, block_no_data

I = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)                 # sensor = body: looks forward
LEFT = (0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)             # sensor x -> body +y (yaw +90 FLU)
EAST = I                                                          # body FLU -> ENU, heading east


def _yaw(psi):
    c, s = math.cos(psi), math.sin(psi)
    return (c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)


def _dir(az_deg):
    a = math.radians(az_deg)
    return (math.cos(a), math.sin(a), 0.0)


def test_direction_inside_a_fresh_beam_has_data_outside_not():
    f = BeamFreshness()
    f.on_evidence(10.0, 0, I, math.radians(10.0), math.radians(2.0))
    assert f.has_data(10.1, EAST, _dir(0.0))
    assert f.has_data(10.1, EAST, _dir(4.9)) and f.has_data(10.1, EAST, _dir(-4.9))
    assert not f.has_data(10.1, EAST, _dir(5.1))                  # just beyond the half field of view
    assert not f.has_data(10.1, EAST, _dir(90.0))                 # north = body left: no beam
    assert not f.has_data(10.1, EAST, _dir(180.0))                # behind the forward beam
    f.on_evidence(10.0, 1, LEFT, math.radians(10.0), math.radians(2.0))
    assert f.has_data(10.1, EAST, _dir(90.0))


def test_the_vehicle_heading_turns_the_beams_and_leaning_does_not_matter():
    f = BeamFreshness()
    f.on_evidence(0.0, 0, I, math.radians(10.0), math.radians(2.0))
    # heading north: the forward beam looks north
    assert f.has_data(0.1, _yaw(math.pi / 2), _dir(90.0)) and not f.has_data(0.1, _yaw(math.pi / 2), _dir(0.0))
    # pitched 10 deg nose down (beyond the 1 deg half vertical field): the level heading still counts
    th = math.radians(10.0)
    pitched = (math.cos(th), 0.0, math.sin(th), 0.0, 1.0, 0.0, -math.sin(th), 0.0, math.cos(th))
    assert f.has_data(0.1, pitched, _dir(0.0))


def test_stale_beams_are_no_data_and_vertical_motion_is_not_checked():
    f = BeamFreshness()
    f.on_evidence(0.0, 0, I, math.radians(10.0), math.radians(2.0))
    assert f.has_data(NO_DATA_TIMEOUT_S, EAST, _dir(0.0))
    assert not f.has_data(NO_DATA_TIMEOUT_S + 0.01, EAST, _dir(0.0))
    assert BeamFreshness().has_data(0.0, EAST, (0.0, 0.0, 0.5))   # a climb: horizontal check only


def test_blocked_command_keeps_only_its_vertical_part():
    assert block_no_data((0.6, -0.3, 0.2), False) == [0.0, 0.0, 0.2]
    assert block_no_data((0.6, -0.3, 0.2), True) == [0.6, -0.3, 0.2]


def _range(sensor_id, R_flu_sensor, hfov_deg):
    from mavcore.codec import Range

    return Range(1000, sensor_id, math.nan, 0.1, 10.0, 100, math.radians(hfov_deg), math.radians(2.0),
                 math.nan, True, R_flu_sensor)


def test_replanner_governor_blocks_a_direction_without_data():
    # the replanner's avoidance command beside an obstacle on the corridor's line:
    # the APF pushes it sideways, outside a forward beam 10 deg wide; with only
    # that beam reporting ("no return" readings through on_range) the command
    # keeps no horizontal part, with a ring of 16 it moves
    import numpy as np
    from test_replan_closedloop import CORRIDOR_Y, build_field

    from mavcore.mission.replan import ReplanConfig
    from companion.replan.replanner import Replanner

    field = build_field()
    P = np.array([8.0, CORRIDOR_Y, 1.5])
    obs = np.array([[9.2, CORRIDOR_Y - 0.05, 1.5]])
    dist = np.linalg.norm(obs - P, axis=1)
    out = {}
    for name, beams in (("forward", [(0, I)]),
                        ("ring", [(k, _yaw(math.radians(22.5 * k))) for k in range(16)])):
        rp = Replanner(ReplanConfig(body_radius_m=0.442), field.known, field.plan)
        rp.on_pose(1.0, P, EAST)
        for sid, R in beams:
            rp.on_range(1.0, _range(sid, R, 10.0 if name == "forward" else 24.0))
        rp._t_s = 1.0
        k = field.plan.leg_near(P, np.array([1.0, 0.0]))
        A, B, u, n = rp._leg_frame(k)
        out[name] = rp._apf_velocity(P, obs, dist, B, A, u, n, 0.0)
    ring = out["ring"]
    assert math.hypot(ring[0], ring[1]) > 0.05
    assert abs(math.degrees(math.atan2(ring[1], ring[0]))) > 5.0      # outside the forward beam
    assert out["forward"][:2] == [0.0, 0.0] and out["forward"][2] == ring[2]
