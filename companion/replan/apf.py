"""The improved artificial potential field of Section 2.3.3 (eqs. 14-19).

With P the vehicle, P_g the goal, P_o an obstacle (ENU, m), rho = |P - P_o|,
rho_g = |P - P_g|::

    U_att(P) = 1/2 k_att rho_g^2                                       (eq. 14)
    F_att(P) = -grad U_att = k_att (P_g - P)                           (eq. 15)
    U_rep(P) = 1/2 k_rep (1/rho - 1/d_o)^2 rho_g^n   if rho <= d_o     (eq. 16)
             = 0                                     if rho >  d_o
    F_rep(P) = -grad U_rep = F_rep1 + F_rep2         if rho <= d_o     (eq. 17)
    F_rep1   = k_rep (1/rho - 1/d_o) rho_g^n / rho^2      n_OR          (eq. 18)
    F_rep2   = n/2 k_rep (1/rho - 1/d_o)^2 rho_g^(n-1)     n_RG          (eq. 19)

with n_OR = (P - P_o) / rho (from the obstacle to the vehicle: F_rep1
pushes away) and n_RG = (P_g - P) / rho_g (toward the goal: F_rep2 pulls
on). The paper prints eqs. (15), (18) and (19) as magnitudes (the unit
vectors were lost) and eq. (16) without k_rep, which the forces then carry;
differentiating eq. (16) with k_rep gives exactly the forces above (the
tests check them against the numerical gradient).

Properties (tested): U_rep and F_rep vanish at and beyond d_o, so the force
is continuous there (both terms carry 1/rho - 1/d_o); U >= 0 everywhere
with U(P_g) = 0 for n > 0 (rho_g^n = 0 at the goal), so the goal is the
global minimum of the total potential however the obstacles lie, the point
of the "improved" field (the conventional field, n = 0, loses it when an
obstacle is within d_o of the goal).

Obstacles are points (the hit points of the rangefinders); several are
summed (the paper's "resultant force"). Units: with U per unit mass
(m^2/s^2), k_att is 1/s^2 and k_rep m^(4-n)/s^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Closer than this (m) to the goal or an obstacle, unit vectors are undefined: 0 is used.
_EPS_M = 1e-9


@dataclass(frozen=True)
class ApfParams:
    """Constants of eqs. (14)-(19).

    Attributes
    ----------
    k_att : float
        Attractive gain (1/s^2), > 0.
    k_rep : float
        Repulsive gain (m^(4-n)/s^2), >= 0.
    influence_m : float
        d_o, the influence range of an obstacle (m), > 0 (the paper: 2.1 m).
    n : float
        Exponent of the goal-distance factor, > 0 (the paper: 2).
    """

    k_att: float = 1.0
    k_rep: float = 0.2
    influence_m: float = 2.1
    n: float = 2.0

    def __post_init__(self) -> None:
        if not (self.k_att > 0 and self.k_rep >= 0 and self.influence_m > 0 and self.n >= 0):
            raise ValueError("APF needs k_att > 0, k_rep >= 0, influence_m > 0, n >= 0")


@dataclass(frozen=True)
class ApfForce:
    """Forces at one point (ENU, (3,) arrays, per unit mass).

    Attributes
    ----------
    attractive : F_att of eq. (15).
    repulsive : sum over the obstacles of F_rep1 + F_rep2 (eqs. 17-19).
    total : attractive + repulsive.
    """

    attractive: np.ndarray
    repulsive: np.ndarray
    total: np.ndarray


def attractive_potential(p_enu_m, goal_enu_m, params: ApfParams) -> float:
    """U_att of eq. (14) at one point (m^2/s^2)."""
    d = np.asarray(goal_enu_m, dtype=float) - np.asarray(p_enu_m, dtype=float)
    return 0.5 * params.k_att * float(d @ d)


def repulsive_potential(p_enu_m, obstacles_enu_m, goal_enu_m, params: ApfParams) -> float:
    """Sum over the obstacles of U_rep of eq. (16) at one point (m^2/s^2).

    Parameters
    ----------
    p_enu_m : (3,) vehicle position.
    obstacles_enu_m : (k, 3) obstacle points (k may be 0).
    goal_enu_m : (3,) goal.
    """
    p = np.asarray(p_enu_m, dtype=float)
    obs = np.asarray(obstacles_enu_m, dtype=float).reshape(-1, 3)
    rho = np.sqrt(np.einsum("ki,ki->k", p - obs, p - obs))
    rho_g = float(np.linalg.norm(np.asarray(goal_enu_m, dtype=float) - p))
    near = rho <= params.influence_m
    if not near.any():
        return 0.0
    inv = 1.0 / np.maximum(rho[near], _EPS_M) - 1.0 / params.influence_m
    return float(0.5 * params.k_rep * np.sum(inv * inv) * rho_g ** params.n)


def total_potential(p_enu_m, obstacles_enu_m, goal_enu_m, params: ApfParams) -> float:
    """U_att + sum U_rep at one point (m^2/s^2)."""
    return attractive_potential(p_enu_m, goal_enu_m, params) + \
        repulsive_potential(p_enu_m, obstacles_enu_m, goal_enu_m, params)


def apf_force(p_enu_m, obstacles_enu_m, goal_enu_m, params: ApfParams) -> ApfForce:
    """F_att and the summed F_rep1 + F_rep2 at one point (eqs. 15, 17-19; module doc).

    Parameters
    ----------
    p_enu_m : (3,) array
        Vehicle position P (ENU, m).
    obstacles_enu_m : (k, 3) array
        Obstacle points P_o (ENU, m); k = 0 gives the attraction alone.
    goal_enu_m : (3,) array
        Goal P_g (ENU, m).
    params : ApfParams

    Returns
    -------
    ApfForce
        ENU forces per unit mass (m/s^2).
    """
    p = np.asarray(p_enu_m, dtype=float)
    g = np.asarray(goal_enu_m, dtype=float)
    to_goal = g - p
    f_att = params.k_att * to_goal
    obs = np.asarray(obstacles_enu_m, dtype=float).reshape(-1, 3)
    f_rep = np.zeros(3)
    if len(obs):
        away = p - obs                                         # (k, 3), obstacle -> vehicle
        rho = np.sqrt(np.einsum("ki,ki->k", away, away))
        near = (rho <= params.influence_m) & (rho > _EPS_M)
        if near.any():
            rho_n = rho[near]
            inv = 1.0 / rho_n - 1.0 / params.influence_m       # >= 0, 0 at d_o
            rho_g = float(np.linalg.norm(to_goal))
            n = params.n
            # F_rep1 = k_rep (1/rho - 1/d_o) rho_g^n / rho^2 * n_OR
            mag1 = params.k_rep * inv * rho_g ** n / (rho_n * rho_n)
            f_rep = (mag1 / rho_n) @ away[near]
            if rho_g > _EPS_M and n > 0:
                # F_rep2 = n/2 k_rep (1/rho - 1/d_o)^2 rho_g^(n-1) * n_RG
                mag2 = 0.5 * n * params.k_rep * float(np.sum(inv * inv)) * rho_g ** (n - 1.0)
                f_rep = f_rep + mag2 * to_goal / rho_g
    return ApfForce(attractive=f_att, repulsive=f_rep, total=f_att + f_rep)
