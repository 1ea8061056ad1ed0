"""Pointing direction toward S_p and its time derivatives (Section 2.4.2, eq. 21).

    s(t) = (S_p - x_d(t)) / ||S_p - x_d(t)||                      (eq. 21)

With d = S_p - x_d, r = ||d|| and s = d / r (so d' = -v, d'' = -a)::

    r'  = s . d'
    s'  = (d' - r' s) / r
    r'' = s' . d' + s . d''
    s'' = (d'' - r'' s - 2 r' s') / r

The controller needs s, s' and s'' to build Omega_d and its derivative.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mavcore.errors import PlanError

#: Closer than this to S_p [m] the direction is undefined.
MIN_TARGET_DISTANCE_M = 1e-6


@dataclass(frozen=True)
class PointingDerivatives:
    """Unit pointing vector and its first two time derivatives (ENU).

    Attributes
    ----------
    s : (n, 3) array
        Unit vector from the trajectory toward S_p (eq. 21).
    s_dot : (n, 3) array
        ds/dt [1/s].
    s_ddot : (n, 3) array
        d^2 s/dt^2 [1/s^2].
    """

    s: np.ndarray
    s_dot: np.ndarray
    s_ddot: np.ndarray

    def __iter__(self):
        # allows ``s, s_dot, s_ddot = pointing_derivatives(...)``
        return iter((self.s, self.s_dot, self.s_ddot))


def _offset(p_enu_m: np.ndarray, target_enu_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(p_enu_m, dtype=float).reshape(-1, 3)
    d = np.asarray(target_enu_m, dtype=float).reshape(1, 3) - p
    r = np.sqrt(np.einsum("ni,ni->n", d, d))
    if np.any(r < MIN_TARGET_DISTANCE_M):
        i = int(np.flatnonzero(r < MIN_TARGET_DISTANCE_M)[0])
        raise PlanError("pointing", f"the pointing target lies on the trajectory (sample {i}); "
                                    "the direction of eq. (21) is undefined there")
    return d, r


def pointing_directions(p_enu_m: np.ndarray, target_enu_m: np.ndarray) -> np.ndarray:
    """Unit vectors from the trajectory toward the pointing target (eq. 21).

    Parameters
    ----------
    p_enu_m : (n, 3) array
        Trajectory positions x_d(t) (ENU, m).
    target_enu_m : (3,) array
        Pointing target S_p (ENU, m).

    Returns
    -------
    (n, 3) array
        s(t), unit vectors (ENU).

    Raises
    ------
    PlanError
        A position coincides with S_p (direction undefined).
    """
    d, r = _offset(p_enu_m, target_enu_m)
    return d / r[:, None]


def pointing_derivatives(p_enu_m: np.ndarray, v_enu_m_s: np.ndarray, a_enu_m_s2: np.ndarray,
                         target_enu_m: np.ndarray) -> PointingDerivatives:
    """s(t) of eq. (21) with its first and second time derivatives.

    Parameters
    ----------
    p_enu_m, v_enu_m_s, a_enu_m_s2 : (n, 3) arrays
        Trajectory position (m), velocity (m/s) and acceleration (m/s^2), ENU.
    target_enu_m : (3,) array
        Pointing target S_p (ENU, m), fixed in time.

    Returns
    -------
    PointingDerivatives
        s, s_dot, s_ddot, each (n, 3).
    """
    d, r = _offset(p_enu_m, target_enu_m)
    dd = -np.asarray(v_enu_m_s, dtype=float).reshape(-1, 3)
    ddd = -np.asarray(a_enu_m_s2, dtype=float).reshape(-1, 3)
    s = d / r[:, None]
    r_dot = np.einsum("ni,ni->n", s, dd)
    s_dot = (dd - r_dot[:, None] * s) / r[:, None]
    r_ddot = np.einsum("ni,ni->n", s_dot, dd) + np.einsum("ni,ni->n", s, ddd)
    s_ddot = (ddd - r_ddot[:, None] * s - 2.0 * r_dot[:, None] * s_dot) / r[:, None]
    return PointingDerivatives(s=s, s_dot=s_dot, s_ddot=s_ddot)
