"""plan.json format 2.x: the trajectory stored as its exact pieces, read back.

- the round trip plan -> plan.json -> trajectory matches the planner's
  in-memory trajectory within 1e-9 m at the same times (p, v, a, jerk, the
  pointing direction), in both stored forms (knot states for Q = 0, the
  coefficients for Q != 0);
- a stored 1.0 plan (``tests/data/plan-1.0``, the replay corpus's plan before 2.0) still loads, and ``companion fly``
  flies the trajectory its own samples describe;
- a 2.x plan is flown from its pieces, without solving the LQR again;
- broken pieces are one-line errors naming the key;
- ``timings_s.wall`` counts from the process start, and ``companion --help``
  imports none of the heavy libraries.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mavcore.errors import PlanError
from mavcore.mission import load_mission
from companion.plan_io import load_plan, plan_json_text, plan_to_json_dict
from companion.planner import plan_mission
from companion.trajectory import generate_trajectory
from mavcore.mission.trajectory import TrajectoryConfig

ROOT = Path(__file__).resolve().parents[1]
MISSION = ROOT / "missions" / "flat-rectangle" / "mission.yaml"
OLD_PLAN = ROOT / "tests" / "data" / "plan-1.0" / "flat-rectangle.json"
TOL_M = 1e-9


@pytest.fixture(scope="module")
def planned():
    mission = load_mission(MISSION)
    return mission, plan_mission(mission)


def _write(plan, mission, path: Path) -> Path:
    path.write_text(plan_json_text(plan_to_json_dict(plan, mission)), encoding="utf-8")
    return path


def _times(traj) -> np.ndarray:
    """Every knot, 1 kHz in between, and seeded random times (s)."""
    rng = np.random.default_rng(18)
    return np.concatenate([traj.knot_times_s, np.arange(traj.t0, traj.tf, 1e-3),
                           rng.uniform(traj.t0, traj.tf, 5000)])


def _assert_same_trajectory(loaded, in_memory, tol: float) -> None:
    t = _times(in_memory)
    a, b = in_memory.sample(t), loaded.sample(t)
    for k in ("p", "v", "a", "jerk", "pointing"):
        err = np.abs(getattr(a, k) - getattr(b, k)).max()
        assert err <= tol, f"{k}: {err:.3g}"
    assert loaded.t0 == in_memory.t0 and loaded.tf == in_memory.tf


def test_round_trip_of_a_default_plan_matches_the_in_memory_trajectory(planned, tmp_path):
    mission, plan = planned
    pf = load_plan(_write(plan, mission, tmp_path / "plan.json"))
    assert pf.data["trajectory"]["form"] == "knot-states" and pf.format_major == 2
    assert pf.t_s is None                                # no samples unless asked for
    # the stored numbers are the solver's knot states, bit for bit
    assert np.array_equal(pf.trajectory.knot_states, plan.trajectory.knot_states)
    assert np.array_equal(pf.trajectory.waypoint_knots, plan.trajectory.waypoint_knots)
    _assert_same_trajectory(pf.trajectory, plan.trajectory, TOL_M)
    # and the pieces pass through the way-points as the planner's do
    assert np.max(pf.trajectory.waypoint_residual_m) <= plan.stats.waypoint_residual_m + TOL_M


def test_round_trip_with_q_not_zero_stores_the_coefficients_bit_for_bit(planned, tmp_path):
    mission, plan = planned
    cfg = TrajectoryConfig(q_acceleration=1.0, q_jerk=3.0)
    w = plan.waypoints
    traj = generate_trajectory(w.t_s, w.p_enu_m, w.v_enu_m_s, w.a_enu_m_s2, cfg, target_enu_m=plan.target_enu_m)
    assert traj.knot_times_s.shape[0] > len(w.t_s)       # sub-knots: not only way-points
    plan_q = dataclasses.replace(plan, trajectory=traj)
    pf = load_plan(_write(plan_q, dataclasses.replace(mission, trajectory=cfg), tmp_path / "plan.json"))
    assert pf.data["trajectory"]["form"] == "polynomial" and pf.data["trajectory"]["degree"] == 27
    assert np.array_equal(pf.trajectory.coefficients, traj.coefficients)
    _assert_same_trajectory(pf.trajectory, traj, TOL_M)


def test_the_stored_old_format_plan_loads_and_flies_what_it_sampled():
    from companion.commands.fly import prepare

    doc = json.loads(OLD_PLAN.read_text(encoding="utf-8"))
    assert doc["format_version"] == "1.0" and set(doc["trajectory"]) == {"t", "p", "v", "a", "pointing"}
    pf = load_plan(OLD_PLAN)
    assert pf.format_major == 1 and pf.trajectory is None
    fp = prepare(load_mission(MISSION), str(OLD_PLAN))
    # the 1.0 writer sampled the trajectory the flight re-solves through the way-points
    s = fp.trajectory.sample(pf.t_s)
    assert np.abs(s.p - pf.p_enu_m).max() <= TOL_M
    assert np.abs(s.v - pf.v_enu_m_s).max() <= TOL_M
    assert np.abs(s.pointing - pf.pointing_enu).max() <= TOL_M


def test_a_2x_plan_is_flown_from_its_pieces_without_a_solve(planned, tmp_path, monkeypatch):
    import companion.trajectory as trajectory_pkg
    from companion.commands.fly import prepare

    mission, plan = planned
    path = _write(plan, mission, tmp_path / "plan.json")

    def no_solve(*args, **kwargs):
        raise AssertionError("the LQR was solved again")

    monkeypatch.setattr(trajectory_pkg, "generate_trajectory", no_solve)
    fp = prepare(mission, str(path))
    _assert_same_trajectory(fp.trajectory, plan.trajectory, TOL_M)
    assert np.array_equal(fp.target_enu_m, plan.target_enu_m)


def _spoil(doc: dict, how: str) -> None:
    tr = doc["trajectory"]
    va = tr["values"]
    if how == "base64":
        va["base64"] = va["base64"][:-8]
    elif how == "shape":
        va["shape"] = [va["shape"][0] - 1, 4, 3]
    elif how == "knots":
        tr["t"][1] += 1e-6                               # way-point 1 is no longer a knot
    elif how == "weights":
        doc["trajectory_weights"]["q_jerk"] = 1.0         # knot states cannot hold Q != 0 pieces
    elif how == "nan":
        raw = bytearray(base64.b64decode(va["base64"]))
        raw[0:8] = np.array([np.nan], "<f8").tobytes()
        va["base64"] = base64.b64encode(bytes(raw)).decode("ascii")


@pytest.mark.parametrize("how,key", [("base64", "trajectory.values.base64"), ("shape", "trajectory.values.shape"),
                                     ("knots", "trajectory.t"), ("weights", "trajectory.form"),
                                     ("nan", "trajectory.values")])
def test_broken_pieces_are_one_line_naming_the_key(planned, tmp_path, how, key):
    mission, plan = planned
    doc = plan_to_json_dict(plan, mission)
    _spoil(doc, how)
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(PlanError, match=f"plan.json: key '{key}'") as exc:
        load_plan(path)
    assert "\n" not in str(exc.value)


def test_timings_wall_counts_from_the_process_start():
    # 0.3 s pass before companion is imported at all: the figure must include them
    code = ("import time; time.sleep(0.3); t = time.perf_counter(); "
            "from companion.process_clock import process_wall_s; w = process_wall_s(); "
            "print(w, time.perf_counter() - t)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT)
    wall, after_import = map(float, r.stdout.split())
    assert wall >= 0.3 - 0.011                           # /proc/uptime has 10 ms steps
    assert wall < 60.0


def test_help_imports_no_heavy_library():
    code = ("import sys; from companion.cli import build_parser; build_parser(); "
            "print(sorted({m.split('.')[0] for m in sys.modules} & "
            "{'numpy', 'scipy', 'matplotlib', 'pymavlink', 'yaml', 'jsonschema', 'pyproj'}))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert r.stdout.strip() == "[]", r.stdout + r.stderr
