"""The improved APF of eqs. (14)-(19): properties of the fields, checked
against independent computations (numerical gradients, hand-worked values,
dense sampling)."""

from __future__ import annotations

import numpy as np
import pytest

from companion.replan.apf import (ApfParams, apf_force, attractive_potential, repulsive_potential,
                                  total_potential)

PARAMS = ApfParams(k_att=1.0, k_rep=0.2, influence_m=2.1, n=2.0)


def test_hand_worked_values():
    # P at the origin, goal 3 m east, obstacle 1 m north: rho = 1, rho_g = 3
    P, g, o = np.zeros(3), np.array([3.0, 0, 0]), np.array([[0.0, 1.0, 0]])
    inv = 1.0 - 1.0 / 2.1
    assert attractive_potential(P, g, PARAMS) == pytest.approx(0.5 * 9.0)
    assert repulsive_potential(P, o, g, PARAMS) == pytest.approx(0.5 * 0.2 * inv ** 2 * 9.0)
    f = apf_force(P, o, g, PARAMS)
    np.testing.assert_allclose(f.attractive, [3.0, 0, 0])
    # F_rep1 = k_rep inv rho_g^2 / rho^2 along (P - P_o) = -y; F_rep2 = k_rep inv^2 rho_g along +x
    np.testing.assert_allclose(f.repulsive, [0.2 * inv ** 2 * 3.0, -0.2 * inv * 9.0, 0.0])
    np.testing.assert_allclose(f.total, f.attractive + f.repulsive)


def test_zero_repulsion_beyond_influence_range():
    rng = np.random.default_rng(1)
    g = np.array([10.0, 0.0, 1.5])
    for _ in range(200):
        P = rng.uniform(-5, 5, 3)
        direction = rng.normal(size=3)
        o = P + direction / np.linalg.norm(direction) * rng.uniform(2.1 + 1e-9, 6.0)
        assert repulsive_potential(P, o[None], g, PARAMS) == 0.0
        np.testing.assert_array_equal(apf_force(P, o[None], g, PARAMS).repulsive, np.zeros(3))


@pytest.mark.parametrize("n", [0.5, 1.0, 2.0, 3.0])
def test_force_continuous_at_influence_range(n):
    params = ApfParams(k_att=1.0, k_rep=0.2, influence_m=2.1, n=n)
    g = np.array([7.0, 3.0, 1.0])
    o = np.array([[0.0, 0.0, 1.0]])
    u = np.array([0.6, 0.8, 0.0])
    mags = []
    for eps in (1e-2, 1e-3, 1e-4, 1e-5):
        P = o[0] + (2.1 - eps) * u
        mags.append(np.linalg.norm(apf_force(P, o, g, params).repulsive))
    # vanishes linearly in the distance to d_o: |F| / eps tends to a constant
    ratios = np.array(mags) / np.array([1e-2, 1e-3, 1e-4, 1e-5])
    assert mags[-1] < 1e-3
    np.testing.assert_allclose(ratios[1:], ratios[-1], rtol=0.02)


def test_force_is_the_negative_numerical_gradient():
    rng = np.random.default_rng(7)
    h = 1e-6
    for _ in range(100):
        g = rng.uniform(-6, 6, 3)
        obs = rng.uniform(-3, 3, (rng.integers(1, 4), 3))
        P = obs[0] + rng.normal(size=3) * 0.5                      # often within d_o of one
        if np.min(np.linalg.norm(obs - P, axis=1)) < 0.2 or np.linalg.norm(g - P) < 0.2:
            continue
        if np.any(np.abs(np.linalg.norm(obs - P, axis=1) - 2.1) < 1e-3):
            continue
        grad = np.array([(total_potential(P + h * e, obs, g, PARAMS) - total_potential(P - h * e, obs, g, PARAMS))
                         / (2 * h) for e in np.eye(3)])
        np.testing.assert_allclose(apf_force(P, obs, g, PARAMS).total, -grad, rtol=1e-5, atol=1e-5)


def _potential_grid(pts, obs, g, k_att, k_rep, d0, n):
    """eqs. (14) + (16) written out over many points at once (independent of the module)."""
    rho_g = np.linalg.norm(pts - g, axis=1)
    rho = np.linalg.norm(pts[:, None, :] - obs[None], axis=2)
    inv = np.where(rho <= d0, 1.0 / rho - 1.0 / d0, 0.0)
    return 0.5 * k_att * rho_g ** 2 + 0.5 * k_rep * np.sum(inv ** 2, axis=1) * rho_g ** n


def test_goal_is_the_global_minimum_with_n2():
    rng = np.random.default_rng(2022)
    for trial in range(20):
        g = rng.uniform(-4, 4, 3)
        k = rng.integers(1, 6)
        # obstacles anywhere, some within d_o of the goal (where the conventional field fails)
        obs = g + rng.uniform(-2.5, 2.5, (k, 3))
        obs = obs[np.linalg.norm(obs - g, axis=1) > 0.3]
        assert total_potential(g, obs, g, PARAMS) == 0.0
        pts = g + rng.uniform(-6, 6, (20000, 3))
        pts = pts[np.min(np.linalg.norm(pts[:, None] - obs[None], axis=2), axis=1) > 1e-3]
        u = _potential_grid(pts, obs, g, PARAMS.k_att, PARAMS.k_rep, PARAMS.influence_m, PARAMS.n)
        for i in range(0, len(pts), 2000):            # the module agrees with the written-out field
            assert total_potential(pts[i], obs, g, PARAMS) == pytest.approx(u[i], rel=1e-12)
        assert np.all(u > 0.0)


def test_conventional_field_loses_the_goal_minimum():
    """n = 0 (no goal-distance factor): an obstacle within d_o of the goal
    makes the goal a non-minimum (the field's value there is positive and
    a point farther from the obstacle is lower). The improved field (n = 2)
    keeps U(goal) = 0."""
    g = np.zeros(3)
    obs = np.array([[0.8, 0.0, 0.0]])
    conventional = ApfParams(k_att=1.0, k_rep=0.2, influence_m=2.1, n=0.0)
    assert total_potential(g, obs, g, conventional) > 0.0
    step = np.array([-0.05, 0.0, 0.0])                             # away from the obstacle
    assert total_potential(g + step, obs, g, conventional) < total_potential(g, obs, g, conventional)
    assert total_potential(g, obs, g, PARAMS) == 0.0
    assert total_potential(g + step, obs, g, PARAMS) > 0.0


def test_params_validated():
    with pytest.raises(ValueError):
        ApfParams(k_att=0.0)
    with pytest.raises(ValueError):
        ApfParams(influence_m=-1.0)
