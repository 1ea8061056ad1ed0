"""The SITL's onboard estimator (sitl/estimator.py) on synthetic sensor data.

The scenario is generated with the estimator's own discrete model (the
attitude propagated by Exp(W dt) per 4 ms frame, the acceleration held over
a frame), so with noise-free samples the true state is an equilibrium of
the filter: every error must decay to rounding, from any reasonable start.
The bounds below are that decay after ten or more time constants
(tau = 1 s for tilt, yaw and the bias integral), with margin.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitl.estimator import EstimatorConfig, OnboardEstimator, initial_attitude
from sitl.gnss import GnssReceiver
from mavcore.so3 import rotate_right

G = 9.81
M_E = (0.0, 0.21, -0.42)
DT = 0.004


def _mat(R9):
    return np.array(R9).reshape(3, 3)


def _angle(Ra, Rb) -> float:
    E = _mat(Ra).T @ _mat(Rb)
    return math.acos(max(-1.0, min(1.0, (np.trace(E) - 1.0) / 2.0)))


def _Rx(a):
    c, s = math.cos(a), math.sin(a)
    return (1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)


def _Rz(a):
    c, s = math.cos(a), math.sin(a)
    return (c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)


def _mul(A, B):
    return tuple((_mat(A) @ _mat(B)).ravel())


def fly(est, seconds, gyro_bias=(0.0, 0.0, 0.0), latency_us=80_000, period_us=100_000,
        accel_mode="specific_force", record_from_s=None):
    """A manoeuvre: body rates and world accelerations as smooth sines (tilts
    up to ~0.3 rad, heading sweeping, |a| <= 1.2 m/s^2, speed up to ~2 m/s),
    sampled exactly; GNSS at ``period_us`` with ``latency_us``. Returns the
    largest attitude, bias, position and velocity errors after ``record_from_s``."""
    R = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    p, v = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
    rx = GnssReceiver(period_us, latency_us, 0.0, 0.0, 0.0, np.random.default_rng(0))
    rx.reset(tuple(p), tuple(v))
    worst = dict(att=0.0, bias=0.0, pos=0.0, vel=0.0)
    for k in range(1, int(round(seconds / DT)) + 1):
        t = k * DT
        w = (0.3 * math.sin(0.7 * t), 0.25 * math.sin(0.5 * t + 1.0), 0.2 * math.cos(0.3 * t))
        R = rotate_right(R, w[0] * DT, w[1] * DT, w[2] * DT)
        a = (1.0 * math.sin(0.4 * t), 0.8 * math.cos(0.3 * t), 0.5 * math.sin(0.9 * t))
        p = [p[i] + v[i] * DT + 0.5 * a[i] * DT * DT for i in range(3)]
        v = [v[i] + a[i] * DT for i in range(3)]
        Rm = _mat(R)
        if accel_mode == "specific_force":
            f = Rm.T @ (np.array(a) + [0.0, 0.0, G])
        else:
            f = G * Rm.T @ [0.0, 0.0, 1.0]
        m = Rm.T @ M_E
        gyro = (w[0] + gyro_bias[0], w[1] + gyro_bias[1], w[2] + gyro_bias[2])
        fix = rx.step(int(round(t * 1e6)), tuple(p), tuple(v))
        e = est.update(int(round(t * 1e6)), DT, gyro, tuple(f), tuple(m), fix)
        if record_from_s is not None and t >= record_from_s:
            worst["att"] = max(worst["att"], _angle(e.R, R))
            worst["bias"] = max(worst["bias"], max(abs(e.gyro_bias_rad_s[i] - gyro_bias[i]) for i in range(3)))
            worst["pos"] = max(worst["pos"], math.dist(e.pos_enu_m, p))
            worst["vel"] = max(worst["vel"], math.dist(e.vel_enu_m_s, v))
    return worst


def test_initial_attitude_from_one_exact_sample_is_the_attitude():
    R = _mul(_Rz(2.0), _Rx(0.3))
    Rm = _mat(R)
    got = initial_attitude(tuple(Rm.T @ [0, 0, G]), tuple(Rm.T @ M_E), M_E)
    assert _angle(got, R) < 1e-12


def test_converges_from_a_wrong_attitude_and_learns_the_gyro_bias_while_manoeuvring():
    """Start 30 deg off in roll and 60 deg in heading with a gyro bias of
    (0.01, -0.02, 0.015) rad/s, GNSS at 10 Hz delivered 80 ms late: after
    40 s every error has decayed to the rounding level."""
    wrong = _mul(_Rz(math.radians(60.0)), _Rx(math.radians(30.0)))
    est = OnboardEstimator(EstimatorConfig(mag_enu_gauss=M_E, gravity_m_s2=G), R0=wrong)
    worst = fly(est, 60.0, gyro_bias=(0.01, -0.02, 0.015), record_from_s=40.0)
    assert worst["att"] < 1e-3           # rad
    assert worst["bias"] < 1e-4          # rad/s
    assert worst["pos"] < 1e-3           # m: the 80 ms delay is compensated (uncompensated: ~0.1 m)
    assert worst["vel"] < 1e-3           # m/s


def test_inclinometer_mode_converges_too():
    """sim.vector_sensors: paper: the accelerometer fields are g R^T e3. (The
    synthetic body tilt is unrelated to its acceleration, unlike a
    multirotor's, so the position filter's g tan(tilt) model does not hold
    here: only attitude and gyro bias are checked.)"""
    wrong = _mul(_Rz(math.radians(-45.0)), _Rx(math.radians(20.0)))
    est = OnboardEstimator(EstimatorConfig(accel_mode="inclinometer", mag_enu_gauss=M_E, gravity_m_s2=G,
                                           accel_noise_m_s2_rthz=0.5), R0=wrong)
    worst = fly(est, 40.0, gyro_bias=(-0.01, 0.01, 0.02), accel_mode="inclinometer", record_from_s=35.0)
    assert worst["att"] < 1e-3 and worst["bias"] < 1e-4


def test_bad_config_is_refused():
    with pytest.raises(ValueError):
        EstimatorConfig(accel_mode="gravity")
    with pytest.raises(ValueError):
        EstimatorConfig(tilt_time_constant_s=0.0)
