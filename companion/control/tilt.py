r"""Tilt and vertical-thrust limit of the desired thrust vector (a safety invariant).

World ENU, z up. The geometric controller's thrust vector of eq. (23),
``F_d = -kx e_x - kv e_v - ki e_i + m (g e3 + a_d)``, points wherever the
errors push it: a hand-over while the vehicle still climbs at 2.5 m/s gives
``kv e_v`` = 75 N against ``m g`` = 42.6 N, F_d points down, the collective
thrust ``f = F_d . R e3`` is negative (clipped to 0 by the mixer) and
``b3d = F_d/|F_d|`` asks for an upside-down attitude. The vehicle must never
be asked to flip, so before eq. (23)'s normalisation F_d is limited, as PX4's
``PositionControl::_accelerationControl`` (``ControlMath::limitTilt`` with
``MPC_TILTMAX_AIR``, the collective thrust floored at ``MPC_THR_MIN``):

1. vertical floor: ``F_z' = max(F_z, F_z_min)``;
2. tilt: the horizontal part ``F_h`` is scaled to ``|F_h'| <= F_z' tan(theta_max)``,
   keeping its azimuth (the vertical part is kept, as PX4 keeps the
   vertical thrust when it projects onto the limited body axis).

Where neither limit is active :func:`limit_thrust` returns None and the
controller uses F_d and its derivatives as they are (bit for bit). Where one
is active, the direction ``b3d`` of the limited vector depends only on what
is not saturated, and the derivatives given to ``desired_frame`` for
``Omega_d`` are those of that direction: floor only, ``G = (F_x, F_y,
F_z_min)`` with ``G_dot = (F_dot_x, F_dot_y, 0)``; tilt, ``G = (tan(theta_max)
u, 1)`` with ``u = F_h/|F_h|`` and ``G_dot = (tan(theta_max) u_dot, 0)`` (u's
derivatives as :func:`mavcore.so3.unit_d2`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from mavcore.so3 import unit_d2


class LimitedThrust(NamedTuple):
    """A limited thrust vector (N, world ENU) and a vector along it with its derivatives.

    Attributes
    ----------
    F : tuple (3,)
        The limited thrust vector F_d' (N): its projection on the body axis is
        the collective thrust.
    G, G_dot, G_ddot : tuple (3,)
        A vector along F_d' (any scale) and its first two time derivatives,
        for ``desired_frame`` (b3d, Omega_d, Omega_d_dot).
    """

    F: tuple
    G: tuple
    G_dot: tuple
    G_ddot: tuple


def needs_limit(F, fz_min_n: float, tan2_max: float) -> bool:
    """True where F_d is below the vertical floor or tilted beyond the limit (``tan2_max = tan^2``)."""
    F2 = F[2]
    return F2 < fz_min_n or F[0] * F[0] + F[1] * F[1] > F2 * F2 * tan2_max


def limit_thrust(F, F_dot, F_ddot, fz_min_n: float, tan_max: float) -> LimitedThrust | None:
    """Limit F_d to the tilt cone and the vertical floor (module docstring).

    Parameters
    ----------
    F, F_dot, F_ddot : sequence (3,)
        Thrust vector of eq. (23) (N, world ENU) and its first two time derivatives.
    fz_min_n : float
        Floor of the vertical component (N), > 0.
    tan_max : float
        ``tan(theta_max)``, theta_max in (0, 90 deg) the largest tilt from vertical.

    Returns
    -------
    LimitedThrust or None
        None where no limit is active (F_d is then used unchanged).
    """
    if not needs_limit(F, fz_min_n, tan_max * tan_max):
        return None
    F0, F1, F2 = F
    floor = F2 < fz_min_n
    Fz = fz_min_n if floor else F2
    h = math.sqrt(F0 * F0 + F1 * F1)
    h_max = Fz * tan_max
    if h <= h_max:                     # only the floor: the horizontal part is unchanged
        Fl = (F0, F1, Fz)
        return LimitedThrust(Fl, Fl, (F_dot[0], F_dot[1], 0.0), (F_ddot[0], F_ddot[1], 0.0))
    u, ud, udd = unit_d2((F0, F1, 0.0), (F_dot[0], F_dot[1], 0.0), (F_ddot[0], F_ddot[1], 0.0))
    return LimitedThrust((h_max * u[0], h_max * u[1], Fz), (tan_max * u[0], tan_max * u[1], 1.0),
                         (tan_max * ud[0], tan_max * ud[1], 0.0), (tan_max * udd[0], tan_max * udd[1], 0.0))
