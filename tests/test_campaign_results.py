"""Outcome classification (hand-made report dicts), the Wilson interval, the summary page."""

from __future__ import annotations

import math

import pytest

from companion.campaign.results import classify, make_row, table
from companion.campaign.summary import html_page, outcome_table, wilson_interval

SCEN = {"campaign": "c", "scenario": 4, "mission": "flat-rectangle", "seed": 9, "cut_s": 10.0,
        "control": "companion", "overrides": {"sim": {"obstacles": [
            {"type": "cylinder", "x": 1.0, "y": 2.0, "height": 3.0, "radius": 0.2}]}}}


@pytest.mark.parametrize("report, outcome", [
    ({"completed": True, "crashed": False, "violation": None}, "completed"),
    ({"completed": False, "crashed": False, "violation": {"kind": "no_route", "detail": "blocked"}}, "held"),
    # a crash wins over everything, even a report that says completed
    ({"completed": True, "crashed": True, "crash": {"t_s": 3.0, "text": "hit obstacle 0"}}, "crashed"),
    ({"completed": False, "crashed": True, "violation": {"kind": "no_route", "detail": "x"}}, "crashed"),
    ({"completed": False, "crashed": False, "violation": {"kind": "tracking", "detail": "5 m off"}}, "failed"),
    ({"completed": False, "crashed": False, "violation": None, "error": "link lost"}, "failed"),
    (None, "failed"),
])
def test_classify(report, outcome):
    assert classify(report, "boom" if report is None else None)[0] == outcome


def test_reasons():
    assert classify({"completed": False, "crashed": True, "crash": {"text": "hit obstacle 0"}}) == \
        ("crashed", "hit obstacle 0")
    assert classify(None, "KilledWorker: died twice") == ("failed", "KilledWorker: died twice")
    assert classify({"completed": False, "violation": {"kind": "no_route", "detail": "blocked"}}) == \
        ("held", "blocked")


def test_row_columns_and_params():
    rep = {"completed": True, "crashed": False, "tracking": {"max_error_m": 0.004, "rms_error_m": 0.001},
           "replanning": {"min_clearance_m": 0.7, "extra_path_m": 1.5, "events": 2,
                          "event_list": [{"pos_enu_m": [3.0, 4.0, 1.5]}]}}
    r = make_row(SCEN, rep, None, 12.3456)
    assert (r["outcome"], r["n_obstacles"], r["max_obstacle_height_m"]) == ("completed", 1, 3.0)
    assert (r["min_clearance_m"], r["tracking_max_error_m"], r["extra_path_m"]) == (0.7, 0.004, 1.5)
    assert (r["event_x_m"], r["event_y_m"], r["wall_s"]) == (3.0, 4.0, 12.346)
    t = table([r, make_row(dict(SCEN, scenario=1), None, "x", 0.0)])
    assert t.column("scenario").to_pylist() == [1, 4]          # sorted by scenario
    assert t.column("outcome").to_pylist() == ["failed", "completed"]


def test_wilson_hand_worked():
    # 0 of 50: upper bound z^2 / (n + z^2) = 3.8415 / 53.8415 = 0.07135
    lo, hi = wilson_interval(0, 50)
    assert lo == 0.0 and hi == pytest.approx(0.0713, abs=5e-5)
    # 5 of 10 is symmetric about 0.5: 0.5 +- z sqrt(0.025 + z^2/400) / (1 + z^2/10)
    z = 1.959963984540054
    half = z * math.sqrt(0.025 + z * z / 400) / (1 + z * z / 10)
    assert wilson_interval(5, 10) == pytest.approx((0.5 - half, 0.5 + half))
    assert half == pytest.approx(0.2634, abs=1e-4)


def test_wilson_against_scipy():
    stats = pytest.importorskip("scipy.stats")
    for k, n in ((0, 50), (3, 20), (1, 500), (49, 50), (7, 7)):
        ci = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
        assert wilson_interval(k, n) == pytest.approx((ci.low, ci.high), abs=1e-12)


def test_outcome_table_and_self_contained_html(tmp_path):
    rows = [make_row(dict(SCEN, scenario=i), {"completed": True, "crashed": False}, None, 1.0) for i in range(49)]
    rows.append(make_row(dict(SCEN, scenario=49), {"completed": False, "crashed": True, "crash": {"text": "hit"}},
                         None, 1.0))
    t = {k: (c, lo, hi) for k, c, _, lo, hi in outcome_table(rows)}
    assert t["crashed"][0] == 1 and t["completed"][0] == 49 and t["failed"] == (0, 0.0, pytest.approx(0.0713, abs=5e-5))
    png = tmp_path / "f.png"
    png.write_bytes(b"\x89PNG\r\n\x1a\nxx")
    page = html_page("c", rows, tmp_path, 10.0, [png])
    assert "data:image/png;base64," in page
    assert "http://" not in page and "https://" not in page and "src='f.png'" not in page
    assert "companion demo --scenario" in page and "0049.yaml" in page


def test_one_failure_map_per_mission_each_with_its_own_flights():
    """Two base missions have two fields in their own frames: a flight that did not complete
    is drawn on its own mission's map only (a campaign of obstacle-low and tilted-hexagon put
    both missions' holds on the first one's map). One mission keeps ``map_failures.png``."""
    from companion.campaign.summary import map_groups

    rows = [{"scenario": 0, "mission": "obstacle-low", "outcome": "held"},
            {"scenario": 1, "mission": "/x/fields/my-field/mission.yaml", "outcome": "crashed"},
            {"scenario": 2, "mission": "obstacle-low", "outcome": "completed"}]
    fields = {"obstacle-low": "F1", "/x/fields/my-field/mission.yaml": "F2"}
    groups = map_groups(rows, fields)
    assert [(n, f, [r["scenario"] for r in mine]) for n, f, mine in groups] == [
        ("map_failures_obstacle-low.png", "F1", [0, 2]),
        ("map_failures_my-field.png", "F2", [1])]
    one = map_groups(rows[:1] + rows[2:], {"obstacle-low": "F1"})
    assert [(n, f, len(mine)) for n, f, mine in one] == [("map_failures.png", "F1", 2)]
    # without fields (a spec without obstacles, or the search), still one map per mission
    assert [n for n, _, _ in map_groups(rows, None)] == ["map_failures_obstacle-low.png", "map_failures_my-field.png"]
