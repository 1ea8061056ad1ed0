"""The reference shaper's predicted brake (``companion.replan.brake``): the stopping point
the avoiding modes keep outside the clearance (docs/replan.md "The stopping point").

The prediction steps the shaper's own law every ``BRAKE_DT_S``; the truth it is compared
with is the shaper itself stepped at the flight's 4 ms frames with a zero command, an
independent integration of the same model. From rest with no acceleration along an
axis the brake of a 1 m/s state is worked by hand below.
"""

from __future__ import annotations

import numpy as np
import pytest

from companion.replan.shaper import ReferenceShaper
from companion.replan.brake import brake_path

A, J = 1.0, 2.0


def _frame_stepped(v, a, j, seconds=12.0, dt=0.004):
    sh = ReferenceShaper(A, J)
    sh.reset((0.0, 0.0, 0.0), v, a, j)
    return np.array([sh.step(dt, (0.0, 0.0, 0.0)).p for _ in range(int(seconds / dt))])


def test_at_rest_the_path_is_the_point():
    bp = brake_path((1.0, 2.0, 3.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), ReferenceShaper(A, J))
    assert bp.shape == (1, 3) and bp[0] == pytest.approx([1.0, 2.0, 3.0])


def test_a_level_brake_from_1_m_s_stops_between_the_jerk_limited_optimum_and_the_governor_law():
    # no brake at these limits stops sooner than the time-optimal one: the acceleration
    # ramps to -A at J (0.5 s, 0.25 m/s lost, 0.5 - 0.25/3 ... = 0.458 m), then -A to rest
    # from 0.75 m/s (0.281 m): 0.740 m; the replanner's governor law, braking at A/2 after
    # 0.6 s, allows 1 / (2 * 0.5) + 0.6 = 1.6 m
    v0 = 1.0
    t1 = A / J
    s1 = v0 * t1 - J * t1 ** 3 / 6.0
    v1 = v0 - 0.5 * J * t1 ** 2
    optimum = s1 + v1 * v1 / (2 * A)
    assert optimum == pytest.approx(0.740, abs=1e-3)
    end = brake_path((0.0, 0.0, 0.0), (v0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), ReferenceShaper(A, J))[-1]
    assert optimum < end[0] < 1.6 and end[1:] == pytest.approx([0.0, 0.0])


def test_the_prediction_follows_the_frame_stepped_brake():
    rng = np.random.default_rng(20261127)
    states = [((1.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
              ((0.2, 0.0, 0.0), (0.8, 0.0, 0.0), (1.5, 0.0, 0.0))]      # still accelerating toward
    states += [(rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3), rng.uniform(-2, 2, 3)) for _ in range(12)]
    sh = ReferenceShaper(A, J)
    for v, a, j in states:
        bp = brake_path((0.0, 0.0, 0.0), v, a, j, sh)
        fine = _frame_stepped(v, a, j)
        # the stopping point within 4.5 cm (the replanner keeps 5 cm beyond the clearance) ...
        assert np.abs(bp[-1] - fine[-1]).max() < 0.045
        # ... and every point of the true brake within that of the predicted path
        gap = np.sqrt(((fine[::10, None, :] - bp[None, :, :]) ** 2).sum(axis=2)).min(axis=1)
        assert gap.max() < 0.045


def _rot(theta):
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("bearing_deg", [0.0, 30.0, 45.0, 117.0, 210.0, 333.0])
def test_a_brake_from_straight_motion_stops_on_the_line_flown_whatever_its_bearing(bearing_deg):
    # a state moving (and accelerating) along a bearing brakes along it: nothing pushes it
    # across, so the frame-stepped shaper and the prediction both stop on that line, as far
    # along it as the same brake along E. On fixed E and N axes a brake at 30 deg from
    # 1.3 m/s stopped 0.13 m off its line: each axis braked on its own, and the one with
    # more speed ran on (fresh seed 20261228 along, flight 5: into a row's margin)
    u = np.array([np.cos(np.radians(bearing_deg)), np.sin(np.radians(bearing_deg)), 0.0])
    for v0, a0 in ((1.3, 0.0), (0.4, 0.7), (2.0, -0.5)):
        on_e = _frame_stepped((v0, 0.0, 0.0), (a0, 0.0, 0.0), (0.0, 0.0, 0.0))[-1]
        fine = _frame_stepped(tuple(v0 * u), tuple(a0 * u), (0.0, 0.0, 0.0))
        across = fine[:, :2] @ np.array([-u[1], u[0]])
        assert np.abs(across).max() < 1e-9
        assert fine[-1] @ u == pytest.approx(on_e[0], abs=1e-9)
        bp = brake_path((0.0, 0.0, 0.0), tuple(v0 * u), tuple(a0 * u), (0.0, 0.0, 0.0), ReferenceShaper(A, J))
        assert np.abs(bp[:, :2] @ np.array([-u[1], u[0]])).max() < 1e-9


def test_any_brake_turned_with_the_state_turns_with_it():
    # the brake does not depend on the field's bearing: a random state turned about the
    # vertical brakes along the same path turned (frame-stepped and predicted)
    rng = np.random.default_rng(20261129)
    sh = ReferenceShaper(A, J)
    for _ in range(8):
        v, a, j = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3), rng.uniform(-2, 2, 3)
        R = _rot(rng.uniform(0.0, 2.0 * np.pi))
        fine0, fine1 = _frame_stepped(v, a, j), _frame_stepped(R @ v, R @ a, R @ j)
        assert np.abs(fine0 @ R.T - fine1).max() < 1e-9
        bp0 = brake_path((0.0, 0.0, 0.0), v, a, j, sh)
        bp1 = brake_path((0.0, 0.0, 0.0), R @ v, R @ a, R @ j, sh)
        assert bp0.shape == bp1.shape and np.abs(bp0 @ R.T - bp1).max() < 1e-9


