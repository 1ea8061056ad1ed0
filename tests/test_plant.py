"""Plant (sitl/plant.py): physical laws with derived values, tight tolerances."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig, allocation_matrix
from sitl.plant import Plant, PlantParams
from mavcore.so3 import polar_step, rotate_right

VEH = VehicleConfig()
H = 1e-3


def _R(plant):
    return np.array(plant.R).reshape(3, 3)


def _rot(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def test_free_fall_matches_half_g_t_squared():
    plant = Plant(PlantParams(VEH))                    # no ground
    p0 = np.array([1.0, -2.0, 50.0])
    v0 = np.array([0.3, 0.0, 2.0])
    plant.set_state(p0, v0, R=_rot([1, 2, 3], 0.7))  # attitude is irrelevant with motors off
    for _ in range(1000):
        plant.step((0, 0, 0, 0), H)
    t = 1.0
    expect = p0 + v0 * t + 0.5 * np.array([0, 0, -GRAVITY_M_S2]) * t * t
    disp = np.linalg.norm(expect - p0)
    assert np.linalg.norm(np.array(plant.p) - expect) <= 1e-9 * disp
    assert np.allclose(plant.v, v0 + np.array([0, 0, -GRAVITY_M_S2]) * t, rtol=0, atol=1e-11)
    assert np.allclose(plant.acc, (0, 0, -GRAVITY_M_S2), atol=1e-12)


def test_hover_at_mg_stays_put():
    plant = Plant(PlantParams(VEH))
    f = VEH.mass_kg * GRAVITY_M_S2 / 4.0
    cmd = (f / VEH.max_thrust_per_rotor_n,) * 4
    p0 = (3.0, 4.0, 10.0)
    plant.set_state(p0, f=(f,) * 4)                     # motor lag settled
    for _ in range(10_000):                             # 10 s
        plant.step(cmd, H)
    assert np.linalg.norm(np.array(plant.p) - p0) < 1e-9
    assert np.linalg.norm(plant.w) < 1e-12
    assert np.allclose(_R(plant), np.eye(3), atol=1e-15)


def test_motor_lag_is_exact_first_order():
    T = VEH.motor_time_constant_s
    plant = Plant(PlantParams(VEH))
    plant.set_state((0, 0, 100.0))
    for _ in range(7):
        plant.step((0.5, 0.5, 0.5, 0.5), H)
    target = 0.5 * VEH.max_thrust_per_rotor_n
    assert plant.f[0] == pytest.approx(target * (1 - math.exp(-7 * H / T)), rel=1e-13)


def test_torque_free_rotation_conserves_momentum_and_energy():
    plant = Plant(PlantParams(VEH, gravity_m_s2=0.0))
    J = VEH.J
    w0 = np.array([1.5, -2.0, 3.0])                    # tumbling, not about a principal axis
    plant.set_state((0, 0, 0), R=_rot([0.2, 1, -0.4], 1.1), w=w0)
    L0 = _R(plant) @ J @ w0
    E0 = 0.5 * w0 @ J @ w0
    for _ in range(10_000):                             # 10 s
        plant.step((0, 0, 0, 0), H)
    w = np.array(plant.w)
    L = _R(plant) @ J @ w
    E = 0.5 * w @ J @ w
    # fourth-order integrator: far below the 1e-6 asked for
    assert np.linalg.norm(L - L0) <= 1e-10 * np.linalg.norm(L0)
    assert abs(E - E0) <= 1e-12 * E0
    assert np.linalg.norm(_R(plant).T @ _R(plant) - np.eye(3)) < 1e-13
    assert np.linalg.det(_R(plant)) == pytest.approx(1.0, abs=1e-13)


def test_rotation_about_principal_axis_matches_closed_form():
    plant = Plant(PlantParams(VEH, gravity_m_s2=0.0))
    plant.set_state((0, 0, 0), w=(0, 0, 2.0))
    for _ in range(1000):
        plant.step((0, 0, 0, 0), H)
    assert np.allclose(_R(plant), _rot([0, 0, 1], 2.0), atol=1e-13)


def test_R_stays_orthonormal_over_a_million_steps():
    # The attitude kinematics exactly as the plant runs them: R <- R Exp(theta)
    # with a Newton polar step every 64 steps; a changing, tumbling theta.
    R = tuple(_rot([1, -2, 0.5], 0.3).reshape(9))
    worst = 0.0
    for k in range(1_000_000):
        R = rotate_right(R, 2e-3 * math.sin(1e-3 * k), 1.7e-3, -3.1e-3)
        if k % 64 == 63:
            R = polar_step(R)
        if k % 100_000 == 0:
            M = np.array(R).reshape(3, 3)
            worst = max(worst, np.linalg.norm(M.T @ M - np.eye(3)))
    M = np.array(R).reshape(3, 3)
    worst = max(worst, np.linalg.norm(M.T @ M - np.eye(3)))
    assert worst < 1e-12


def test_rotate_right_is_the_matrix_exponential():
    from scipy.linalg import expm
    th = np.array([0.3, -0.2, 0.9])
    K = np.array([[0, -th[2], th[1]], [th[2], 0, -th[0]], [-th[1], th[0], 0]])
    R0 = _rot([1, 1, 0], 0.4)
    got = np.array(rotate_right(tuple(R0.reshape(9)), *th)).reshape(3, 3)
    assert np.allclose(got, R0 @ expm(K), atol=1e-15)


def test_torque_from_rotor_thrusts_follows_allocation():
    # Zero gravity, constant rotor thrusts: Omega' = J^-1 tau at Omega = 0.
    plant = Plant(PlantParams(VEH, gravity_m_s2=0.0, ))
    f = np.array([10.0, 10.0, 12.0, 9.0])
    plant.set_state((0, 0, 0), f=f)
    h = 1e-6
    plant.step(tuple(f / VEH.max_thrust_per_rotor_n), h)
    tau = (allocation_matrix(VEH) @ f)[1:]
    assert np.allclose(np.array(plant.w) / h, tau / np.array(VEH.inertia_kg_m2), rtol=1e-6)


def test_ground_contact_landed_no_sinking_then_lift_off():
    plant = Plant(PlantParams(VEH), ground_height=lambda x, y: 5.0)
    plant.set_state((0, 0, 5.2))
    hover = VEH.mass_kg * GRAVITY_M_S2 / 4 / VEH.max_thrust_per_rotor_n
    for _ in range(1000):                               # falls 0.2 m and rests
        plant.step((0.5 * hover,) * 4, H)
    assert plant.landed and plant.p[2] == 5.0 and plant.v == (0.0, 0.0, 0.0)
    # impact speed of a fall of 0.2 m at g - F/m = g/2 (small motor lag neglected)
    assert plant.impact_speed_m_s == pytest.approx(math.sqrt(2 * GRAVITY_M_S2 / 2 * 0.2), rel=0.02)
    x0 = plant.p
    for _ in range(500):                                # thrust below weight: stays
        plant.step((0.99 * hover, 0.99 * hover, 0.99 * hover, 0.99 * hover), H)
    assert plant.landed and plant.p == x0
    for _ in range(500):                                # above weight: lifts off
        plant.step((1.2 * hover,) * 4, H)
    assert not plant.landed and plant.p[2] > 5.0 and plant.v[2] > 0.0


def test_linear_drag_terminal_velocity_in_wind():
    # Motors at hover, wind 3 m/s east, drag k: velocity tends to the wind,
    # v(t) = w (1 - exp(-k t / m)).
    k = 0.8
    plant = Plant(PlantParams(VEH, drag_n_s_m=k))
    f = VEH.mass_kg * GRAVITY_M_S2 / 4
    plant.set_state((0, 0, 10.0), f=(f,) * 4)
    for _ in range(5000):
        plant.step((f / VEH.max_thrust_per_rotor_n,) * 4, H, (3.0, 0.0, 0.0))
    assert plant.v[0] == pytest.approx(3.0 * (1 - math.exp(-k * 5.0 / VEH.mass_kg)), rel=1e-8)
