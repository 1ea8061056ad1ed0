"""Sensor models (sitl/sensors.py) and their use in a Simulation frame."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.mission.schema import HomeConfig, Mission
from companion.mission.sim import NoiseConfig, ObstacleConfig, RangefinderConfig, SimConfig
from companion.vehicle import GRAVITY_M_S2
from sitl.sensors import SensorSuite, fan_directions_flu, orientation_direction_flu
from sitl.sim import Simulation
from sitl.world import World

G = GRAVITY_M_S2
QUIET = NoiseConfig(vector_variance=0.0, gyro_variance=0.0, range_std_m=0.0)


def _mission(**sim):
    return Mission(name="t", map="m.yaml", dem="d.asc", home=HomeConfig(44.8, -0.6, 30.0),
                   sim=SimConfig(**sim))


def _yaw(psi):
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_orientations_follow_the_mavlink_enum():
    assert orientation_direction_flu(mavlink.MAV_SENSOR_ROTATION_NONE) == (1.0, 0.0, 0.0)
    assert orientation_direction_flu(mavlink.MAV_SENSOR_ROTATION_YAW_90) == (0.0, -1.0, 0.0)   # right
    assert orientation_direction_flu(mavlink.MAV_SENSOR_ROTATION_YAW_180) == (-1.0, 0.0, 0.0)
    assert orientation_direction_flu(mavlink.MAV_SENSOR_ROTATION_YAW_270) == (0.0, 1.0, 0.0)  # left
    assert orientation_direction_flu(mavlink.MAV_SENSOR_ROTATION_PITCH_270) == (0.0, 0.0, -1.0)
    assert orientation_direction_flu(mavlink.MAV_SENSOR_ROTATION_PITCH_90) == (0.0, 0.0, 1.0)


def test_fan_spans_the_field_of_view():
    rays = fan_directions_flu(RangefinderConfig(id=0, orientation=0, hfov_deg=10.0, vfov_deg=4.0))
    assert len(rays) == 5 and rays[0] == (1.0, 0.0, 0.0)
    angles = sorted(round(math.degrees(math.acos(r[0])), 9) for r in rays[1:])
    assert angles == [2.0, 2.0, 5.0, 5.0]
    assert all(abs(np.linalg.norm(r) - 1.0) < 1e-15 for r in rays)


def test_accelerometer_reads_plus_g_at_rest_and_zero_in_free_fall():
    s = SensorSuite(SimConfig(noise=QUIET), World.build(), np.random.default_rng(0))
    imu = s.imu(np.eye(3), np.zeros(3), np.zeros(3), G)
    assert np.array_equal(imu.accel_flu_m_s2, [0.0, 0.0, G])
    # pitched 90 deg nose down: body x = world down, body z = world east;
    # the reaction to gravity (world up) is along body -x
    R = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])   # columns: body axes
    assert np.allclose(s.imu(R, np.zeros(3), np.zeros(3), G).accel_flu_m_s2, [-G, 0, 0], atol=1e-15)
    noisy = SensorSuite(SimConfig(), World.build(), np.random.default_rng(0))
    ff = noisy.imu(_yaw(0.3), np.array([0.0, 0.0, -G]), np.zeros(3), G)
    assert np.array_equal(ff.accel_flu_m_s2, [0.0, 0.0, 0.0])   # noise scales with |f|: none in free fall


def test_magnetometer_rotated_90_deg_yaw():
    s = SensorSuite(SimConfig(noise=QUIET, magnetic_field_enu_gauss=(0.0, 0.21, -0.42)),
                    World.build(), np.random.default_rng(0))
    m = s.imu(_yaw(math.pi / 2), np.zeros(3), np.zeros(3), G).mag_flu_gauss
    # nose north: the north component is along body x, nothing along body y (left = west)
    assert np.allclose(m, [0.21, 0.0, -0.42], atol=1e-15)


def test_noise_levels_follow_the_paper_variance_on_unit_vectors():
    s = SensorSuite(SimConfig(noise=NoiseConfig(gyro_bias_rad_s=(0.01, 0.0, 0.0))),
                    World.build(), np.random.default_rng(42))
    n = 20000
    acc = np.empty((n, 3))
    mag = np.empty((n, 3))
    gyr = np.empty((n, 3))
    for k in range(n):
        imu = s.imu(np.eye(3), np.zeros(3), np.zeros(3), G)
        acc[k], mag[k], gyr[k] = imu.accel_flu_m_s2, imu.mag_flu_gauss, imu.gyro_flu_rad_s
    var = 5e-4
    tol = 4 * math.sqrt(2 / n)      # relative sampling error of a variance, 4 sigma
    assert np.allclose(np.var(acc / G, axis=0), var, rtol=tol)
    assert np.allclose(np.var(mag / np.linalg.norm([0.0, 0.21, -0.42]), axis=0), var, rtol=tol)
    assert np.allclose(np.var(gyr, axis=0), var, rtol=tol)
    assert np.mean(gyr[:, 0]) == pytest.approx(0.01, abs=4 * math.sqrt(var / n))


def test_same_seed_same_frames():
    a = Simulation(_mission(), np.random.default_rng(5))
    b = Simulation(_mission(), np.random.default_rng(5))
    for _ in range(5):
        fa, fb = a.step_frame([0.6] * 4), b.step_frame([0.6] * 4)
        assert np.array_equal(fa.gyro_flu_rad_s, fb.gyro_flu_rad_s)
        assert np.array_equal(fa.accel_flu_m_s2, fb.accel_flu_m_s2)
        assert fa.ranges == fb.ranges


def _ranges_at(sim: Simulation, p, yaw=0.0, frames=30):
    """Put the vehicle at p (hovering, motors at hover) and collect the readings."""
    sim.plant.set_state(p, R=_yaw(yaw), f=(sim.mission.vehicle.mass_kg * G / 4,) * 4)
    cmd = [sim.mission.vehicle.mass_kg * G / 4 / sim.mission.vehicle.max_thrust_per_rotor_n] * 4
    out = {}
    for _ in range(frames):
        sim.plant.set_state(p, R=_yaw(yaw), f=(sim.mission.vehicle.mass_kg * G / 4,) * 4)
        for r in sim.step_frame(cmd).ranges:
            out.setdefault(r.sensor_id, []).append(r.distance_m)
    return out


def test_rangefinders_against_hand_placed_geometry():
    occ = np.zeros((100, 200), bool)
    occ[60, :] = True                                 # a vine row along x at y in [6.0, 6.1)
    from companion.maps.grid import OccupancyGrid
    grid = OccupancyGrid(occ, ~occ, 0.1)
    cyl = ObstacleConfig("cylinder", x=10.0, y=3.75, height=3.0, radius=0.3)
    mission = _mission(obstacles=(cyl,), noise=QUIET)
    world = World.build(grid, None, mission.sim.obstacles, mission.sim.canopy_height_m)
    sim = Simulation(mission, np.random.default_rng(1), world=world, start_enu_m=(2.0, 3.75, 1.5))
    got = _ranges_at(sim, (4.0, 3.75, 1.5), frames=250)
    # defaults: 0 forward, 1 left, 2 right, 3 down
    assert got[0][0] == pytest.approx(6.0 - 0.3, abs=1e-9)      # cylinder ahead
    assert got[1][0] == pytest.approx(6.0 - 3.75, abs=1e-9)     # row face on the left
    assert got[2][0] is None                                    # nothing on the right within 10 m
    assert got[3][0] == pytest.approx(1.5, abs=1e-12)           # the ground
    # each sensor at its rate: 25 Hz over 1 s (+1 for the phase of its first reading)
    assert all(len(v) in (25, 26) for v in got.values())
    assert all(len(set(v)) == 1 for v in got.values())          # noise off: identical readings


def test_rangefinder_below_min_clamps_and_noise_is_seeded():
    rf = (RangefinderConfig(id=7, orientation=25, min_m=0.2, max_m=5.0, rate_hz=250.0),)
    sim = Simulation(_mission(rangefinders=rf, noise=NoiseConfig(range_std_m=0.01)),
                     np.random.default_rng(3))
    got = _ranges_at(sim, (0.0, 0.0, 0.1), frames=1)
    assert got[7] == [0.2]
    d = np.array(_ranges_at(sim, (0.0, 0.0, 2.0), frames=400)[7])
    assert abs(d.mean() - 2.0) < 4 * 0.01 / math.sqrt(d.size)
    assert d.std() == pytest.approx(0.01, rel=0.2)
    sim2 = Simulation(_mission(rangefinders=rf, noise=NoiseConfig(range_std_m=0.01)),
                      np.random.default_rng(3))
    _ranges_at(sim2, (0.0, 0.0, 0.1), frames=1)
    assert np.array_equal(np.array(_ranges_at(sim2, (0.0, 0.0, 2.0), frames=400)[7]), d)


def test_frame_carries_truth_and_positions():
    sim = Simulation(_mission(noise=dataclasses.replace(QUIET, position_std_m=0.0)),
                     np.random.default_rng(0), start_enu_m=(1.0, 2.0))
    fr = sim.step_frame([0.0] * 4)
    assert fr.time_us == sim.sensor_period_us == 4000
    assert fr.truth.landed
    assert np.array_equal(fr.pos_enu_m, [1.0, 2.0, 0.0])
    assert np.array_equal(fr.accel_flu_m_s2, [0.0, 0.0, G])
