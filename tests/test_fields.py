"""Field input without guesswork (docs/fields.md): the sample 1 ha GeoJSON vineyard
plans, keeps its clearances from the vectors it was drawn from, flies every
corridor, and exports what a flight stack needs; the launch point's forms agree;
a field without a DEM is flat, with a warning only when no elevation is given."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from mavcore.config import from_dict
from mavcore.errors import MissionError
from mavcore.geodesy import geodetic2enu
from companion.launch import launch_enu_xy
from mavcore.mission import Mission, load_mission

ROOT = Path(__file__).resolve().parents[1]
VINEYARD = ROOT / "missions" / "vineyard-1ha"
#: make_field.py's launch point and row layout (ENU m about the parcel's south-west corner)
LAUNCH_ENU = (60.0, 5.0)


@pytest.fixture(scope="module")
def vineyard():
    from companion.planner import plan_mission

    mission = load_mission(VINEYARD / "mission.yaml")
    return mission, plan_mission(mission)


def _features():
    return json.loads((VINEYARD / "field.geojson").read_text())["features"]


def _enu(lonlat, home):
    a = np.asarray(lonlat, float)
    x, y, _ = geodetic2enu(a[:, 1], a[:, 0], home.alt_m, home.lat, home.lon, home.alt_m)
    return np.column_stack([x, y])


def _dense(path, step=0.05):
    path = np.asarray(path, float)
    return np.vstack([np.linspace(p, q, max(2, int(np.hypot(*(q - p)) / step) + 1)) for p, q in zip(path[:-1], path[1:])])


def _seg_dist(pts, a, b):
    ab = b - a
    t = np.clip(((pts - a) @ ab) / max(ab @ ab, 1e-12), 0.0, 1.0)
    return np.hypot(*(pts - a - t[:, None] * ab).T)


def test_sample_field_is_wgs84_with_the_documented_roles():
    feats = _features()
    roles = [f["properties"]["role"] for f in feats]
    assert roles.count("boundary") == 1 and roles.count("exclusion") == 1 and roles.count("launch") == 1
    assert roles.count("row") >= 40
    for f in feats:
        c = np.asarray(f["geometry"]["coordinates"], float).reshape(-1, 2)
        assert np.all(np.abs(c[:, 0] + 0.58) < 0.01) and np.all(np.abs(c[:, 1] - 44.81) < 0.01)   # [lon, lat]
    home = load_mission(VINEYARD / "mission.yaml").home
    ring = _enu(feats[0]["geometry"]["coordinates"][0], home)
    area = 0.5 * abs(np.dot(ring[:, 0], np.roll(ring[:, 1], -1)) - np.dot(np.roll(ring[:, 0], -1), ring[:, 1]))
    assert 9_000 < area < 12_000                                          # ~1 ha


def test_vineyard_plans_flat_from_its_launch_point_with_airframe_clearance(vineyard):
    mission, plan = vineyard
    assert plan.warnings == ()                             # elevation_m given: no flat-field warning
    assert np.allclose(plan.sorties.launch_xy_m, LAUNCH_ENU, atol=2e-3)   # the file's Point (1e-8 deg ~ 1 mm)
    # flat at elevation_m = home.alt_m: every way-point at height_agl_m
    assert np.allclose(plan.waypoints.p_enu_m[:, 2], mission.flight.height_agl_m, atol=1e-9)
    # clearance from the vectors themselves (not the raster): the rows (half their width)
    # and the shed; the raster costs at most one cell
    R = 0.315 + 0.127
    keep = R + mission.coverage.safety_margin_m - mission.field.resolution_m
    pts = np.vstack([_dense(s.path_xy_m) for s in plan.sorties.sorties])
    feats, home = _features(), mission.home
    rows = [_enu(f["geometry"]["coordinates"], home) for f in feats if f["properties"]["role"] == "row"]
    d_rows = np.min([_seg_dist(pts, r[0], r[1]) for r in rows], axis=0) - mission.field.row_width_m / 2
    shed = _enu(feats[1]["geometry"]["coordinates"][0], home)
    d_shed = np.min([_seg_dist(pts, a, b) for a, b in zip(shed[:-1], shed[1:])], axis=0)
    assert d_rows.min() >= keep and d_shed.min() >= keep
    # the launch point itself
    lp = np.asarray(plan.sorties.launch_xy_m)[None]
    assert min(_seg_dist(lp, r[0], r[1])[0] for r in rows) - mission.field.row_width_m / 2 >= keep


def test_vineyard_every_corridor_is_flown(vineyard):
    """Between two neighbouring rows (make_field.py: north-south, 2.5 m apart) the path
    runs along the corridor's centre line for at least 90 % of the shorter row."""
    mission, plan = vineyard
    feats, home = _features(), mission.home
    rows = [_enu(f["geometry"]["coordinates"], home) for f in feats if f["properties"]["role"] == "row"]
    path = np.asarray(plan.coverage.path_xy_m)
    seg_a, seg_b = path[:-1], path[1:]
    northward = np.abs(seg_a[:, 0] - seg_b[:, 0]) < 0.05
    full = [r for r in rows if np.hypot(*(r[1] - r[0])) > 50]          # rows the shed does not cut
    full.sort(key=lambda r: r[0, 0])
    n_checked = 0
    for r1, r2 in zip(full[:-1], full[1:]):
        if abs(r2[0, 0] - r1[0, 0] - 2.5) > 0.05:
            continue                                                   # the rows beside the shed
        xc = 0.5 * (r1[0, 0] + r2[0, 0])
        on = northward & (np.abs(seg_a[:, 0] - xc) < 0.1)
        flown = float(np.sum(np.abs(seg_b[on, 1] - seg_a[on, 1])))
        assert flown >= 0.9 * min(np.ptp(r1[:, 1]), np.ptp(r2[:, 1])), f"corridor at x = {xc:.2f}"
        n_checked += 1
    assert n_checked >= 30


