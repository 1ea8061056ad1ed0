"""Pre-flight sensor coverage (companion/replan/coverage_check.py, ``--sensor-gap``).

Hand-worked frames: the pointing law turns body y toward the target, level
body: b2 = horizontal unit vector toward the target, b1 = b2 x e_z. With the
target due north, b1 = north x up = east: flying east is flying forward;
flying north is flying toward body +y (left).
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from mavcore.mission.sim import RangefinderConfig, default_rangefinders
from companion.replan.coverage_check import (CONTROL_DELAY_S, allowed_speed, beam_from_config, check_coverage,
                                             level_body_axes, stopping_distance_m)

ROOT = Path(__file__).resolve().parents[1]
FLAT = ROOT / "missions" / "flat-rectangle"
A, C = 1.0, 0.5 + 0.442          # braking (m/s^2) and clearance + body radius (m)


def _line(direction_enu, speed, n=101, dt=0.1):
    t = np.arange(n) * dt
    d = np.asarray(direction_enu, float) / np.linalg.norm(direction_enu)
    v = np.tile(d * speed, (n, 1))
    p = np.cumsum(v * dt, axis=0) + np.array([0.0, 0.0, 1.5])
    return t, p, v


def test_allowed_speed_solves_the_stopping_distance_by_hand():
    # v^2/2 + 0.15 v = 1: v = -0.15 + sqrt(0.0225 + 2)
    v = float(allowed_speed(1.0 + C, A, 0.15, C))
    assert v == pytest.approx(-0.15 + math.sqrt(2.0225), abs=1e-12)
    assert float(stopping_distance_m(v, A, 0.15, C)) == pytest.approx(1.0 + C, abs=1e-12)
    assert float(allowed_speed(C, A, 0.15, C)) == 0.0      # a beam that reaches only the clearance


def test_level_body_axes_turn_body_y_toward_the_target():
    R = level_body_axes(np.array([[0.0, 0.0, 1.5]]), np.array([0.0, 10.0, 0.0]))[0]
    assert np.allclose(R[:, 1], [0, 1, 0]) and np.allclose(R[:, 0], [1, 0, 0]) and np.allclose(R[:, 2], [0, 0, 1])
    # target to the north-east: forward is south-east, travel east is 45 deg left of forward
    R = level_body_axes(np.array([[0.0, 0.0, 1.5]]), np.array([10.0, 10.0, 0.0]))[0]
    assert np.allclose(R.T @ [1.0, 0.0, 0.0], [math.sqrt(0.5), math.sqrt(0.5), 0.0])


def test_forward_beam_covers_forward_travel_and_nothing_covers_sideways():
    fwd = (beam_from_config(RangefinderConfig(id=0, orientation=0)),)
    target = np.array([0.0, 1000.0, 1.5])
    t, p, v = _line([1.0, 0.0, 0.0], 1.0)
    cov = check_coverage(t, p, v, target, fwd, A, C)
    assert cov.gaps == () and cov.time_scale == 1.0 and set(cov.sensor_id) == {0}
    t, p, v = _line([0.0, 1.0, 0.0], 1.0)           # toward the target: body +y, no beam there
    cov = check_coverage(t, p, v, target, fwd, A, C)
    assert len(cov.gaps) == 1 and cov.gaps[0].kind == "blind" and cov.time_scale == math.inf
    assert cov.gaps[0].allowed_speed_m_s == 0.0


def test_old_default_was_blind_45_deg_off_and_the_new_ring_is_not():
    # the failure: the nearest of forward/left/right (5 deg) is 45 deg off the travel
    old = tuple(beam_from_config(c) for c in (RangefinderConfig(id=0, orientation=0),
                                                RangefinderConfig(id=1, orientation=6),
                                                RangefinderConfig(id=2, orientation=2)))
    new = tuple(beam_from_config(c) for c in default_rangefinders())
    target = np.array([1000.0, 1000.0, 1.5])
    t, p, v = _line([1.0, 0.0, 0.0], 1.0)
    assert check_coverage(t, p, v, target, old, A, C).blind
    cov = check_coverage(t, p, v, target, new, A, C)
    assert cov.gaps == ()
    assert set(cov.sensor_id) == {2}                 # beam k looks 22.5 k deg left: 45 deg is beam 2
    # and every horizontal direction at 3 m/s (the transit speed) is covered by the ring
    for az in np.radians(np.arange(0.0, 360.0, 7.5)):
        t, p, v = _line([math.cos(az), math.sin(az), 0.0], 3.0, n=3)
        assert check_coverage(t, p, v, np.array([0.0, 1e4, 1.5]), new, A, C).gaps == ()


def test_short_range_gives_a_short_gap_and_the_uniform_slowdown_by_hand():
    beam = beam_from_config(RangefinderConfig(id=0, orientation=0, max_m=2.0, rate_hz=25.0))
    tau = 1.0 / 25.0 + CONTROL_DELAY_S
    # v^2/2 + tau v = 2 - C
    v_ok = -tau + math.sqrt(tau * tau + 2.0 * (2.0 - C))
    t, p, v = _line([1.0, 0.0, 0.0], 1.0, n=60)
    v[20:40] *= 1.5                                   # 1.5 m/s from t = 2.0 s to 3.9 s
    cov = check_coverage(t, p, v, np.array([0.0, 1000.0, 1.5]), (beam,), A, C)
    assert len(cov.gaps) == 1
    g = cov.gaps[0]
    assert g.kind == "short" and g.t_start_s == pytest.approx(2.0) and g.t_end_s == pytest.approx(3.9)
    assert g.p_enu_m == pytest.approx(tuple(p[20]))
    assert g.allowed_speed_m_s == pytest.approx(v_ok, abs=1e-12)
    assert cov.time_scale == pytest.approx(1.5 / v_ok, rel=1e-12)
    # mutation check: 1.0 m/s is below v_ok = 1.32 m/s, 1.5 above; with the
    # clearance left out the 1.5 m/s part would be covered (v = 1.86 m/s)
    assert 1.0 < v_ok < 1.5 < float(allowed_speed(2.0, A, tau, 0.0))


def test_speed_between_samples_is_held_to_the_smaller_allowed_speed_of_its_ends():
    beam = beam_from_config(RangefinderConfig(id=0, orientation=0, max_m=2.0, rate_hz=25.0))
    tau = 1.0 / 25.0 + CONTROL_DELAY_S
    v_ok = -tau + math.sqrt(tau * tau + 2.0 * (2.0 - C))          # 1.32 m/s, as above
    t, p, v = _line([1.0, 0.0, 0.0], 1.0, n=5)
    target = np.array([0.0, 1000.0, 1.5])
    assert check_coverage(t, p, v, target, (beam,), A, C).gaps == ()    # the samples alone: covered
    peaks = np.array([1.0, 1.0, 1.6, 1.0])                        # 1.6 m/s between t = 0.2 and 0.3 s
    cov = check_coverage(t, p, v, target, (beam,), A, C, peaks)
    assert len(cov.gaps) == 1
    g = cov.gaps[0]
    assert g.kind == "short" and (g.t_start_s, g.t_end_s) == pytest.approx((0.2, 0.3))
    assert g.planned_speed_m_s == 1.6 and g.allowed_speed_m_s == pytest.approx(v_ok, abs=1e-12)
    assert cov.time_scale == pytest.approx(1.6 / v_ok, rel=1e-12)


def test_hovering_is_not_checked():
    fwd = (beam_from_config(RangefinderConfig(id=0, orientation=0)),)
    t, p, v = _line([0.0, 1.0, 0.0], 0.04)             # 4 cm/s sideways: below MIN_SPEED_M_S
    assert check_coverage(t, p, v, np.array([0.0, 1000.0, 1.5]), fwd, A, C).gaps == ()


# --- the flight's gate --------------------------------------------------------------------------


def _mission_dir(tmp_path, rangefinders):
    for f in FLAT.iterdir():
        shutil.copy(f, tmp_path / f.name)
    doc = yaml.safe_load((FLAT / "mission.yaml").read_text())
    doc.setdefault("sim", {})["rangefinders"] = rangefinders
    (tmp_path / "mission.yaml").write_text(yaml.safe_dump(doc))
    return tmp_path / "mission.yaml"


@pytest.fixture(scope="module")
def flat_plan():
    from companion.flight_plan import FlightPlan
    from mavcore.mission import load_mission
    from companion.planner import plan_mission

    m = load_mission(FLAT / "mission.yaml")
    return FlightPlan.from_plan(plan_mission(m))


def test_gate_refuses_naming_the_gap_and_slow_flies_short_gaps_slower(tmp_path, flat_plan):
    from companion.flight_plan import sensor_coverage_gate
    from mavcore.errors import PlanError
    from mavcore.mission import load_mission

    # forward only: blind whenever the travel is not along body x
    m = load_mission(_mission_dir(tmp_path, [{"id": 0, "orientation": 0}]))
    for mode in ("refuse", "slow"):
        with pytest.raises(PlanError, match=r"sensor gap from t = [0-9.]+ s to [0-9.]+ s of the plan, "
                                            r"starting at ENU \(.*\) m: no rangefinder sees .* in time"):
            sensor_coverage_gate(m, flat_plan, mode)
    # a ring 100 deg tall, 1.5 m range: from 1.5 m the ground is 1.5 / sin 50 = 1.96 m away
    # (out of range), the lowest obstacle top (0.942 m down) is in view from 0.942 / tan 50 =
    # 0.79 m: the range binds, v^2/2 + 0.15 v = 1.5 - 0.942 allows 0.917 m/s for a top level
    # with the centre. Lower tops are seen at sqrt(1.5^2 - d^2) and need
    # sqrt(0.942^2 - d^2) less; the check's depth grid (0.942 / 8 steps) takes the first
    # step's far end with the level top's need: 1.5 -> 1.4954 m, 0.9125 m/s. The plan flies 1.04.
    short = [{"id": k, "orientation": 100, "rotation_flu_deg": [0.0, 0.0, 22.5 * k], "hfov_deg": 24.0,
              "vfov_deg": 100.0, "rate_hz": 20.0, "max_m": 1.5} for k in range(16)]
    m = load_mission(_mission_dir(tmp_path, short))
    with pytest.raises(PlanError, match="allow 0.91 m/s"):
        sensor_coverage_gate(m, flat_plan, "refuse")
    slow, doc = sensor_coverage_gate(m, flat_plan, "slow")
    v_ok = -0.15 + math.sqrt(0.15 ** 2 + 2.0 * (math.sqrt(1.5 ** 2 - (0.942 / 8) ** 2) - 0.942))
    tr0, tr1 = flat_plan.trajectory, slow.trajectory
    t0 = np.linspace(tr0.t0, tr0.tf, 4001)
    vmax0 = np.linalg.norm(tr0.sample(t0).v, axis=1).max()
    k = doc["time_scale"]
    assert doc["mode"] == "slow" and doc["checked"] and doc["gaps"] and k >= vmax0 / v_ok * (1 - 1e-3)
    # the same path, k times slower: positions at t0 + k t equal, speeds / k
    t1 = tr1.t0 + k * (t0 - tr0.t0)
    assert np.allclose(tr1.sample(t1).p, tr0.sample(t0).p, atol=1e-9)
    assert np.allclose(tr1.sample(t1).v, tr0.sample(t0).v / k, atol=1e-9)
    # every piece of the slowed trajectory, sampled every 0.5 ms or finer, stays under
    # v_ok (the old 10 Hz check flew 0.917009 m/s where 0.917005 is allowed; sampled
    # at h the peak is missed by |v''| h^2 / 8 ~ 1e-7 m/s here)
    knots = tr1.knot_times_s
    for a, b in zip(knots[:-1], knots[1:]):
        t = np.linspace(a, b, int((b - a) / 5e-4) + 2)
        assert np.linalg.norm(tr1.sample(t).v, axis=1).max() <= v_ok + 1e-9
    again, doc2 = sensor_coverage_gate(m, slow, "refuse")      # the slowed plan passes
    assert doc2["gaps"] == [] and again is slow
    from companion.flight_plan import slowed_mission      # and avoidance is no faster than the flight
    assert slowed_mission(m, k).replan.speed_m_s == pytest.approx(m.flight.speed_m_s / k)
    assert slowed_mission(m, 1.0) is m


@pytest.mark.slow
def test_fly_refuses_a_blind_mission_with_one_line_and_no_output(tmp_path):
    mission = _mission_dir(tmp_path, [{"id": 0, "orientation": 0}])
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, "-m", "companion", "fly", str(mission), "--connect", "udpout:127.0.0.1:9",
                        "--tlog", str(tmp_path / "f.tlog"), "--report", str(tmp_path / "r.json"), "--quiet"],
                       capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "sensor gap from t = " in lines[0] and "Traceback" not in r.stderr
    assert not (tmp_path / "f.tlog").exists() and not (tmp_path / "r.json").exists()
