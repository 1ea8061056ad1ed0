"""The preflight check (``companion.preflight``) on every way-point list that can
be flown: the whole plan, each sortie, a cut and its re-solved trajectory, a
resume point. The field is flat-rectangle: flat terrain at z = 0 m (its
dem.asc is all zeros), flight.height_agl_m = 1.5 m, so the allowed band is
[0.5 * 1.5, 1.5 + max(2, 1.5)] = [0.75, 3.5] m; the default vehicle's rotors
give at most 4 * 25 N / 4.34 kg = 23.041 m/s^2 of |a + g e_z|."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from companion.bundled import missions_dir
from mavcore.errors import PlanError
from mavcore.maps.field import load_mission_maps
from mavcore.mission import load_mission
from companion.plan_io import load_plan
from companion.preflight import (check_flight_plan, check_plan, check_waypoints, max_thrust_accel_m_s2,
                                 resume_index)

from test_bad_input import good_plan_doc

MISSION = missions_dir() / "flat-rectangle" / "mission.yaml"   # map: y in [-1, 11] m
G = 9.81


@pytest.fixture(scope="module")
def field():
    mission = load_mission(MISSION)
    grid, dem = load_mission_maps(mission)
    return mission, grid, dem


def _doc_with_sortie(mission) -> dict:
    doc = good_plan_doc(mission)
    doc["sorties"] = [{"waypoints": json.loads(json.dumps(doc["waypoints"]))}]
    return doc


def _plan(tmp_path, doc):
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(doc))
    return load_plan(path)


def test_the_hand_worked_limits(field):
    mission, _, dem = field
    assert float(dem.height_at(np.array([10.0]), np.array([8.75]))[0]) == 0.0
    assert max_thrust_accel_m_s2(mission.vehicle) == pytest.approx(4 * 25.0 / 4.34)


def test_the_bundled_missions_plans_and_sorties_pass():
    """Every bundled mission's own plan (made here), each sortie and a cut pass."""
    from companion.flight_plan import FlightPlan, sortie_flight_plan
    from companion.planner import plan_mission

    mission = load_mission(missions_dir() / "tilted-hexagon" / "mission.yaml")
    maps = load_mission_maps(mission)
    plan = plan_mission(mission)
    fp = FlightPlan.from_plan(plan, "planned")
    check_flight_plan("planned", fp, mission, *maps)
    check_flight_plan("cut", fp.cut(20.0, mission.trajectory), mission, *maps)
    for so in plan.sorties.sorties:
        w = so.waypoints
        check_flight_plan("sortie", sortie_flight_plan(w.t_s, w.p_enu_m, w.v_enu_m_s, w.a_enu_m_s2,
                                                       plan.target_enu_m, mission.trajectory), mission, *maps)


# (case, way-point index, key, value, text the message must hold). Values are
# set on sortie 0's way-point only: the whole plan stays good.
SORTIE_CASES = [
    ("underground-50m", 2, "p", [6.5, 8.75, -50.0], "below the clearance"),
    ("just-below-clearance", 2, "p", [6.5, 8.75, 0.74], "below the clearance"),
    ("just-above-ceiling", 2, "p", [6.5, 8.75, 3.51], "above the ceiling"),
    ("5km-off-the-map", 3, "p", [5003.0, 8.75, 1.5], "off the map"),
    ("at-1e300", 3, "p", [1e300, 8.75, 1.5], "off the map"),
    ("west-of-the-dem", 1, "p", [-30.0, 8.75, 1.5], "off the map"),
    ("1e4-m-s", 4, "v", [1e4, 0.0, 0.0], "more than 30 m/s"),
    ("31-m-s", 4, "v", [0.0, 31.0, 0.0], "more than 30 m/s"),
    ("accel-beyond-thrust", 1, "a", [0.0, 0.0, 14.0], "thrust"),          # |a + g| = 23.81 > 23.04
    ("accel-sideways-beyond-thrust", 1, "a", [21.0, 0.0, 0.0], "thrust"),  # hypot(21, 9.81) = 23.18
    ("accel-31", 1, "a", [0.0, 0.0, -31.0], "more than 30 m/s^2"),
]


