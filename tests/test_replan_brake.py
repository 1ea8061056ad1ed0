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
