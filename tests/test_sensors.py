"""Sensor models (sitl/sensors.py) and their use in a Simulation frame."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore.mission.schema import HomeConfig, Mission
from mavcore.mission.sim import NoiseConfig, ObstacleConfig, RangefinderConfig, SimConfig
from mavcore.vehicle import GRAVITY_M_S2
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
    from mavcore.maps.grid import OccupancyGrid
    grid = OccupancyGrid(occ, ~occ, 0.1)
    cyl = ObstacleConfig("cylinder", x=10.0, y=3.75, height=3.0, radius=0.3)
    # 0 forward, 1 left, 2 right, 3 down (5 deg beams)
    suite = (RangefinderConfig(id=0, orientation=0), RangefinderConfig(id=1, orientation=6),
             RangefinderConfig(id=2, orientation=2), RangefinderConfig(id=3, orientation=25, max_m=20.0))
    mission = _mission(obstacles=(cyl,), noise=QUIET, rangefinders=suite)
    world = World.build(grid, None, mission.sim.obstacles, mission.sim.canopy_height_m)
    sim = Simulation(mission, np.random.default_rng(1), world=world, start_enu_m=(2.0, 3.75, 1.5))
    got = _ranges_at(sim, (4.0, 3.75, 1.5), frames=250)
    assert got[0][0] == pytest.approx(6.0 - 0.3, abs=1e-9)      # cylinder ahead
    assert got[1][0] == pytest.approx(6.0 - 3.75, abs=1e-9)     # row face on the left
    assert got[2][0] is None                                    # nothing on the right within 10 m
    assert got[3][0] == pytest.approx(1.5, abs=1e-12)           # the ground
    # each sensor at its rate: 25 Hz over 1 s (+1 for the phase of its first reading)
    assert all(len(v) in (25, 26) for v in got.values())
    assert all(len(set(v)) == 1 for v in got.values())          # noise off: identical readings


def test_default_suite_is_two_closed_rings_a_down_beam_and_a_down_array():
    # every horizontal direction lies inside some beam of each ring: 16 beams 22.5 deg
    # apart, each 24 deg wide; the level ring's axes level, the low ring's 9 deg down
    # (mavcore.mission.sim); with the companion's own reading of the mounting. The down
    # array (ids 33-41) is tests/test_descent_sight.py's.
    suite = SimConfig().rangefinders_or_default
    assert [c.id for c in suite] == list(range(42))
    level, down, low = suite[:16], suite[16], suite[17:33]
    for ring, elevation in ((level, 0.0), (low, -9.0)):
        dirs = [fan_directions_flu(c)[0] for c in ring]
        for az in np.radians(np.arange(0.0, 360.0, 0.5)):
            off = min(abs(math.degrees(math.atan2(math.sin(az - math.atan2(d[1], d[0])),
                                                   math.cos(az - math.atan2(d[1], d[0]))))) for d in dirs)
            assert off <= 12.0
        assert all(abs(d[2] - math.sin(math.radians(elevation))) < 1e-12 for d in dirs)
    assert fan_directions_flu(down)[0] == orientation_direction_flu(25)


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


# --- sensor models of issue 7: paper vectors, profile, biases, disturbance ------------------

from scipy.stats import chi2  # noqa: E402

from sitl.profiles import PAPER_DEFAULTS, PROFILES, resolve_sensor_model  # noqa: E402

PROFILE = "icm42688p-bmm150-zedf9p"


def _var_bounds(n: int, p: float = 1e-6):
    """Two-sided bounds on sample variance / true variance for n normal samples:
    (n - 1) s^2 / sigma^2 ~ chi2(n - 1)."""
    return chi2.ppf(p / 2, n - 1) / (n - 1), chi2.ppf(1 - p / 2, n - 1) / (n - 1)


def _R(roll, pitch, yaw):
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return Rz @ Ry @ Rx


def test_paper_vectors_are_constant_inertial_directions_whatever_the_acceleration():
    """vector_sensors: paper: accel fields = g (R^T e3 + n), mag = |m| (R^T m_hat + n),
    n ~ N(0, 5e-4 I), even while accelerating hard (a physical accelerometer
    would read R^T (a + g e3))."""
    s = SensorSuite(SimConfig(vector_sensors="paper"), World.build(), np.random.default_rng(7))
    R = _R(0.4, -0.3, 2.0)                      # hand-placed tilted attitude
    acc = np.array([3.0, -2.0, 4.0])            # and a large acceleration (world)
    m_e = np.array([0.0, 0.21, -0.42])
    n = 8000
    R9, acc3 = tuple(R.ravel()), tuple(acc)
    samples = [s.imu_tuples(R9, acc3, (0.0, 0.0, 0.0), G) for _ in range(n)]
    da = np.array([x[0] for x in samples]) / G - R.T @ [0.0, 0.0, 1.0]
    dm = (np.array([x[2] for x in samples]) - R.T @ m_e) / np.linalg.norm(m_e)
    lo, hi = _var_bounds(n)
    for d in (da, dm):
        assert np.all(np.abs(d.mean(axis=0)) < 5 * math.sqrt(5e-4 / n))       # centred on R^T r_i
        assert np.all((lo * 5e-4 < d.var(axis=0, ddof=1)) & (d.var(axis=0, ddof=1) < hi * 5e-4))
    # the physical model differs by the acceleration: R^T (a + g e3)/g is far from R^T e3
    phys = SensorSuite(SimConfig(noise=QUIET), World.build(), np.random.default_rng(7)).imu(R, acc, np.zeros(3), G)
    assert np.allclose(phys.accel_flu_m_s2, R.T @ (acc + [0, 0, G]), atol=1e-12)
    assert np.linalg.norm(phys.accel_flu_m_s2 / G - R.T @ [0, 0, 1]) > 0.3


def test_profile_values_follow_the_datasheets():
    """Per-sample std = density * sqrt(rate), from the datasheet figures in
    sitl/profiles.py (computed here independently of the module)."""
    md = resolve_sensor_model(SimConfig(sensor_profile=PROFILE), sensor_hz=250)
    g0 = 9.80665
    assert md.gyro_std_rad_s == pytest.approx(2.8e-3 * math.pi / 180 * math.sqrt(250), rel=1e-12)
    assert md.accel_std_m_s2 == pytest.approx(70e-6 * g0 * math.sqrt(250), rel=1e-12)
    assert md.gyro_bias_turn_on_std_rad_s == pytest.approx(math.radians(0.5), rel=1e-12)
    assert md.accel_rel_std == 0.0 and md.mag_std_gauss == 0.006
    assert (md.position_std_xy_m, md.position_std_z_m, md.velocity_std_m_s) == (0.01, 0.02, 0.02)
    assert (md.gnss_period_us, md.gnss_latency_us) == (100_000, 80_000)
    # at another sensor rate the per-sample std scales with sqrt(rate)
    md1k = resolve_sensor_model(SimConfig(sensor_profile=PROFILE), sensor_hz=1000)
    assert md1k.gyro_std_rad_s / md.gyro_std_rad_s == pytest.approx(2.0, rel=1e-12)
    # sim.noise keys override the profile; absent ones keep it
    over = resolve_sensor_model(SimConfig(sensor_profile=PROFILE, noise=NoiseConfig(
        velocity_std_m_s=0.05, gyro_variance=1e-4)), sensor_hz=250)
    assert over.velocity_std_m_s == 0.05 and over.position_std_xy_m == 0.01
    assert over.gyro_std_rad_s == pytest.approx(math.sqrt(1e-4 + (2.8e-3 * math.pi / 180) ** 2 * 250), rel=1e-12)
    # no profile: the paper's model, exact position every frame
    paper = resolve_sensor_model(SimConfig(), sensor_hz=250)
    assert paper.accel_rel_std == math.sqrt(5e-4) and paper.gyro_std_rad_s == math.sqrt(5e-4)
    assert (paper.gnss_period_us, paper.gnss_latency_us, paper.position_std_xy_m) == (4000, 0, 0.0)
    assert set(PROFILES[PROFILE]) == set(PAPER_DEFAULTS) == {f.name for f in dataclasses.fields(NoiseConfig)}


def test_profile_gyro_and_accel_noise_on_the_samples():
    s = SensorSuite(SimConfig(sensor_profile=PROFILE, noise=NoiseConfig(
        gyro_bias_walk_rad_s_rts=0.0, accel_bias_walk_m_s2_rts=0.0)), World.build(), np.random.default_rng(3))
    md = s.model
    n = 20000
    gy = np.empty((n, 3))
    ac = np.empty((n, 3))
    for k in range(n):
        a, w, _ = s.imu_tuples((1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), G)
        gy[k], ac[k] = w, a
    lo, hi = _var_bounds(n)
    for x, std in ((gy, md.gyro_std_rad_s), (ac, md.accel_std_m_s2)):
        v = x.var(axis=0, ddof=1) / std ** 2
        assert np.all((lo < v) & (v < hi))
    assert np.allclose(gy.mean(axis=0), s._gyro_bias, atol=5 * md.gyro_std_rad_s / math.sqrt(n))


def test_turn_on_bias_is_a_seeded_draw_of_the_configured_std():
    cfg = SimConfig(noise=NoiseConfig(gyro_bias_turn_on_std_rad_s=0.01, gyro_bias_rad_s=(0.1, 0.0, 0.0)))
    b = np.array([SensorSuite(cfg, World.build(), np.random.default_rng(k))._gyro_bias for k in range(400)])
    lo, hi = _var_bounds(400)
    v = b.var(axis=0, ddof=1) / 0.01 ** 2
    assert np.all((lo < v) & (v < hi))
    assert b[:, 0].mean() == pytest.approx(0.1, abs=5 * 0.01 / 20)       # constant + turn-on
    again = SensorSuite(cfg, World.build(), np.random.default_rng(5))._gyro_bias
    assert np.array_equal(again, b[5])                                     # seeded


def test_bias_random_walk_variance_grows_linearly_in_time():
    """b(t) = b(0) + sum of N(0, q^2 dt) steps: Var b(t) = q^2 t, across independent runs."""
    q = 0.02          # rad/s/sqrt(s), large so the test is short
    cfg = SimConfig(noise=NoiseConfig(gyro_variance=0.0, gyro_bias_walk_rad_s_rts=q))
    runs, steps = 200, 125                         # 0.5 s at 250 Hz
    b_half = np.empty((runs, 3))
    b_end = np.empty((runs, 3))
    R9 = (1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0)
    for r in range(runs):
        s = SensorSuite(cfg, World.build(), np.random.default_rng(100 + r))
        for k in range(steps):
            s.imu_tuples(R9, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), G)
            if k == steps // 2 - 1:
                b_half[r] = s._gyro_bias
        b_end[r] = s._gyro_bias
    lo, hi = _var_bounds(3 * runs)
    for b, t in ((b_half, 0.25), (b_end, 0.5)):
        v = np.mean(b ** 2) / (q * q * t)          # mean-zero: E b^2 = q^2 t
        assert lo < v < hi
    # and the gyro reading carries it: with no white noise the sample is W + b
    s = SensorSuite(cfg, World.build(), np.random.default_rng(1))
    b0 = s._gyro_bias
    _, w, _ = s.imu_tuples(R9, (0.0, 0.0, 0.0), (0.1, 0.0, 0.0), G)
    assert w == pytest.approx((0.1 + b0[0], b0[1], b0[2]), abs=1e-15)


def test_magnetometer_disturbance_hard_iron_plus_motor_current():
    hi_ = (0.01, -0.02, 0.005)
    kT = (1e-4, 2e-4, -3e-4)
    s = SensorSuite(SimConfig(noise=NoiseConfig(vector_variance=0.0, gyro_variance=0.0, mag_hard_iron_gauss=hi_,
                                                mag_thrust_gauss_per_n=kT)), World.build(), np.random.default_rng(0))
    R = _R(0.1, 0.2, 1.0)
    m_e = np.array([0.0, 0.21, -0.42])
    for T in (0.0, 42.6, 100.0):
        m = s.imu(R, np.zeros(3), np.zeros(3), G, thrust_n=T).mag_flu_gauss
        assert np.allclose(m, R.T @ m_e + np.array(hi_) + T * np.array(kT), atol=1e-15)