@pytest.mark.parametrize("case", SORTIE_CASES, ids=[c[0] for c in SORTIE_CASES])
def test_a_bad_sortie_waypoint_is_refused_naming_the_sortie_and_index(case, field, tmp_path):
    _, i, key, value, text = case
    mission, grid, dem = field
    doc = _doc_with_sortie(mission)
    doc["sorties"][0]["waypoints"][i][key] = value
    with pytest.raises(PlanError) as exc:
        check_plan(_plan(tmp_path, doc), mission, grid, dem)
    msg = str(exc.value)
    assert f"plan.json: key 'sorties[0].waypoints[{i}].{key}'" in msg and text in msg, msg
    assert "\n" not in msg


@pytest.mark.parametrize("value", [[6.5, 8.75, 0.76], [6.5, 8.75, 3.49], [6.5, 10.9, 1.5]])
def test_just_inside_the_band_and_the_map_passes(value, field, tmp_path):
    mission, grid, dem = field
    doc = _doc_with_sortie(mission)
    doc["sorties"][0]["waypoints"][2]["p"] = value
    check_plan(_plan(tmp_path, doc), mission, grid, dem)


def test_accelerations_at_the_thrust_limit_pass(field):
    """|a + g e_z| = 22.81 and hypot(20.8, 9.81) = 23.00 are under 23.04 m/s^2."""
    mission, grid, dem = field
    t = np.array([0.0, 4.0])
    p = np.array([[3.0, 8.75, 1.5], [6.5, 8.75, 1.5]])
    for a1 in ([0.0, 0.0, 13.0], [20.8, 0.0, 0.0]):
        check_waypoints("x", "w", t, p, np.zeros((2, 3)), np.array([a1, [0.0, 0.0, 0.0]]), mission, grid, dem)


TIME_CASES = [
    ("negative-start", [-1.0, 4.0, 8.0], "w[0].t", "must be >= 0"),
    ("repeated", [0.0, 4.0, 4.0], "w[2].t", "strictly increasing"),
    ("backwards", [0.0, 8.0, 4.0], "w[2].t", "strictly increasing"),
    ("nan", [0.0, math.nan, 8.0], "w[1].t", "non-finite"),
    ("inf", [0.0, 4.0, math.inf], "w[2].t", "non-finite"),
    ("two-days", [0.0, 4.0, 172_800.0], "w[].t", "span"),
]


@pytest.mark.parametrize("case", TIME_CASES, ids=[c[0] for c in TIME_CASES])
def test_bad_times_are_refused(case, field):
    _, t, key, text = case
    mission, grid, dem = field
    p = np.array([[3.0, 8.75, 1.5], [6.5, 8.75, 1.5], [10.0, 8.75, 1.5]])
    with pytest.raises(PlanError) as exc:
        check_waypoints("plan.json", "w", np.array(t), p, np.zeros((3, 3)), np.zeros((3, 3)), mission, grid, dem)
    assert f"plan.json: key '{key}'" in str(exc.value) and text in str(exc.value), str(exc.value)


def test_a_sortie_with_times_not_increasing_is_refused_on_load(field, tmp_path):
    mission, _, _ = field
    doc = _doc_with_sortie(mission)
    doc["sorties"][0]["waypoints"][3]["t"] = 0.0
    with pytest.raises(PlanError, match=r"sorties\[0\]\.waypoints\[\]\.t"):
        _plan(tmp_path, doc)