def test_vineyard_exports_acceptance_radius_fence_and_no_nan(vineyard):
    """param2 = min(w / 3, w / 2 - R), w = 2.5 - 0.4 m; the fence keeps the navigation
    accuracy + the lateral limit (RTK 0.1 + 0.5 m, GNSS 3.0 + 0.5 m) from the path;
    no NaN anywhere (QGC writes unused params as 0)."""
    from companion.margins import plan_margins
    from companion.plan_io import field_fence, flight_items

    mission, plan = vineyard
    R, w = 0.315 + 0.127, 2.5 - 0.4
    want = min(w / 3.0, w / 2.0 - R)                         # 0.608 m: the airframe's room binds
    assert want <= w / 3.0
    s = plan.sorties.sorties[0]
    pts = _dense(s.path_xy_m)
    for accuracy, margin in (("rtk", 0.1 + 0.5), ("gnss", 3.0 + 0.5)):
        m = dataclasses.replace(mission, navigation=dataclasses.replace(mission.navigation, accuracy=accuracy))
        p = dataclasses.replace(plan, margins=plan_margins(m, plan.grid, plan.coverage))
        fence = field_fence(p, m)
        items = flight_items(p, m, s, fence)
        wps = [it for it in items.mission if it.command == 16]
        assert all(it.params[1] == pytest.approx(want, abs=2e-3) for it in wps)     # w measured from the detected spacing
        assert all(math.isfinite(v) for it in items.mission + items.fence for v in it.params)
        f = np.asarray(fence)
        d = np.min([_seg_dist(pts, a, b) for a, b in zip(f, np.roll(f, -1, axis=0))], axis=0)
        assert d.min() >= margin, accuracy
        assert p.margins.fence_margin_m == pytest.approx(margin)


def _mission(extra: dict) -> Mission:
    data = {"name": "t", "field": {"file": "field.geojson"}, "home": {"lat": 44.81, "lon": -0.58, "alt_m": 35.0}}
    data.update(extra)
    m = from_dict(Mission, data, "t.yaml")
    return dataclasses.replace(m, base_dir=str(VINEYARD), source="t.yaml")