def test_a_brake_already_begun_is_predicted_on_its_own_axes():
    # a brake from a turning state (acceleration across the motion) keeps the axes it began
    # on; the prediction from any state of it, given that axis, follows the rest of it
    sh = ReferenceShaper(A, J)
    sh.reset((0.0, 0.0, 0.0), (1.0, 0.3, 0.0), (-0.4, 0.9, 0.0), (0.0, 0.0, 0.0))
    for _ in range(100):                                   # 0.4 s into the brake
        st = sh.step(0.004, (0.0, 0.0, 0.0))
    assert st.brake_u == pytest.approx((1.0 / np.hypot(1.0, 0.3), 0.3 / np.hypot(1.0, 0.3)))
    rest = np.array([sh.step(0.004, (0.0, 0.0, 0.0)).p for _ in range(3000)])
    bp = brake_path(st.p, st.v, st.a, st.jerk, sh, brake_u=st.brake_u)
    assert np.abs(bp[-1] - rest[-1]).max() < 0.045


def test_a_brake_after_a_command_is_the_per_axis_brake_on_that_commands_axes():
    # commanded along a bearing for 0.2 s, then braked: the same as the scene turned so the
    # command is along E (rotation invariance), where the brake is the per-axis model on E
    # and N, stepped here axis by axis with ``axis_snap`` alone; the prediction from the
    # brake's first state (its ``brake_u``) ends within the 4.5 cm of the test above
    from companion.replan.shaper import axis_snap
    rng = np.random.default_rng(20261130)
    dt = 0.004
    for _ in range(6):
        theta = rng.uniform(0.0, 2.0 * np.pi)
        R = _rot(theta)
        v, a, j = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3), rng.uniform(-2, 2, 3)
        cmd_e = np.array([rng.uniform(0.3, 2.0), 0.0, rng.uniform(-0.3, 0.3)])
        paths, firsts = [], []
        for M in (np.eye(3), R):
            sh = ReferenceShaper(A, J)
            sh.reset((0.0, 0.0, 0.0), M @ v, M @ a, M @ j)
            for _ in range(50):
                sh.step(dt, tuple(M @ cmd_e))
            firsts.append(sh.state())
            paths.append(np.array([sh.step(dt, (0.0, 0.0, 0.0)).p for _ in range(2500)]))
        assert np.abs(paths[0] @ R.T - paths[1]).max() < 1e-9
        assert firsts[1].brake_u == pytest.approx((np.cos(theta), np.sin(theta)))
        # along E: each axis on its own
        st = firsts[0]
        lim = (A, J, 5.0 * J, 2.0, 6.0, 18.0)
        x = list(st.p)
        vv, aa, jj = list(st.v), list(st.a), list(st.jerk)
        for _ in range(2500):
            for i in range(3):
                s = axis_snap(0.0, vv[i], aa[i], jj[i], dt, *lim)
                x[i] += vv[i] * dt + aa[i] * dt * dt / 2 + jj[i] * dt ** 3 / 6 + s * dt ** 4 / 24
                vv[i], aa[i], jj[i] = (vv[i] + aa[i] * dt + jj[i] * dt * dt / 2 + s * dt ** 3 / 6,
                                       aa[i] + jj[i] * dt + s * dt * dt / 2, jj[i] + s * dt)
        assert np.abs(np.array(x) - paths[0][-1]).max() < 1e-9
        st1 = firsts[1]
        bp = brake_path(st1.p, st1.v, st1.a, st1.jerk, ReferenceShaper(A, J), brake_u=st1.brake_u)
        assert np.abs(bp[-1] - paths[1][-1]).max() < 0.045
