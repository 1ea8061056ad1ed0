"""The reference shaper's horizontal axes are the command's own (``companion.replan.shaper``).

Hand-worked premise: with the limits a_max = 1 m/s^2, j_max = 2 m/s^3 and the pole 6 rad/s
(k_v = 2 1/s), a step command of 1.5 m/s along (0.9, -0.4)/|.| asks
k_v v = 2 x (1.37, -0.61) = (2.74, -1.22) m/s^2 of E and N: both above a_max, so E and N
each saturated on its own accelerate at the same 1 m/s^2, at 45 deg, not along the command
(24 deg below E): the old per-axis model leaves the command's line by centimetres (fresh seed
20261222, flight 13: a give-way along a diagonal corridor flown into the row beside it).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.replan.shaper import ReferenceShaper, axis_snap, planar_snap

DT = 0.004
LIMITS = (1.0, 2.0)


def _enu_axes_step(sh: ReferenceShaper, cmd) -> None:
    """The old model: every ENU axis saturated on its own (the premise's comparison)."""
    lim = (sh.a_max, sh.j_max, sh.s_max, sh.k_v, sh.k_a, sh.k_j)
    s = [axis_snap(cmd[i], sh.v[i], sh.a[i], sh.j[i], DT, *lim) for i in range(3)]
    h, h2, h3, h4 = DT, DT * DT / 2, DT ** 3 / 6, DT ** 4 / 24
    for i in range(3):
        sh.p[i] += sh.v[i] * h + sh.a[i] * h2 + sh.j[i] * h3 + s[i] * h4
        sh.v[i] += sh.a[i] * h + sh.j[i] * h2 + s[i] * h3
        sh.a[i] += sh.j[i] * h + s[i] * h2
        sh.j[i] += s[i] * h


def _off_line(points, u) -> np.ndarray:
    """Distance (m) of each point from the line through the origin along the unit vector u."""
    return np.abs(points[:, 0] * u[1] - points[:, 1] * u[0])


def test_a_diagonal_command_is_flown_along_its_own_line():
    u = np.array([0.9, -0.4]) / math.hypot(0.9, -0.4)
    cmd = (1.5 * u[0], 1.5 * u[1], 0.0)
    new, old = ReferenceShaper(*LIMITS), ReferenceShaper(*LIMITS)
    P, Q = [], []
    for _ in range(int(4.0 / DT)):
        P.append(new.step(DT, cmd).p)
        _enu_axes_step(old, cmd)
        Q.append(tuple(old.p))
    P, Q = np.array(P), np.array(Q)
    # the premise: per axis, the reference leaves the line by centimetres
    assert _off_line(Q, u).max() > 0.05
    # on the command's axes, the across axis has nothing to do: on the line (rounding only)
    assert _off_line(P, u).max() < 1e-9
    # and it gets there: the speed along u reaches the command, overshooting less than 2 %
    speed = np.hypot(*np.diff(P[:, :2], axis=0).T) / DT
    assert speed[-1] == pytest.approx(1.5, abs=1e-3) and speed.max() <= 1.02 * 1.5


@pytest.mark.parametrize("direction", [(1, 0), (-1, 0), (0, 1), (0, -1), (0, 0)])
def test_along_e_or_n_and_braking_on_e_the_axes_are_e_and_n_to_the_last_bit(direction):
    # a rotation by a multiple of 90 deg is exact: every axis-aligned command, and a brake
    # (zero command) on the axis E, are the per-axis model's, bit for bit
    rng = np.random.default_rng(20261129)
    sh = ReferenceShaper(*LIMITS)
    lim = (sh.a_max, sh.j_max, sh.s_max, sh.k_v, sh.k_a, sh.k_j)
    for _ in range(200):
        c = rng.uniform(0.0, 3.0) * np.array(direction, dtype=float)
        v, a, j = rng.normal(0, 1, 2), rng.normal(0, 1, 2), rng.normal(0, 2, 2)
        got = planar_snap(c[0], c[1], v[0], v[1], a[0], a[1], j[0], j[1], DT, *lim, brake_u=(1.0, 0.0))
        want = tuple(axis_snap(c[i], v[i], a[i], j[i], DT, *lim) for i in range(2))
        assert got == want


def test_on_each_frames_command_axes_the_jerk_is_never_pushed_past_its_limit():
    # random commands held 4 ms-0.5 s each: on that frame's command axes (along, across) and
    # the vertical, a jerk component within its limit stays within it, and one beyond it
    # (built on the axes of an earlier command) only comes back: the snap moves each
    # component toward its target (within the limit) and never past it
    rng = np.random.default_rng(20261130)
    sh = ReferenceShaper(*LIMITS)
    j_max = LIMITS[1]
    beyond = n_frames = 0
    while n_frames < 20000:
        cmd = rng.normal(0.0, 1.5, 3)
        n = math.hypot(cmd[0], cmd[1])
        u = (cmd[0] / n, cmd[1] / n)

        def axes(vec):
            return np.abs([vec[0] * u[0] + vec[1] * u[1], vec[1] * u[0] - vec[0] * u[1], vec[2]])

        for _ in range(int(rng.integers(1, 125))):
            b = axes(sh.state().jerk)
            x = axes(sh.step(DT, cmd.tolist()).jerk)
            n_frames += 1
            assert np.all(x <= np.maximum(b, j_max) + 1e-9), (b, x)
            beyond += int((b > j_max + 1e-9).any())
    # the commands turn often enough that components do start beyond the limit
    assert beyond > 0


def test_a_held_command_keeps_the_acceleration_within_its_limit_on_its_axes():
    # a command held (any direction): on its axes |a| <= a_max up to one frame of jerk, as on
    # one axis of the per-axis model
    rng = np.random.default_rng(20261131)
    a_max, j_max = LIMITS
    for _ in range(20):
        sh = ReferenceShaper(*LIMITS)
        sh.reset((0.0, 0.0, 0.0), rng.normal(0.0, 1.0, 3), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        cmd = rng.normal(0.0, 2.0, 3)
        u = cmd[:2] / math.hypot(cmd[0], cmd[1])
        worst = 0.0
        for _ in range(int(3.0 / DT)):
            a = sh.step(DT, cmd.tolist()).a
            worst = max(worst, abs(a[0] * u[0] + a[1] * u[1]), abs(a[1] * u[0] - a[0] * u[1]), abs(a[2]))
        assert worst <= a_max + j_max * DT
