"""Turn a velocity command into a smooth, dynamically feasible reference.

The APF (and the stop) give a desired velocity each frame; the controller
needs p, v, a, jerk and snap that are continuous and bounded. A
third-order reference model tracks the command with nested saturations::

    a_des = sat(k_v (v_cmd - v - a |a| / (2 j_max)), a_max)
    j_des = sat(k_a (a_des - a), j_max)
    snap  = sat(k_j (j_des - j), s_max)

per axis, integrated exactly over each frame for constant snap. The
horizontal axes are the command's own: along its direction and across it
(``planar_snap``), so from rest
the across axis has nothing to do and the reference moves the way it is
commanded, while a small correction across still has the whole of its own
axis's limits when the along axis saturates. On fixed E and N axes, each
saturated on its own, a command along a diagonal was flown at 45 deg until
the slower axis caught up (fresh seed 20261222, flight 13: a give-way
along a diagonal corridor flew into the row beside it, 2.5 m/s walker);
saturating the horizontal pair by its norm instead keeps the direction but
shares the limits, so a correction across a saturated motion along is
slowed in proportion, and a reference inside a row's clearance could not
take back its last millimetre per second toward the row fast enough to go
on along it (tests/test_replan_stopping.py). For a command along E or N
the two frames are the same axes. The brake (a zero command) has no direction
of its own: it stays on the axes of the last command (along it and across it),
so a brake from motion along a command goes straight on, and what the state
still has across the command (an approach the command had turned away from) is
stopped on its own axis, soonest; from a state no command reached (``reset``),
on the axes of its own motion (``brake_frame``). On E and N, a brake from a
diagonal stopped each axis on its own, so the axis with more speed ran on after
the other had stopped and the brake bent toward it: backing away at 1.3 m/s
along a row at 30 deg, the stopping point lay 0.13 m nearer the row than the
line flown. Near a row that bend was refused as an approach, the fallback
brake drifted the reference into the row's margin, and there every motion
along the row was refused until a walker reached the vehicle (fresh seed
20261228 along, flight 5). A brake on the axes of the state's own velocity goes
straight too, but along an approach the command has already turned from: its
last millimetres per second toward a face ran on for the whole brake, and
beside a face the reference could no longer go on along it
(tests/test_replan_stopping.py). On the command's axes the brake turns with the
field, whatever its bearing (tests/test_replan_brake.py). The vertical axis stays apart: with a shared
limit, braking along the track uses up the jerk a climb needs to level
off, and the vertical speed overshoots. Unsaturated, v follows v_cmd
with the triple pole s = -omega (k_j = 3 omega, k_a = omega, k_v = omega / 3:
s^3 + k_j s^2 + k_j k_a s + k_j k_a k_v = (s + omega)^3), so a step of the
command gives no overshoot; saturated, the term a |a| / (2 j_max) (the
speed still gained while the acceleration is ramped down at j_max) keeps
the overshoot small (tested: below 2 % on speed steps). Per axis of
that frame |jerk| <= j_max and |snap| <= s_max, and for a command held
|a| <= a_max (up to one frame of jerk); a component built on the axes of an
earlier command may start beyond a limit on the new ones, and the jerk's
then only comes back (tests/test_replan_shaper.py), while the acceleration
can pass a_max as that jerk unwinds (random commands each held 0.2 s:
horizontal |a| up to 1.53 a_max, against sqrt(2) a_max on fixed axes; the
emergency limit is 3 a_max). The brake's prediction (``companion.replan.brake``)
steps the same axes. p, v, a and jerk are
continuous by construction (the state is integrated, never reset, except
by ``reset`` which takes the state to continue from).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Pole of the reference model (rad/s).
OMEGA_RAD_S = 6.0
#: Pole (rad/s) of the emergency brake's model (``ReferenceShaper.set_limits`` with
#: ``replan.emergency_accel_m_s2`` / ``emergency_jerk_m_s3``): the fastest that brakes to rest
#: without reversing (9 rad/s reverses at 0.04-0.1 m/s; tests/test_replan_emergency_brake.py).
EMERGENCY_OMEGA_RAD_S = 8.0


def _sat(x: float, limit: float) -> float:
    return limit if x > limit else (-limit if x < -limit else x)


def axis_snap(v_cmd: float, v: float, a: float, j: float, dt_s: float, a_max: float, j_max: float,
              s_max: float, k_v: float, k_a: float, k_j: float) -> float:
    """The snap (m/s^4) one axis of the reference model applies over a frame of ``dt_s``
    toward the command ``v_cmd`` from (v, a, j) (module doc's nested saturations). The
    shaper and the prediction of its own brake (``companion.replan.brake``) both use it."""
    # the speed error left once a is ramped to zero at j_max: braking on it
    # keeps the speed from overshooting while the acceleration unwinds
    e = v_cmd - v - a * abs(a) / (2.0 * j_max)
    a_des = _sat(k_v * e, a_max)
    j_des = _sat(k_a * (a_des - a), j_max)
    si = _sat(k_j * (j_des - j), s_max)
    # do not let the jerk overshoot its target within one frame
    if abs(si) * dt_s > abs(j_des - j):
        si = (j_des - j) / dt_s
    return si


#: Below this horizontal speed (m/s) a command gives no direction (``planar_snap``): the
#: brake's axes (``brake_frame``); below it a state's speed (m/s^2: its acceleration) neither.
FRAME_EPS_M_S = 1e-9


def brake_frame(vx: float, vy: float, ax: float, ay: float) -> tuple:
    """The horizontal unit vector a brake stops along from a state no command reached (module
    doc): the velocity's direction, the acceleration's from rest, E when neither has one.
    Across it is the other axis of the brake."""
    n = math.hypot(vx, vy)
    if n > FRAME_EPS_M_S:
        return vx / n, vy / n
    n = math.hypot(ax, ay)
    if n > FRAME_EPS_M_S:
        return ax / n, ay / n
    return 1.0, 0.0


def planar_snap(cx: float, cy: float, vx: float, vy: float, ax: float, ay: float, jx: float, jy: float,
                dt_s: float, a_max: float, j_max: float, s_max: float, k_v: float, k_a: float,
                k_j: float, brake_u: tuple) -> tuple:
    """The horizontal snap (m/s^4, E and N) of the reference model over a frame of ``dt_s``
    toward the command (cx, cy) from v, a, j: ``axis_snap`` along the command's direction and
    across it (module doc). A zero command (the brake) is on the axes ``brake_u`` (a unit
    vector and the one +90 deg from it; ``ReferenceShaper.preview`` chooses it). A command
    along E or N is on E and N to the last bit (a rotation by a multiple of 90 deg is exact)."""
    n = math.hypot(cx, cy)
    ux, uy = (cx / n, cy / n) if n > FRAME_EPS_M_S else brake_u
    # along (u) and across (w = u turned +90 deg)
    su = axis_snap(cx * ux + cy * uy, vx * ux + vy * uy, ax * ux + ay * uy, jx * ux + jy * uy,
                   dt_s, a_max, j_max, s_max, k_v, k_a, k_j)
    sw = axis_snap(cy * ux - cx * uy, vy * ux - vx * uy, ay * ux - ax * uy, jy * ux - jx * uy,
                   dt_s, a_max, j_max, s_max, k_v, k_a, k_j)
    return su * ux - sw * uy, su * uy + sw * ux


@dataclass(frozen=True, slots=True)
class ShapedState:
    """Reference state (ENU, float 3-tuples): p m, v m/s, a m/s^2, jerk m/s^3, snap m/s^4;
    ``brake_u``: the horizontal axis (unit 2-tuple) a brake from it is on (the last command's
    direction; module doc), None when no command reached it (``brake_frame`` of its own)."""

    p: tuple
    v: tuple
    a: tuple
    jerk: tuple
    snap: tuple
    brake_u: tuple | None = None


class ReferenceShaper:
    """Third-order velocity-command tracker (module doc).

    Parameters
    ----------
    accel_m_s2, jerk_m_s3, snap_m_s4 : float
        Per-axis limits of a, jerk and snap, horizontally on the command's axes (module doc;
        default snap: 5 jerk_m_s3 per s).
    omega_rad_s : float
        Pole of the unsaturated model.
    """

    def __init__(self, accel_m_s2: float, jerk_m_s3: float, snap_m_s4: float | None = None,
                 omega_rad_s: float = OMEGA_RAD_S) -> None:
        self.set_limits(accel_m_s2, jerk_m_s3, snap_m_s4, omega_rad_s)
        self.p = [0.0, 0.0, 0.0]
        self.v = [0.0, 0.0, 0.0]
        self.a = [0.0, 0.0, 0.0]
        self.j = [0.0, 0.0, 0.0]
        self.s = [0.0, 0.0, 0.0]
        self.brake_u: tuple | None = None

    def set_limits(self, accel_m_s2: float, jerk_m_s3: float, snap_m_s4: float | None = None,
                   omega_rad_s: float = OMEGA_RAD_S) -> None:
        """Limits and pole from now on; the state goes on from where it is (continuous)."""
        self.a_max = float(accel_m_s2)
        self.j_max = float(jerk_m_s3)
        self.s_max = float(snap_m_s4) if snap_m_s4 is not None else 5.0 * self.j_max
        self.k_j = 3.0 * omega_rad_s
        self.k_a = omega_rad_s
        self.k_v = omega_rad_s / 3.0

    def reset(self, p, v, a, jerk) -> None:
        """Continue from this state (ENU 3-sequences)."""
        self.p = [float(x) for x in p]
        self.v = [float(x) for x in v]
        self.a = [float(x) for x in a]
        self.j = [float(x) for x in jerk]
        self.s = [0.0, 0.0, 0.0]
        self.brake_u = None

    def state(self) -> ShapedState:
        return ShapedState(tuple(self.p), tuple(self.v), tuple(self.a), tuple(self.j), tuple(self.s),
                           self.brake_u)

    def preview(self, dt_s: float, v_cmd) -> ShapedState:
        """The state ``step(dt_s, v_cmd)`` would reach, without moving there."""
        if dt_s <= 0.0:
            return self.state()
        p, v, a, j = self.p, self.v, self.a, self.j
        lim = (self.a_max, self.j_max, self.s_max, self.k_v, self.k_a, self.k_j)
        # a zero command brakes on the last command's axes (module doc)
        n = math.hypot(v_cmd[0], v_cmd[1])
        if n > FRAME_EPS_M_S:
            brake_u = (v_cmd[0] / n, v_cmd[1] / n)
        else:
            brake_u = self.brake_u if self.brake_u is not None else brake_frame(v[0], v[1], a[0], a[1])
        s = [*planar_snap(v_cmd[0], v_cmd[1], v[0], v[1], a[0], a[1], j[0], j[1], dt_s, *lim, brake_u=brake_u),
             axis_snap(v_cmd[2], v[2], a[2], j[2], dt_s, *lim)]
        h, h2, h3, h4 = dt_s, dt_s * dt_s / 2.0, dt_s ** 3 / 6.0, dt_s ** 4 / 24.0
        return ShapedState(tuple(p[i] + v[i] * h + a[i] * h2 + j[i] * h3 + s[i] * h4 for i in range(3)),
                           tuple(v[i] + a[i] * h + j[i] * h2 + s[i] * h3 for i in range(3)),
                           tuple(a[i] + j[i] * h + s[i] * h2 for i in range(3)),
                           tuple(j[i] + s[i] * h for i in range(3)), tuple(s), brake_u)

    def commit(self, state: ShapedState) -> ShapedState:
        """Move to a state ``preview`` gave (the frame's step)."""
        self.p, self.v, self.a, self.j, self.s = (list(state.p), list(state.v), list(state.a),
                                                  list(state.jerk), list(state.snap))
        self.brake_u = state.brake_u
        return state

    def step(self, dt_s: float, v_cmd) -> ShapedState:
        """Advance by ``dt_s`` toward the velocity command ``v_cmd`` (ENU m/s); the new state."""
        if dt_s <= 0.0:
            return self.state()
        return self.commit(self.preview(dt_s, v_cmd))
