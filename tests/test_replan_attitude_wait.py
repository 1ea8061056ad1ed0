"""A reading waits for the attitude of its own time (``companion.replan.attitude_wait``).

Over a lossy link the vehicle's ATTITUDE comes in gaps of up to 200 ms; carried
that far with the last body rates it was off by up to 4.5 deg of tilt, and a
beam looking down at the ground a few metres ahead then returned from above
the ground: phantom obstacles on a clear field (the lossy real-time test of
``tests/test_outcomes_e2e.py``, with the low ring, failed 5 times in 6)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink
from scipy.spatial.transform import Rotation, Slerp

from mavcore import codec
from mavcore.maps.grid import ElevationModel, OccupancyGrid
from mavcore.mission.replan import ReplanConfig
from companion.coverage.freespace import erode_free_space
from companion.replan import KnownMap
from companion.replan.attitude_wait import AttitudeWait, interpolated_rotation
from companion.replan.perception import MAX_EXTRAPOLATION_S, MAX_PROPAGATION_S, PoseHistory

EYE = tuple(np.eye(3).ravel())
#: the beam looks 20 deg down (FRD pitch -20 deg): flat ground 1.5 m below is 1.5 / sin 20 deg away
DOWN_DEG = 20.0
H = 1.5


def _pitch_up(deg):
    """Body FLU -> ENU of a vehicle heading east, nose up by ``deg`` (a rotation about
    body y, which is north: nose up turns +x toward +z)."""
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return (c, 0.0, -s, 0.0, 1.0, 0.0, s, 0.0, c)


def _reading(t_ms, distance_cm):
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    a = math.radians(-DOWN_DEG) / 2
    m = mav.distance_sensor_encode(t_ms, 10, 1000, distance_cm, mavlink.MAV_DISTANCE_SENSOR_LASER, 0,
                                   codec.MAV_SENSOR_ROTATION_CUSTOM, 255, 0.02, 0.02,
                                   (math.cos(a), 0.0, math.sin(a), 0.0), 100)
    rx = mavlink.MAVLink(None)
    return codec.decode_distance_sensor(rx.parse_buffer(m.pack(mav))[0])


def _replanner(tilt_tolerance_deg=0.0, heading_tolerance_deg=0.0):
    """The attitude allowance (``replan.tilt_tolerance_deg``, ``heading_tolerance_deg``) is off by default here:
    these tests isolate the wait; ``tests/test_replan_attitude_allowance.py`` tests it."""
    from companion.replan import GlobalPlan, Replanner
    from companion.trajectory import generate_trajectory
    from mavcore.mission.schema import FlightConfig
    from mavcore.mission.trajectory import TrajectoryConfig
    occ = np.zeros((40, 100), dtype=bool)
    occ[30:34, 10:90] = True                                  # a row far to the north (y 3.0..3.4 m)
    grid = OccupancyGrid(occupied=occ, free=~occ, resolution_m=0.1)
    dem = ElevationModel(np.zeros((2, 2)), x0_m=0.0, y0_m=0.0, cellsize_m=10.0)    # flat, z = 0
    km = KnownMap.build(grid, dem, erode_free_space(grid, 0.5), 2.0, 0.2)
    t = np.array([0.0, 10.0])
    p = np.array([[0.5, 1.0, H], [8.5, 1.0, H]])
    plan = GlobalPlan.from_waypoints(generate_trajectory(t, p), t, p, np.zeros((2, 3)), np.zeros((2, 3)),
                                     np.array([True, True]), None, None, FlightConfig(), TrajectoryConfig(), 1.0)
    return Replanner(ReplanConfig(tilt_tolerance_deg=tilt_tolerance_deg, heading_tolerance_deg=heading_tolerance_deg),
                     km, plan)


D_CM = round(100 * H / math.sin(math.radians(DOWN_DEG)))     # the ground's return: 439 cm
P = (1.0, 1.0, H)


def test_the_ground_ahead_is_the_ground_with_the_attitude_of_its_time():
    """Level throughout; the pose of the frame carries the last attitude (1.00 s) 150 ms
    with a stale pitch rate to 4 deg nose up. Placed with that pose the ground's return
    lies 4.39 (sin 20 - sin 16) = 0.29 m above the ground (tolerance 0.2 m): a phantom.
    The reading waits; the next attitude (1.20 s, level) places it level: the ground."""
    rp = _replanner()
    rp.on_pose(1.00, P, EYE, attitude=(1.00, EYE))
    rp.on_pose(1.15, P, _pitch_up(4.0), attitude=(1.00, EYE))
    rp.on_range(1.15, _reading(1150, D_CM))
    assert len(rp.attitude) == 1 and len(rp.memory) == 0      # waiting
    rp.on_pose(1.20, P, EYE, attitude=(1.20, EYE))
    assert len(rp.attitude) == 0
    assert len(rp.memory) == 0 and rp.n_unknown == 0 and rp.n_readings == 1


def test_the_same_reading_placed_with_the_carried_attitude_is_a_phantom():
    """The geometry above is what the test says it is: with the companion's own
    observer (nothing waits) the 4 deg pose puts the return 0.29 m up: unknown."""
    rp = _replanner()
    rp.on_pose(1.15, P, _pitch_up(4.0))
    rp.on_range(1.15, _reading(1150, D_CM))
    assert len(rp.attitude) == 0 and rp.n_unknown == 1
    z = H - D_CM / 100 * math.sin(math.radians(DOWN_DEG - 4.0))
    assert z == pytest.approx(0.29, abs=0.01) and z > 0.2


def test_a_reading_is_late_never_lost():
    """No attitude comes for MAX_PROPAGATION_S: the reading is placed with the pose
    there is (here the carried one: the phantom is kept, as before the rule)."""
    rp = _replanner()
    rp.on_pose(1.00, P, EYE, attitude=(1.00, EYE))
    rp.on_pose(1.15, P, _pitch_up(4.0), attitude=(1.00, EYE))
    rp.on_range(1.15, _reading(1150, D_CM))
    rp.on_pose(1.15 + 0.5 * MAX_PROPAGATION_S, P, _pitch_up(4.0), attitude=(1.00, EYE))
    assert len(rp.attitude) == 1
    rp.on_pose(1.15 + MAX_PROPAGATION_S, P, _pitch_up(4.0), attitude=(1.00, EYE))
    assert len(rp.attitude) == 0 and rp.n_unknown == 1 and rp.n_readings == 1


def test_fresh_attitude_places_at_once():
    """An attitude measured within MAX_EXTRAPOLATION_S of the reading: no wait (a 50 Hz
    stream that loses nothing is never older than 20 ms)."""
    aw = AttitudeWait()
    aw.live = True
    aw.measured(1.0, EYE)
    assert not aw.stale(1.0 + MAX_EXTRAPOLATION_S)
    assert aw.stale(1.0 + MAX_EXTRAPOLATION_S + 1e-3)
    aw.live = False                                          # the observer's poses
    assert not aw.stale(5.0)
    assert not AttitudeWait().stale(5.0)                     # no measurement yet


def test_interpolated_between_the_two_measurements_around_the_reading():
    aw = AttitudeWait()
    aw.live = True
    aw.measured(1.0, EYE)
    aw.measured(1.2, _pitch_up(6.0))
    ph = PoseHistory()
    ph.add(1.0, P, EYE)
    ph.add(1.2, P, _pitch_up(6.0))
    aw.hold(1.15, _reading(1050, D_CM))                      # a quarter of the way
    (arrival, _, pose), = aw.ready(1.2, ph)
    assert arrival == 1.15
    np.testing.assert_allclose(pose.R, _pitch_up(1.5), atol=1e-12)


def test_interpolated_rotation_is_scipys_slerp():
    rng = np.random.default_rng(11)
    for _ in range(50):
        r = Rotation.random(2, random_state=rng)
        s = float(rng.uniform())
        want = Slerp([0.0, 1.0], r)([s]).as_matrix()[0]
        got = interpolated_rotation(tuple(r[0].as_matrix().ravel()), tuple(r[1].as_matrix().ravel()), s)
        np.testing.assert_allclose(np.reshape(got, (3, 3)), want, atol=1e-9)
    R = tuple(Rotation.random(random_state=rng).as_matrix().ravel())
    assert interpolated_rotation(R, R, 0.3) == R
