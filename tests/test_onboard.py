"""Onboard cascaded controller (sitl/onboard.py) flying the plant."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavcore.mission.schema import HomeConfig, Mission
from mavcore.mission.sim import NoiseConfig, SimConfig
from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig, allocation_matrix
from sitl.onboard import CascadedController, Setpoint
from sitl.sim import Simulation

VEH = VehicleConfig()
MG = VEH.mass_kg * GRAVITY_M_S2


def _sim(start=(0.0, 0.0, 0.0), hover=False):
    # The controller itself: flown on the true state (the estimator's own
    # tests are in test_estimator.py).
    m = Mission(name="t", map="m.yaml", dem="d.asc", home=HomeConfig(44.8, -0.6, 30.0),
                sim=SimConfig(rangefinders=(), onboard_state="truth"))
    sim = Simulation(m, np.random.default_rng(0), start_enu_m=start)
    if hover:
        sim.plant.set_state(start, f=(MG / 4,) * 4)
    return sim


def _fly(sim, sp_of_t, seconds):
    n = int(round(seconds / sim.dt_frame_s))
    out = np.empty((n, 3))
    for k in range(n):
        sp = sp_of_t((k + 1) * sim.dt_frame_s)
        out[k] = sim.step_onboard(sp).truth.pos_enu_m
    return out


def test_mixer_round_trip_inside_limits():
    ctl = CascadedController(VEH)
    A = allocation_matrix(VEH)
    for F, tx, ty, tz in [(MG, 0.0, 0.0, 0.0), (40.0, 0.8, -0.5, 0.01), (60.0, -1.2, 0.3, -0.02)]:
        cmd = np.array(ctl.mix(F, tx, ty, tz))
        assert np.allclose(A @ (cmd * VEH.max_thrust_per_rotor_n), [F, tx, ty, tz], rtol=0, atol=1e-12)


def test_mixer_gives_up_yaw_first_then_keeps_roll_pitch_ratio():
    ctl = CascadedController(VEH)
    A = allocation_matrix(VEH)
    fmax = VEH.max_thrust_per_rotor_n
    # far more yaw than the rotors can give: thrust and roll/pitch exact, yaw same sign, reduced
    got = A @ (np.array(ctl.mix(MG, 0.3, -0.2, 5.0)) * fmax)
    assert np.allclose(got[:3], [MG, 0.3, -0.2], atol=1e-12)
    assert 0.0 < got[3] < 5.0
    # best yaw: the binding rotor sits exactly on a limit
    f = np.linalg.solve(A, got)
    assert min(f.min(), fmax - f.max()) == pytest.approx(0.0, abs=1e-12)
    # roll/pitch needing a little more than hover leaves: the collective is
    # shifted by the least amount (one rotor at zero), torques exact
    tx = 1.1 * MG * VEH.arm_m / math.sqrt(2)   # per-rotor share tx/(4 d) = 1.1 x hover thrust
    got = A @ (np.array(ctl.mix(MG, tx, 0.0, 0.0)) * fmax)
    assert np.allclose(got[1:], [tx, 0.0, 0.0], atol=1e-12)
    assert got[0] > MG
    f = np.linalg.solve(A, got)
    assert f.min() == pytest.approx(0.0, abs=1e-12)
    # impossible roll/pitch: scaled to the full thrust span, direction kept
    got = A @ (np.array(ctl.mix(MG, 30.0, 10.0, 0.0)) * fmax)
    assert got[1] / got[2] == pytest.approx(3.0, rel=1e-12)
    f = np.linalg.solve(A, got)
    assert f.max() - f.min() == pytest.approx(fmax, rel=1e-12)


def test_hover_holds():
    sim = _sim((1.0, 2.0, 3.0), hover=True)
    sp = Setpoint(pos_enu_m=(1.0, 2.0, 3.0), yaw_enu_rad=0.0)
    traj = _fly(sim, lambda t: sp, 5.0)
    assert np.abs(traj - [1.0, 2.0, 3.0]).max() < 1e-9


def test_takeoff_step_and_land():
    sim = _sim()
    traj = _fly(sim, lambda t: Setpoint(pos_enu_m=(0.0, 0.0, 2.0), yaw_enu_rad=0.0), 5.0)
    assert traj[-1] == pytest.approx([0.0, 0.0, 2.0], abs=0.02)
    assert traj[:, 2].max() < 2.1                         # no large overshoot
    # a 3 m step: inside 5 cm within 3 s, inside 5 mm at 6 s
    traj = _fly(sim, lambda t: Setpoint(pos_enu_m=(3.0, 0.0, 2.0), yaw_enu_rad=0.0), 6.0)
    err = np.linalg.norm(traj - [3.0, 0.0, 2.0], axis=1)
    assert err[int(3.0 * 250):].max() < 0.05
    assert err[-1] < 0.005
    assert traj[:, 0].max() < 3.15
    # land: descend at 0.7 m/s (no z position), settle on the ground
    sp = Setpoint(pos_enu_m=(3.0, 0.0, math.nan), vel_enu_m_s=(math.nan, math.nan, -0.7), yaw_enu_rad=0.0)
    _fly(sim, lambda t: sp, 4.0)
    assert sim.truth.landed
    assert sim.plant.impact_speed_m_s < 0.8
    assert sim.truth.pos_enu_m[:2] == pytest.approx([3.0, 0.0], abs=0.02)


def test_straight_line_tracking_at_one_metre_per_second():
    p0 = np.array([0.0, 0.0, 2.0])
    d = np.array([0.6, 0.8, 0.0])
    sim = _sim(tuple(p0), hover=True)

    def ref(t):  # accelerate at 1 m/s^2 for 1 s, then cruise at 1 m/s
        if t < 1.0:
            return 0.5 * t * t, t, 1.0
        return 0.5 + (t - 1.0), 1.0, 0.0

    def sp(t):
        s, v, a = ref(t)
        return Setpoint(pos_enu_m=p0 + s * d, vel_enu_m_s=v * d, acc_enu_m_s2=a * d, yaw_enu_rad=0.0)

    traj = _fly(sim, sp, 10.0)
    want = np.array([p0 + ref((k + 1) / 250)[0] * d for k in range(len(traj))])
    err = np.linalg.norm(traj - want, axis=1)
    assert err.max() < 0.03                    # including the acceleration kinks
    assert err[3 * 250:].max() < 0.01          # steady cruise


def test_yaw_setpoint_and_velocity_only_mode():
    sim = _sim((0.0, 0.0, 2.0), hover=True)
    traj = _fly(sim, lambda t: Setpoint(pos_enu_m=(0.0, 0.0, 2.0), yaw_enu_rad=math.pi / 2), 10.0)
    R = sim.truth.R
    assert math.atan2(R[1, 0], R[0, 0]) == pytest.approx(math.pi / 2, abs=0.02)
    assert np.abs(traj - [0.0, 0.0, 2.0]).max() < 0.01          # yawing does not move it
    # velocity only (position not controlled): settles on the commanded velocity
    sp = Setpoint(vel_enu_m_s=(0.5, -0.3, 0.0), yaw_enu_rad=math.pi / 2)
    _fly(sim, lambda t: sp, 4.0)
    assert sim.truth.vel_enu_m_s == pytest.approx([0.5, -0.3, 0.0], abs=0.01)


def test_controller_is_deterministic_and_resettable():
    ctl = CascadedController(VEH)
    sim = _sim((0.0, 0.0, 2.0), hover=True)
    sp = Setpoint(pos_enu_m=(1.0, 0.0, 2.0))
    a = ctl.update(sim.truth, sp, 0.004)
    ctl.update(sim.truth, sp, 0.004)
    ctl.reset()
    assert np.array_equal(ctl.update(sim.truth, sp, 0.004), a)
    assert a.shape == (4,) and np.all((a >= 0) & (a <= 1))
