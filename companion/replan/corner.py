"""Where the path turns, a leg's end is a wall of the avoiding modes' corridor (pure).

The avoiding modes (avoid, climb) fly a velocity command along leg k's line
toward its end corner B; ``Replanner._constrain`` bounds the offset across the
leg with soft walls at the corridor's half-width L (``lateral_limit_m`` less
its margin). Near B the goal moves to the next leg, whose walls then apply.
Nothing bounded the speed *along* the leg: at 2 m/s the shaped reference
carried 0.8 m past a 90 degree corner into the headland after the goal had
turned (fresh seed 20261152 of obstacles-wide, flight 0: lateral 0.81 m).

Overshooting B by x along leg k puts the vehicle x sin(theta) off the next
leg's line for a turn theta <= 90 degrees, and x from the next leg's start for
a sharper turn (it is behind it). The next leg's wall at L is therefore a wall
across leg k at ``L / sin(theta)`` beyond B (``L`` for theta >= 90 degrees):
the same wall the vehicle meets after the switch, seen before it. Straight on
(theta = 0) there is no wall. The last leg's end is the plan's end: no turn.
"""

from __future__ import annotations

import math

import numpy as np


def end_room_m(u, u_next, half_width_m: float) -> float:
    """Distance (m) beyond a leg's end at which the next leg's corridor wall crosses the
    leg's line: ``half_width_m / sin(theta)`` for a turn theta < 90 degrees between the
    unit vectors ``u`` (this leg) and ``u_next``, ``half_width_m`` for 90 degrees or
    more, infinite straight on."""
    c = float(np.dot(u, u_next))
    if c <= 0.0:
        return float(half_width_m)
    s = math.sqrt(max(0.0, 1.0 - c * c))
    return math.inf if s * 1e9 <= half_width_m else float(half_width_m) / s


def leg_end_wall_m(plan, k: int, p_xy, half_width_m: float) -> float:
    """Distance (m) along leg k of ``plan`` from ``p_xy`` to the wall of its end corner
    (``end_room_m`` beyond it; negative when beyond the wall); infinite on the last leg
    or where the path runs straight on."""
    n_legs = len(plan.turns_enu_m) - 1
    if k >= n_legs - 1:
        return math.inf
    _, B, u, _ = plan.leg_frame(k)
    u_next = plan.leg_frame(k + 1)[2]
    room = end_room_m(u, u_next, half_width_m)
    if not math.isfinite(room):
        return math.inf
    return float((B[0] - p_xy[0]) * u[0] + (B[1] - p_xy[1]) * u[1]) + room