def test_a_trajectory_that_leaves_the_band_is_refused(field):
    """Way-points in the band, but the middle one passes 1.5 m going down at 5 m/s:
    the re-solved trajectory is 2 m higher 0.4 s before it (3.5 m, the ceiling)
    and 0.75 m lower 0.15 s after it (the clearance), so it leaves the band."""
    from companion.flight_plan import sortie_flight_plan

    mission, grid, dem = field
    t = np.array([0.0, 4.0, 8.0])
    p = np.array([[3.0, 8.75, 1.5], [6.5, 8.75, 1.5], [10.0, 8.75, 1.5]])
    v = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -5.0], [0.0, 0.0, 0.0]])
    fp = sortie_flight_plan(t, p, v, np.zeros((3, 3)), [12.0, 20.0, 1.5], mission.trajectory, source="p.json --cut 9")
    check_waypoints("p.json", "w", t, p, v, np.zeros((3, 3)), mission, grid, dem)      # the way-points pass
    with pytest.raises(PlanError,
                       match=r"p\.json --cut 9: key 'trajectory\(t=[0-9.]+ s\)\.p': .* outside \[0\.75, 3\.5\] m"):
        check_flight_plan(fp.source, fp, mission, grid, dem)


def test_fly_refuses_a_bad_sortie_before_sending_anything(field, tmp_path, monkeypatch, capsys):
    """``companion fly --sortie 1`` with sortie way-point 2 underground: exit 2, one
    line naming the file, the sortie and the way-point; no datagram leaves."""
    import socket

    from companion.cli import main

    mission, _, _ = field
    doc = _doc_with_sortie(mission)
    doc["sorties"][0]["waypoints"][2]["p"] = [6.5, 8.75, -50.0]
    (tmp_path / "plan.json").write_text(json.dumps(doc))
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(0.3)
    port = vehicle.getsockname()[1]
    monkeypatch.chdir(tmp_path)
    try:
        rc = main(["fly", str(MISSION), "--plan", "plan.json", "--sortie", "1", "--quiet",
                   "--connect", f"udpout:127.0.0.1:{port}"])
        err = capsys.readouterr().err
        with pytest.raises(socket.timeout):
            vehicle.recvfrom(4096)
    finally:
        vehicle.close()
    assert rc == 2 and err.count("\n") == 1, err
    assert "plan.json: key 'sorties[0].waypoints[2].p'" in err and "Traceback" not in err
    assert not (tmp_path / "flight.tlog").exists() and not (tmp_path / "report.json").exists()


def test_resume_index_needs_a_finite_position():
    wp = np.array([[0.0, 0.0, 1.5], [10.0, 0.0, 1.5], [20.0, 0.0, 1.5]])
    assert resume_index(wp, (11.0, 1.0, 1.5)) == 1
    assert resume_index(wp, (19.0, -3.0, 2.0)) == 2
    assert resume_index(wp, (math.nan, 0.0, 1.5)) is None       # argmin over NaN would say 0
    assert resume_index(wp, (0.0, math.inf, 1.5)) is None
    assert resume_index(wp, None) is None
    assert resume_index(np.zeros((0, 3)), (0.0, 0.0, 0.0)) is None


def test_fly_checks_what_it_flies_before_opening_anything(field, tmp_path):
    """``execute`` (fly and demo) checks the flight plan it is given (here a sortie
    whose re-solved trajectory leaves the band) before the link or the tlog."""
    import socket

    from companion.commands.fly import execute
    from companion.flight_plan import sortie_flight_plan

    mission, _, _ = field
    t = np.array([0.0, 4.0, 8.0])
    p = np.array([[3.0, 8.75, 1.5], [6.5, 8.75, 1.5], [10.0, 8.75, 1.5]])
    v = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -5.0], [0.0, 0.0, 0.0]])
    fp = sortie_flight_plan(t, p, v, np.zeros((3, 3)), [12.0, 20.0, 1.5], mission.trajectory,
                            source="plan.json --sortie 2")
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(0.2)
    try:
        with pytest.raises(PlanError, match=r"plan\.json --sortie 2: key 'trajectory\(t="):
            execute(mission, fp, f"udpout:127.0.0.1:{vehicle.getsockname()[1]}", "companion",
                    str(tmp_path / "flight.tlog"))
        with pytest.raises(socket.timeout):
            vehicle.recvfrom(4096)
    finally:
        vehicle.close()
    assert not (tmp_path / "flight.tlog").exists()
