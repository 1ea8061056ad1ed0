"""Where a shaped reference stops: the reference shaper's own brake, predicted (pure).

The avoiding modes turn a velocity command into the reference with the
third-order shaper (``companion.replan.shaper``). Limiting the *command*'s
approach to a surface does not limit the *reference*'s: the shaper lags, so
the state it has built (its speed, and an acceleration still toward the
surface) keeps closing after the command has turned away (obstacles-wide seed
20261127, flight 15: 0.11-0.20 m/s toward a row's end for over a second while
the command moved away; the guard refused the sample). What the guard sees is
the shaped state; what it can still stop is the shaper's brake from that state.

``brake_path`` is that brake: the shaper with a zero velocity command from
(p, v, a, jerk), each axis on its own (the model is per axis), stepped every
``dt_s`` until at rest; the points it passes, the stopping point last. The
horizontal axes are the shaper's brake's: along the last command and across it
(``ShapedState.brake_u``; from a state no command reached, its own motion's,
``shaper.brake_frame``), so a brake turns with the field whatever its bearing. It is
the distance the reference still flies with nothing but braking, the delay
(the jerk ramp and the acceleration still toward the surface) included: the
CP_DELAY and stopping distance of PX4's collision prevention, for the reference
itself. ``Guard.check_path`` judges it (docs/replan.md "The stopping point").
"""

from __future__ import annotations

import numpy as np

from .shaper import axis_snap, brake_frame

#: Step (s) of the predicted brake: coarser than a frame (4 ms) for its cost; the
#: stopping point agrees with the frame-stepped brake within 1 cm
#: (``tests/test_replan_brake.py``), well inside the 0.1 m the replanner keeps.
BRAKE_DT_S = 0.05
#: Step (s) of the predicted emergency brake (``ReferenceShaper.set_limits`` with the emergency
#: limits): its faster pole and jerk need a finer step for the same accuracy (2 cm;
#: ``tests/test_replan_emergency_brake.py``).
EMERGENCY_BRAKE_DT_S = 0.01
#: An axis is at rest below these speed (m/s), acceleration (m/s^2) and jerk (m/s^3).
REST_V_M_S, REST_A_M_S2, REST_J_M_S3 = 2e-3, 1e-2, 5e-2
#: The prediction stops after this long (s) whatever the state (the shaper brakes from
#: 3 m/s in about 4 s at 1 m/s^2).
MAX_BRAKE_S = 10.0


def axis_brake(v: float, a: float, j: float, shaper, dt_s: float = BRAKE_DT_S,
               states: bool = False):
    """Displacements (m) of one axis of ``shaper``'s model braking from (v, a, j) with a
    zero command, one per ``dt_s``, until at rest (empty when already at rest). With
    ``states``: (displacements, speeds m/s, accelerations m/s^2), one each per step."""
    out: list[float] = []
    vs: list[float] = []
    acc: list[float] = []
    x = 0.0
    h, h2, h3, h4 = dt_s, dt_s * dt_s / 2.0, dt_s ** 3 / 6.0, dt_s ** 4 / 24.0
    args = (shaper.a_max, shaper.j_max, shaper.s_max, shaper.k_v, shaper.k_a, shaper.k_j)
    for _ in range(int(MAX_BRAKE_S / dt_s)):
        if abs(v) < REST_V_M_S and abs(a) < REST_A_M_S2 and abs(j) < REST_J_M_S3:
            break
        s = axis_snap(0.0, v, a, j, dt_s, *args)
        x += v * h + a * h2 + j * h3 + s * h4
        v, a, j = v + a * h + j * h2 + s * h3, a + j * h + s * h2, j + s * h
        out.append(x)
        if states:
            vs.append(v)
            acc.append(a)
    return (out, vs, acc) if states else out


def brake_path(p, v, a, jerk, shaper, dt_s: float = BRAKE_DT_S, brake_u: tuple | None = None) -> np.ndarray:
    """(M, 3) ENU points (m) of ``shaper``'s brake to rest from the state (p, v, a, jerk)
    (ENU 3-sequences), every ``dt_s``: the first row is ``p``, the last the stopping point
    (module doc). ``shaper``: a ``ReferenceShaper`` (its limits and gains); ``brake_u``: the
    state's brake axis (``ShapedState.brake_u``), None for a state no command reached."""
    return brake_states(p, v, a, jerk, shaper, dt_s, brake_u)[0]


def brake_states(p, v, a, jerk, shaper, dt_s: float = BRAKE_DT_S, brake_u: tuple | None = None) -> tuple:
    """(P, V, A): (M, 3) ENU positions (m), velocities (m/s) and accelerations (m/s^2) of
    ``brake_path``'s points, every ``dt_s`` from the state (its first row) to rest (an axis
    already at rest keeps its last speed and acceleration, within the rest thresholds).
    ``brake_u`` as ``brake_path``'s."""
    v = [float(c) for c in v]
    a = [float(c) for c in a]
    jerk = [float(c) for c in jerk]
    ux, uy = brake_u if brake_u is not None else brake_frame(v[0], v[1], a[0], a[1])

    def along(vec):                    # the state's components on (u, w = u turned +90 deg, up)
        return (vec[0] * ux + vec[1] * uy, vec[1] * ux - vec[0] * uy, vec[2])

    vb, ab, jb = along(v), along(a), along(jerk)
    axes = [axis_brake(vb[i], ab[i], jb[i], shaper, dt_s, states=True) for i in range(3)]
    m = max(len(x[0]) for x in axes)
    X, Vb, Ab = np.zeros((m + 1, 3)), np.empty((m + 1, 3)), np.empty((m + 1, 3))
    for i, (x, vs, acc) in enumerate(axes):
        Vb[:, i], Ab[:, i] = vb[i], ab[i]
        if x:
            n = len(x)
            X[1:n + 1, i] = x
            X[n + 1:, i] = x[-1]
            Vb[1:n + 1, i], Vb[n + 1:, i] = vs, vs[-1]
            Ab[1:n + 1, i], Ab[n + 1:, i] = acc, acc[-1]

    def enu(B):                        # back from (u, w, up) to ENU
        return np.column_stack([B[:, 0] * ux - B[:, 1] * uy, B[:, 0] * uy + B[:, 1] * ux, B[:, 2]])

    P = enu(X) + np.asarray(p, dtype=float)
    V, A = enu(Vb), enu(Ab)
    V[0], A[0] = v, a                  # the state itself, as given
    return P, V, A
