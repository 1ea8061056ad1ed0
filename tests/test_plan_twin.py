"""plan.json's binary twin (companion.plan_twin, format 2.1; issue 18, loading a plan in <= 0.5 s):
read only when it is the twin of the plan.json beside it, and then giving the same plan
as the JSON, array for array and bit for bit.

The twin's threshold is lowered so that the small bundled flat-rectangle plan gets one.
"""

from __future__ import annotations

import dataclasses
import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import companion.plan_twin as plan_twin
from mavcore.errors import PlanError
from mavcore.mission import load_mission
from companion.plan_io import load_plan, plan_json_text, plan_to_json_dict
from companion.planner import plan_mission

ROOT = Path(__file__).resolve().parents[1]
MISSION = ROOT / "missions" / "flat-rectangle" / "mission.yaml"
TOL_M = 1e-9


@pytest.fixture(scope="module")
def planned():
    mission = load_mission(MISSION)
    return mission, plan_mission(mission)


def _write(planned, path: Path, twin: bool = True) -> Path:
    """plan.json and, with ``twin``, its twin (as ``companion plan`` writes them)."""
    mission, plan = planned
    doc = plan_to_json_dict(plan, mission)
    data = plan_json_text(doc).encode("utf-8")
    path.write_bytes(data)
    if twin:
        old = plan_twin.TWIN_MIN_BYTES
        plan_twin.TWIN_MIN_BYTES = 0
        try:
            Path(plan_twin.twin_path(path)).write_bytes(plan_twin.twin_bytes(doc, data))
        finally:
            plan_twin.TWIN_MIN_BYTES = old
    return path


def _assert_same_plan(a, b) -> None:
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and np.array_equal(x, y), f.name
    assert len(a.sorties) == len(b.sorties) > 0
    for sa, sb in zip(a.sorties, b.sorties):
        assert sa.keys() == sb.keys() and all(np.array_equal(sa[k], sb[k]) for k in sa)
    ta, tb = a.trajectory, b.trajectory
    for k in ("knot_times_s", "knot_states", "waypoint_knots", "waypoint_targets", "coefficients", "target_enu_m"):
        assert np.array_equal(getattr(ta, k), getattr(tb, k)), k
    assert ta.config == tb.config
    assert (a.origin, a.stats, a.timings_s, a.format_major) == (b.origin, b.stats, b.timings_s, b.format_major)


def test_the_twin_gives_the_json_plan_bit_for_bit(planned, tmp_path, monkeypatch):
    with_twin = load_plan(_write(planned, tmp_path / "a.json"))
    without = load_plan(_write(planned, tmp_path / "b.json", twin=False))
    assert "waypoints" not in with_twin.data and "waypoints" in without.data   # the twin was read
    _assert_same_plan(with_twin, without)
    # the round trip plan.json (twin) -> trajectory stays within 1e-9 m of the in-memory one
    _, plan = planned
    t = np.linspace(plan.trajectory.t0, plan.trajectory.tf, 20001)
    assert np.abs(with_twin.trajectory.sample(t).p - plan.trajectory.sample(t).p).max() <= TOL_M


def test_a_twin_of_other_bytes_is_ignored(planned, tmp_path):
    path = _write(planned, tmp_path / "plan.json")
    text = path.read_text()
    path.write_text(text.replace('"name":"', '"name":"edited ', 1))    # plan.json edited after planning
    pf = load_plan(path)
    assert "waypoints" in pf.data and pf.data["name"].startswith("edited ")


def test_small_plans_and_plans_with_samples_get_none(planned):
    mission, plan = planned
    doc = plan_to_json_dict(plan, mission)
    data = plan_json_text(doc).encode("utf-8")
    assert len(data) < plan_twin.TWIN_MIN_BYTES and plan_twin.twin_bytes(doc, data) is None
    sampled = plan_to_json_dict(plan, mission, 2.0)
    assert plan_twin.twin_bytes(sampled, b"x" * plan_twin.TWIN_MIN_BYTES) is None
    assert plan_twin.twin_path("out/plan.json") == "out/plan.json.npz"


def _rewrite_twin(path: Path, **changes) -> None:
    tp = plan_twin.twin_path(path)
    with np.load(tp) as z:
        arrays = {k: z[k] for k in z.files}
    arrays.update(changes)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    Path(tp).write_bytes(buf.getvalue())


@pytest.mark.parametrize("how,key", [
    ("nan", "waypoints[].p"), ("times", "sorties[0].waypoints[].t"), ("counts", "sorties"),
    ("values", "trajectory.values"), ("corner", "waypoints[].corner"), ("short", "waypoints[].v"),
])
def test_a_bad_twin_is_one_line_naming_the_key(planned, tmp_path, how, key):
    path = _write(planned, tmp_path / "plan.json")
    with np.load(plan_twin.twin_path(path)) as z:
        a = {k: z[k] for k in z.files}
    if how == "nan":
        p = a["wp_p"].copy()
        p[3, 1] = np.nan
        _rewrite_twin(path, wp_p=p)
    elif how == "times":
        t = a["so_t"].copy()
        t[1] = t[0]
        _rewrite_twin(path, so_t=t)
    elif how == "counts":
        _rewrite_twin(path, so_count=a["so_count"] + 1)
    elif how == "values":
        _rewrite_twin(path, traj_values=a["traj_values"][:-1])
    elif how == "corner":
        _rewrite_twin(path, wp_corner=a["wp_corner"].astype(np.int8))
    else:
        _rewrite_twin(path, wp_v=a["wp_v"][:-1])
    with pytest.raises(PlanError) as exc:
        load_plan(path)
    assert f"key '{key}'" in str(exc.value) and "\n" not in str(exc.value)


