"""LQR trajectory weights (mission key ``trajectory``), Section 2.3.2, eq. (4).

The cost of one axis (the same weights act on x, y and z, so the three axes
decouple and are solved together)::

    J = sum_{i=1..N} (y(t_i) - y_i)^T S (y(t_i) - y_i)
        + int_{t_0}^{t_N} 1/2 (x^T Q x + R u^2) dt

with x = [p, v, a, jerk], u = snap, y = [p, v, a], S = diag(s_position,
s_velocity, s_acceleration), Q = diag(q_position, q_velocity,
q_acceleration, q_jerk). The way-point term carries no 1/2 (as the paper
writes it). Only ratios matter: multiplying S, Q and R by the same factor
leaves the trajectory unchanged.

Default choice, tuned on vineyard way-points (4 m apart at 1 m/s, 4 s
intervals, corners at rest with 90 and 180 degree turns, 2.5 m row spacing;
rows of 40-61 m, times = distance / speed, and also with 1.5x and 2x more time
on the segments next to a corner):

- ``r_snap = 1`` sets the scale; Q = 0. With Q = 0 the optimal snap is a
  cubic on every interval and the reference a degree-7 spline (minimum snap
  with soft way-point constraints), computed exactly and fastest. A position
  weight in Q would pull the path toward the ENU origin (not translation
  invariant) and a velocity weight would fight the cruise speed. Small
  acceleration/jerk weights (e.g. q_acceleration = 1, q_jerk = 3 with
  S = (1e4, 300, 30)) reduce the lateral ringing after corners from ~10 to
  ~5 cm but split every interval into sub-knots with degree-27 pieces
  (about 20x the generation and 4x the sampling time); available, not default.
- ``s_position = 1e4`` [1/m^2]: the position stiffness of a 4 s spline
  piece is 100800 R/dt^7 ~ 6 against 2 s_position = 2e4, so way-point
  position residuals are a few mm
  (max 0.2-0.6 cm on the examples, requirement <= 5 cm), while the path still
  smooths rather than interpolates.
- ``s_velocity = 60`` [s^2/m^2] and ``s_acceleration = 8`` [s^4/m^2]: the
  paper's constraints (v = 0 at corners, cruise speed on runs, a = 0
  everywhere). The paper's output omits the jerk, so the jerk is continuous
  through a corner and the spline "rings" after a turn: an overshoot across
  the new corridor. The ratio S_v : S_a matters much more than their size;
  60 : 8 minimised the worst lateral deviation from the straight runs over the
  examples (<= 10 cm, 8 cm on a 6 x 42 m boustrophedon). Much larger S_v or
  S_a (harder rest at corners) makes the ringing worse (0.3-0.8 m), and
  S_a = 0 leaves the acceleration free at corners (0.5-0.7 m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class TrajectoryConfig:
    """Diagonal weights of the paper's cost (eq. 4), per axis (same on x, y, z).

    Attributes
    ----------
    s_position, s_velocity, s_acceleration : float
        Way-point output weights S on p [1/m^2], v [s^2/m^2], a [s^4/m^2]; >= 0.
    q_position, q_velocity, q_acceleration, q_jerk : float
        Running state weights Q on p, v, a, jerk; >= 0.
    r_snap : float
        Running weight R on the snap input; > 0.
    """

    s_position: float = 1.0e4
    s_velocity: float = 60.0
    s_acceleration: float = 8.0
    q_position: float = 0.0
    q_velocity: float = 0.0
    q_acceleration: float = 0.0
    q_jerk: float = 0.0
    r_snap: float = 1.0

    def __post_init__(self) -> None:
        for name in ("s_position", "s_velocity", "s_acceleration",
                     "q_position", "q_velocity", "q_acceleration", "q_jerk"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"trajectory.{name} must be a finite number >= 0, got {value}")
        if not (math.isfinite(self.r_snap) and self.r_snap > 0.0):
            raise ValueError(f"trajectory.r_snap must be a finite number > 0, got {self.r_snap}")

    @property
    def s_diag(self) -> tuple[float, float, float]:
        """Diagonal of S (p, v, a)."""
        return (self.s_position, self.s_velocity, self.s_acceleration)

    @property
    def q_diag(self) -> tuple[float, float, float, float]:
        """Diagonal of Q (p, v, a, jerk)."""
        return (self.q_position, self.q_velocity, self.q_acceleration, self.q_jerk)