def test_launch_forms_agree():
    lon, lat = next(f for f in _features() if f["properties"]["role"] == "launch")["geometry"]["coordinates"]
    forms = [{"launch": {"lat": lat, "lon": lon}}, {"launch": {"type": "Point", "coordinates": [lon, lat]}},
             {"launch": {"file": "field.geojson"}}, {"launch": {"enu_m": list(LAUNCH_ENU)}},
             {"energy": {"launch_xy_m": list(LAUNCH_ENU)}}]
    got = np.array([launch_enu_xy(_mission(f)) for f in forms])
    assert np.allclose(got, LAUNCH_ENU, atol=2e-3)
    assert launch_enu_xy(_mission({})) is None
    for bad in ({"launch": {"lat": lat}}, {"launch": {"lat": lat, "lon": lon, "enu_m": [0, 0]}},
                {"launch": {"enu_m": [0, 0]}, "energy": {"launch_xy_m": [0, 0]}},
                {"launch": {"type": "Point"}}, {"launch": {"coordinates": [lat, 200.0], "type": "Point"}}):
        with pytest.raises(MissionError):
            _mission(bad)


def test_flat_field_without_dem_warns_only_without_elevation(tmp_path):
    from mavcore.maps.field import flat_field_warning, load_mission_dem

    m = _mission({})
    assert "home.alt_m = 35 m AMSL" in flat_field_warning(m)
    dem = load_mission_dem(m)
    assert np.allclose(dem.height_at(np.array([-500.0, 0.0, 800.0]), np.array([300.0, 0.0, -900.0])), 0.0)
    m = _mission({"elevation_m": 37.5})
    assert flat_field_warning(m) is None
    assert np.allclose(load_mission_dem(m).height_at(np.array([10.0, 120.0]), np.array([5.0, 90.0])), 2.5)
    with pytest.raises(MissionError):
        _mission({"elevation_m": 37.5, "dem": "dem.asc"})


def test_bad_launch_file_is_one_line_exit_2(tmp_path, capsys):
    from companion.cli import main

    (tmp_path / "field.geojson").write_text((VINEYARD / "field.geojson").read_text())
    (tmp_path / "none.geojson").write_text('{"type": "FeatureCollection", "features": []}')
    text = (VINEYARD / "mission.yaml").read_text().replace("launch: {file: field.geojson}", "launch: {file: none.geojson}")
    (tmp_path / "mission.yaml").write_text(text)
    assert main(["plan", str(tmp_path / "mission.yaml"), "-o", str(tmp_path / "plan.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "none.geojson" in err[0] and "Point" in err[0]
    assert not (tmp_path / "plan.json").exists()


def test_vineyard_files_load_in_pymavlink_with_the_acceptance_radius(vineyard, tmp_path):
    """The WPL file of a sortie loads in pymavlink's mavwp with param2 = the acceptance
    radius on every NAV_WAYPOINT and no NaN; the .plan holds no null param."""
    from pymavlink import mavwp

    from companion.plan_io import flight_items, qgc_plan_text, qgc_wpl_text

    mission, plan = vineyard
    items = flight_items(plan, mission, plan.sorties.sorties[0])
    wpl = qgc_wpl_text(items)
    assert "nan" not in wpl.lower()
    (tmp_path / "s.waypoints").write_text(wpl)
    loader = mavwp.MAVWPLoader()
    assert loader.load(str(tmp_path / "s.waypoints")) == len(items.mission) + 1
    wps = [loader.wp(i) for i in range(1, loader.count()) if loader.wp(i).command == 16]
    assert len(wps) == sum(it.command == 16 for it in items.mission)
    assert all(w.param2 == pytest.approx(plan.margins.acceptance_radius_m, abs=1e-6) for w in wps)
    doc = json.loads(qgc_plan_text(items, mission.flight.speed_m_s))
    assert all(v is not None for it in doc["mission"]["items"] for v in it["params"])