def test_a_twin_that_is_not_an_npz_is_refused(planned, tmp_path):
    path = _write(planned, tmp_path / "plan.json")
    Path(plan_twin.twin_path(path)).write_bytes(b"PK\x03\x04 not a zip")
    with pytest.raises(PlanError, match="not a plan twin"):
        load_plan(path)


def test_a_compressed_twin_is_refused(planned, tmp_path):
    """np.savez stores its entries; a deflated entry could expand without bound."""
    path = _write(planned, tmp_path / "plan.json")
    with np.load(plan_twin.twin_path(path)) as z:
        arrays = {k: z[k] for k in z.files}
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    Path(plan_twin.twin_path(path)).write_bytes(buf.getvalue())
    with pytest.raises(PlanError, match="compressed"):
        load_plan(path)


def test_companion_plan_writes_the_twin_of_a_large_plan(tmp_path):
    """The CLI: a twin next to plan.json when the text reaches the threshold (lowered to 0
    here through a sitecustomize-free wrapper), whose digest is plan.json's."""
    out = tmp_path / "plan.json"
    code = ("import sys, companion.plan_twin as t; t.TWIN_MIN_BYTES = 0; from companion.cli import main; "
            "sys.exit(main(['plan', sys.argv[1], '-o', sys.argv[2]]))")
    subprocess.run([sys.executable, "-c", code, str(MISSION), str(out)], check=True, cwd=ROOT,
                   capture_output=True)
    twin = Path(plan_twin.twin_path(out))
    assert twin.exists()
    with np.load(twin) as z:
        assert np.array_equal(z["json_sha256"], plan_twin.digest(out.read_bytes()))
    assert "waypoints" not in load_plan(out).data


def test_the_plan_is_named_by_the_digest_of_the_bytes_read(planned, tmp_path):
    # the digest the twin is checked against is the one the flight's setup record names the
    # plan by (computed once): SHA-256 of the plan.json file, with or without a twin
    import hashlib

    from companion.commands.fly import MissionMaps, flight_setup, prepare

    mission, _ = planned
    for name, twin in (("a.json", True), ("b.json", False)):
        path = _write(planned, tmp_path / name, twin=twin)
        want = hashlib.sha256(path.read_bytes()).hexdigest()
        assert load_plan(path).sha256_hex == want
        for sortie in (None, 1):
            fp = prepare(mission, str(path), sortie, MissionMaps(mission))
            assert fp.plan_sha256_hex == want
        read = flight_setup(mission, str(path), "companion", None, {})["plan_sha"]
        assert read == want[:16]
        # given the digest, the file is not read again: a path that no longer exists still gets it
        gone = str(tmp_path / "moved.json")
        assert flight_setup(mission, gone, "companion", None, {}, plan_sha256_hex=want)["plan_sha"] == read
        assert flight_setup(mission, gone, "companion", None, {})["plan_sha"] is None


def test_a_sortie_flight_checks_the_whole_route_without_rebuilding_it(planned, tmp_path):
    # load_plan(rebuild_trajectory=False): the same plan but for the trajectory, which is
    # checked (a damaged one is still refused) and not rebuilt; companion fly --sortie uses it
    import json

    from companion.commands.fly import MissionMaps, prepare

    mission, _ = planned
    for name, twin in (("a.json", True), ("b.json", False)):
        path = _write(planned, tmp_path / name, twin=twin)
        full, light = load_plan(path), load_plan(path, rebuild_trajectory=False)
        assert full.trajectory is not None and light.trajectory is None
        for f in dataclasses.fields(full):
            x, y = getattr(full, f.name), getattr(light, f.name)
            if isinstance(x, np.ndarray):
                assert np.array_equal(x, y), f.name
        # the sortie flown is the same either way (it is solved through its own way-points)
        fp = prepare(mission, str(path), 1, MissionMaps(mission))
        so = full.sorties[0]
        assert np.array_equal(fp.waypoints_t_s, so["waypoint_t_s"])
        assert fp.trajectory.t0 == so["waypoint_t_s"][0] and fp.trajectory.tf == so["waypoint_t_s"][-1]
    # a damaged trajectory is refused without the rebuild too
    doc = json.loads((tmp_path / "b.json").read_text())
    doc["trajectory"]["t"][1] = doc["trajectory"]["t"][0]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    for rebuild in (True, False):
        with pytest.raises(PlanError, match="trajectory.t"):
            load_plan(bad, rebuild_trajectory=rebuild)
