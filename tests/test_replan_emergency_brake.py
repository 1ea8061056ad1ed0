"""The emergency brake (docs/replan.md "The emergency brake"): a surface that the brake at
the normal limits (``replan.accel_m_s2`` / ``jerk_m_s3``) can no longer stop for is braked
for at ``replan.emergency_accel_m_s2`` / ``emergency_jerk_m_s3``.

The shaper's brake at the emergency limits is compared with the jerk-limited time-optimal
stop worked by hand (no brake at given limits stops sooner), with the shaper stepped at the
flight's 4 ms frames (the prediction's accuracy), and checked never to reverse. In flight,
a walker steps out of a vine row in front of the vehicle: with the emergency brake the
vehicle is not walked into; with the emergency limits set to the normal ones (the brake
broken) it is.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from companion.replan.brake import EMERGENCY_BRAKE_DT_S, brake_path
from companion.replan.shaper import EMERGENCY_OMEGA_RAD_S, ReferenceShaper
from mavcore.mission.replan import ReplanConfig

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import step_out_sweep  # noqa: E402

A, J = ReplanConfig.emergency_accel_m_s2, ReplanConfig.emergency_jerk_m_s3
A0, J0 = ReplanConfig.accel_m_s2, ReplanConfig.jerk_m_s3


def _emergency() -> ReferenceShaper:
    return ReferenceShaper(A, J, omega_rad_s=EMERGENCY_OMEGA_RAD_S)


def _optimum(v0: float, a_max: float, j_max: float) -> float:
    """Shortest stop (m) from v0 at rest acceleration with |a| <= a_max, |jerk| <= j_max:
    the acceleration ramps to its peak and back at j_max (a triangle when v0 < a_max^2 / j_max,
    else a trapezoid at a_max)."""
    if v0 <= a_max * a_max / j_max:
        t = 2.0 * math.sqrt(v0 / j_max)            # the triangle's base: v0 = j t^2 / 4
        return v0 * t / 2.0                        # symmetric deceleration: the mean speed is v0 / 2
    t_r = a_max / j_max                            # each ramp
    t_c = v0 / a_max - t_r                         # at a_max
    return v0 * (t_c + 2.0 * t_r) / 2.0


def test_the_hand_worked_optima():
    # 1 m/s at 3 m/s^2, 8 m/s^3: 1 < 9/8, a triangle 2 sqrt(1/8) = 0.707 s long, 0.354 m
    assert _optimum(1.0, 3.0, 8.0) == pytest.approx(0.35355, abs=1e-4)
    # at 1 m/s^2, 2 m/s^3: 1 > 1/2, ramps of 0.5 s round 0.5 s at 1 m/s^2: 1.5 s, 0.75 m
    assert _optimum(1.0, 1.0, 2.0) == pytest.approx(0.75, abs=1e-9)


@pytest.mark.parametrize("v0", [0.5, 1.0, 1.5])
def test_the_emergency_brake_stops_between_its_optimum_and_the_normal_optimum(v0):
    end = brake_path((0.0, 0.0, 0.0), (v0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), _emergency(),
                     EMERGENCY_BRAKE_DT_S)[-1]
    assert _optimum(v0, A, J) < end[0] < _optimum(v0, A0, J0)
    assert end[1:] == pytest.approx([0.0, 0.0])


def test_the_emergency_brake_never_reverses():
    rng = np.random.default_rng(20261127)
    for _ in range(40):
        v0 = float(rng.uniform(0.1, 2.0))
        a0 = float(rng.uniform(-A, A))
        sh = _emergency()
        sh.reset((0.0, 0.0, 0.0), (v0, 0.0, 0.0), (a0, 0.0, 0.0), (0.0, 0.0, 0.0))
        xs = np.array([sh.step(0.004, (0.0, 0.0, 0.0)).p[0] for _ in range(1500)])
        assert xs.max() - xs[-1] < 0.01, (v0, a0)                # at most 1 cm back
        assert abs(sh.v[0]) < 2e-3 and abs(sh.a[0]) < 1e-2       # at rest within 6 s


def test_the_prediction_follows_the_frame_stepped_emergency_brake():
    rng = np.random.default_rng(20261128)
    sh = _emergency()
    for _ in range(12):
        v, a, j = rng.uniform(-1.5, 1.5, 3), rng.uniform(-A, A, 3), rng.uniform(-J, J, 3)
        bp = brake_path((0.0, 0.0, 0.0), v, a, j, sh, EMERGENCY_BRAKE_DT_S)
        fine = _emergency()
        fine.reset((0.0, 0.0, 0.0), v, a, j)
        path = np.array([fine.step(0.004, (0.0, 0.0, 0.0)).p for _ in range(2000)])
        assert np.abs(bp[-1] - path[-1]).max() < 0.02
        gap = np.sqrt(((path[::10, None, :] - bp[None, :, :]) ** 2).sum(axis=2)).min(axis=1)
        assert gap.max() < 0.02


@pytest.mark.parametrize("key, value", [("emergency_accel_m_s2", 0.0), ("emergency_jerk_m_s3", -1.0),
                                        ("emergency_accel_m_s2", math.nan), ("emergency_jerk_m_s3", 25.0)])
def test_bad_emergency_limits_are_refused(key, value):
    with pytest.raises(ValueError, match=f"replan.{key}"):
        ReplanConfig(**{key: value})


def test_the_emergency_limits_are_never_below_the_normal_ones():
    assert ReplanConfig().emergency_limits() == (A, J)
    assert ReplanConfig(accel_m_s2=5.0, jerk_m_s3=4.0).emergency_limits() == (5.0, J)
    assert ReplanConfig(emergency_accel_m_s2=0.5, emergency_jerk_m_s3=1.0).emergency_limits() == (A0, J0)


def _step_out_flight(tmp_path, emergency: bool) -> dict:
    """flat-rectangle's first corridor, flown westward along y = 8.75 m at 1 m/s from
    x = 22 m. A worker inside the row below it (y = 6.9 m, hidden by the canopy) sets off at
    10 s across the corridor at 1 m/s: the vehicle first sees the worker 1.4 m away, nearer
    than the normal brake stops from 1 m/s (about 0.9 m) plus the 0.94 m the clearance
    sphere needs (``benchmarks/step_out_sweep.py``, which sweeps the time it sets off)."""
    return step_out_sweep.fly(tmp_path, 10.0, emergency)


@pytest.mark.slow
def test_a_worker_stepping_out_of_the_row_is_braked_for_and_not_walked_into(tmp_path):
    rep = _step_out_flight(tmp_path, True)
    rp = rep["replanning"]
    first = next(e for e in rp["event_list"] if e["obstacle_range_m"] is not None)
    normal_stop = brake_path((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                             ReferenceShaper(A0, J0))[-1][0]
    from companion.safety import GuardConfig
    from mavcore.mission import load_mission

    sphere = GuardConfig.from_mission(load_mission(tmp_path / "m.yaml")).required_m("obstacle")
    assert first["obstacle_range_m"] < normal_stop + sphere          # seen inside the normal stop
    assert any(e["action"] == "stop" and e["detail"].startswith("emergency brake") for e in rp["event_list"])
    assert rep["crashed"] is False and rep["crash"] is None
    assert rp["clearance_source"] == "sim_truth" and rp["min_clearance_obstacle"] == 0    # the walker
    assert rp["min_clearance_m"] > 0.15


@pytest.mark.slow
def test_with_the_emergency_brake_broken_the_same_worker_walks_into_the_vehicle(tmp_path):
    """The mutation: emergency limits equal to the normal ones."""
    rep = _step_out_flight(tmp_path, False)
    assert rep["replanning"]["min_clearance_m"] < 0.05


def test_the_exit_judges_the_state_the_frame_falls_back_to():
    """Leaving the emergency limits judges, at the normal limits and with
    ``EMERGENCY_EXIT_MARGIN_M`` more, the state the frame falls back to when its command
    fails: one frame at a zero command from the present state. Judging the present state
    instead let the two disagree (the present state's brake passed, the step's failed), and
    the limits alternated every frame at rest beside a row for 11.5 s (987 events; mix seed
    20261200, flight 0). The reference here moves at 0.3 m/s, calm, far from the row
    (tests/test_replan_stopping.py's scene): the first brake judged starts where the normal
    limits' zero-command frame leaves it (a shaper of its own, stepped once), not at the
    present point."""
    import test_replan_stopping as scene

    from companion.replan.replanner import EMERGENCY_EXIT_MARGIN_M, STOP_MARGIN_M

    rp = scene._shaping(scene._guard())
    state = ((1.0, 1.0, 1.0), (0.3, 0.0, 0.0), (0.2, 0.0, 0.0), (0.0, 0.0, 0.0))
    rp.shaper.reset(*state)
    rp._set_emergency(True)
    judged = []
    forecast = rp.guard.forecast_brake

    def spy(here, P, V, A, dt, since, margin_m, *rest):
        judged.append((np.array(P[0]), margin_m))
        return forecast(here, P, V, A, dt, since, margin_m, *rest)

    rp.guard.forecast_brake = spy
    scene._step(rp, (0.5, 0.0, 0.0))
    fallback = ReferenceShaper(A0, J0)                  # the normal limits, as _set_emergency(False) sets
    fallback.reset(*state)
    expected = np.array(fallback.step(scene.DT, (0.0, 0.0, 0.0)).p)
    first, margin = judged[0]
    assert margin == pytest.approx(STOP_MARGIN_M + EMERGENCY_EXIT_MARGIN_M)
    assert np.abs(expected - np.array(state[0])).max() > 1e-3          # the frame moves it
    assert first == pytest.approx(expected, abs=1e-12)
    assert not rp.emergency and rp.n_emergency_brakes == 0              # left, not re-entered


def test_the_exit_never_takes_the_emergency_brake_again_in_its_own_frame():
    """The margin rule is not monotonic in its margin: a brake that starts inside the wider
    band passes it by not closing there (``companion.safety.margin_rule``), where the narrower
    one, once kept, must be kept. tests/test_replan_stopping.py's row: the frame's margin
    (``STOP_MARGIN_M``, 0.05 m) keeps x <= 4.10 (0.85 + 0.05 m from the face at 5.0), the
    exit's (0.15 m) x <= 4.00. A reference just inside x = 4.10, creeping toward the row at
    5-10 mm/s, brakes to within 5 mm past it: the wider band passes (inside it, closing under
    the 5 mm tolerance), the frame's fails. An exit judged at the wider margin alone left the
    emergency limits there and took them again in the same frame, with a new emergency-brake
    event (every frame at rest beside a row in mix seed 20261200 flight 0). Swept across
    x = 4.090-4.105: no frame may count an emergency brake, and the sweep must cross the
    boundary (the exit taken at some points, refused at others)."""
    import test_replan_stopping as scene

    taken = refused = 0
    for x in np.arange(4.090, 4.1051, 0.0005):
        for v in (0.005, 0.01):
            rp = scene._shaping(scene._guard())
            rp.shaper.reset((float(x), 1.0, 1.0), (v, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
            rp._set_emergency(True)
            scene._step(rp, (0.0, 0.0, 0.0))
            assert rp.n_emergency_brakes == 0, (x, v)
            taken += not rp.emergency
            refused += rp.emergency
    assert taken > 0 and refused > 0


def test_the_emergency_brake_is_taken_only_when_the_normal_brake_would_enter_the_clearance():
    """``STOP_MARGIN_M`` (0.05 m) is the prediction's allowance, not the clearance: a normal
    brake that fails that band but keeps the clearance itself still stops for the surface,
    and is flown; the emergency limits are for a brake that would enter the clearance
    (tests/test_replan_stopping.py's row: the clearance begins at x = 4.15). Before, failing
    the band alone took them, whenever a brake ridden along the band's edge closed a
    millimetre more than the last (92 emergency brakes at rest beside a row in mix seed
    20261200 flight 0). A reference between the band (x <= 4.10) and the clearance, creeping
    or moving at up to 0.1 m/s toward the row, zero command: the emergency brake is counted
    exactly where the normal brake from the start ends inside the clearance (its own stop,
    ``brake_path`` at the normal limits, away from the boundary by 3 mm or more), and a
    reference that did not take it never enters the clearance."""
    import test_replan_stopping as scene

    checked = {True: 0, False: 0}
    for x in (4.102, 4.11, 4.12, 4.13):
        for v in (0.01, 0.02, 0.05, 0.1):
            end = brake_path((x, 1.0, 1.0), (v, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                             ReferenceShaper(A0, J0))[-1][0]
            if abs(end - 4.15) < 0.003:
                continue
            rp = scene._shaping(scene._guard())
            rp.shaper.reset((x, 1.0, 1.0), (v, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
            xs = [scene._step(rp, (0.0, 0.0, 0.0)).p[0] for _ in range(300)]
            enters = end > 4.15
            assert (rp.n_emergency_brakes > 0) == enters, (x, v, end)
            if not enters:
                assert max(xs) <= 4.15, (x, v)
            checked[enters] += 1
    assert checked[True] > 0 and checked[False] >= 4          # both sides of the boundary
