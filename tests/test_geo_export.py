"""``companion plan --geojson/--kml``: the map layers in WGS 84, read back and
checked against plan.json (read through ``plan_io.load_plan``), the QGC
export's fence (converted by ``mission_items``, not by the exports) and the
field the mission generator drew (three rows along x at y = 2.5, 5, 7.5 m,
18 m long)."""

from __future__ import annotations

import contextlib
import io
import json
import math
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from mavcore import frames
from companion.cli import main
from companion.plan_io import load_plan

ROOT = Path(__file__).resolve().parents[1]
KML = "{http://www.opengis.net/kml/2.2}"
#: Written degrees have 8 decimals: half a unit of the last place is at most
#: 0.5e-8 deg x (pi / 180) x 6.4e6 m (a radius of curvature of the WGS 84
#: ellipsoid, rounded up) on the ground, plus 1 um for the conversion's own round trip.
TOL_M = 0.5e-8 * math.pi / 180 * 6.4e6 + 1e-6
#: Altitudes have 3 decimals.
TOL_ALT_M = 0.5e-3 + 1e-6
#: The bundled map's cell (m): the rows are found on it.
CELL_M = 0.1


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """flat-rectangle with a 0.9 Ah battery (several sorties), planned once."""
    d = tmp_path_factory.mktemp("geo")
    shutil.copytree(ROOT / "missions" / "flat-rectangle", d / "m")
    mission = d / "m" / "mission.yaml"
    mission.write_text(mission.read_text() + "energy: {battery_capacity_ah: 0.9}\n")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["plan", str(mission), "-o", str(d / "plan.json"), "--qgc", str(d / "p.plan"),
                     "--geojson", str(d / "p.geojson"), "--kml", str(d / "p.kml"),
                     "--html", str(d / "map.html")]) == 0
    plan = load_plan(d / "plan.json")
    assert len(plan.sorties) >= 2, "the test needs several sorties"
    return {"dir": d, "plan": plan, "geojson": json.loads((d / "p.geojson").read_text()),
            "kml": ET.parse(d / "p.kml").getroot()}


def to_enu(lon_lat: np.ndarray, plan, alt=None) -> np.ndarray:
    """(N, 2) (lon, lat) [and altitudes] -> (N, 2|3) ENU through ``frames.geodetic2enu``."""
    lat0, lon0, alt0 = plan.origin
    out = []
    for i, (lon, lat) in enumerate(np.asarray(lon_lat, float)):
        x, y, z = frames.geodetic2enu(lat, lon, alt0 if alt is None else alt[i], lat0, lon0, alt0)
        out.append((x, y) if alt is None else (x, y, z))
    return np.array(out)


def by_kind(doc, kind):
    return [f for f in doc["features"] if f["properties"]["kind"] == kind]


def test_geojson_rfc7946_structure(exported):
    doc, plan = exported["geojson"], exported["plan"]
    assert doc["type"] == "FeatureCollection" and "crs" not in doc     # RFC 7946: WGS 84 only, no crs member
    lat0, lon0, _ = plan.origin
    for f in doc["features"]:
        assert f["type"] == "Feature" and isinstance(f["properties"], dict)
        g = f["geometry"]
        pts = np.asarray(g["coordinates"], float).reshape(-1, 2)
        # longitude first: home is at lat 44.8, lon -0.6, and the field is 23 m across
        assert np.all(np.abs(pts[:, 0] - lon0) < 1e-3) and np.all(np.abs(pts[:, 1] - lat0) < 1e-3), f["properties"]
        if g["type"] == "LineString":
            assert len(g["coordinates"]) >= 2
    fence = by_kind(doc, "fence")
    assert len(fence) == 1 and fence[0]["geometry"]["type"] == "Polygon"
    rings = fence[0]["geometry"]["coordinates"]
    assert len(rings) == 1                                     # no holes
    ring = np.asarray(rings[0], float)
    assert len(ring) >= 4 and np.array_equal(ring[0], ring[-1])   # closed linear ring
    # right-hand rule: the exterior ring is counter-clockwise (positive shoelace area)
    assert np.sum(ring[:-1, 0] * ring[1:, 1] - ring[1:, 0] * ring[:-1, 1]) > 0


def test_geojson_round_trips_to_the_plan(exported):
    doc, plan = exported["geojson"], exported["plan"]
    _, _, alt0 = plan.origin
    (path,) = by_kind(doc, "path")
    xy = to_enu(path["geometry"]["coordinates"], plan)
    assert xy.shape == (len(plan.waypoint_p_enu_m), 2)
    assert np.max(np.abs(xy - plan.waypoint_p_enu_m[:, :2])) <= TOL_M
    assert np.max(np.abs(np.array(path["properties"]["alt_amsl_m"]) - alt0
                         - plan.waypoint_p_enu_m[:, 2])) <= TOL_ALT_M
    sorties = sorted(by_kind(doc, "sortie"), key=lambda f: f["properties"]["index"])
    assert [f["properties"]["index"] for f in sorties] == list(range(1, len(plan.sorties) + 1))
    for f, s in zip(sorties, plan.sorties):
        xy = to_enu(f["geometry"]["coordinates"], plan)
        assert np.max(np.abs(xy - s["waypoint_p_enu_m"][:, :2])) <= TOL_M
    assert len({f["properties"]["colour"] for f in sorties}) == len(sorties)     # distinct colours
    (launch,) = by_kind(doc, "launch")
    assert launch["geometry"]["type"] == "Point"
    xy = to_enu([launch["geometry"]["coordinates"]], plan)[0]
    assert np.max(np.abs(xy - np.asarray(plan.data["launch_enu_m"]))) <= TOL_M
    # every sortie starts and ends over the launch point
    for s in plan.sorties:
        assert np.max(np.abs(s["waypoint_p_enu_m"][[0, -1], :2] - xy)) <= TOL_M


def test_fence_matches_the_qgc_export(exported):
    """The fence is the QGC .plan's (converted there by mission_items, not here)."""
    (fence,) = by_kind(exported["geojson"], "fence")
    ring = np.asarray(fence["geometry"]["coordinates"][0], float)[:-1]       # (lon, lat), open
    qgc = json.loads((exported["dir"] / "p-sortie1.plan").read_text())
    poly = np.asarray(qgc["geoFence"]["polygons"][0]["polygon"], float)[:, ::-1]   # (lat, lon) -> (lon, lat)
    assert len(ring) == len(poly)
    tol_deg = 1e-8      # both written to at least 8 decimals
    for v in poly:
        assert np.min(np.max(np.abs(ring - v), axis=1)) <= tol_deg


def test_rows_are_the_drawn_rows(exported):
    doc, plan = exported["geojson"], exported["plan"]
    rows = sorted(by_kind(doc, "row"), key=lambda f: f["properties"]["index"])
    assert len(rows) == 3
    ends = np.array([to_enu(f["geometry"]["coordinates"], plan) for f in rows])    # (3, 2, 2)
    ys = np.sort(ends[:, :, 1].mean(axis=1))
    np.testing.assert_allclose(ys, [2.5, 5.0, 7.5], atol=CELL_M)
    np.testing.assert_allclose(np.abs(ends[:, 1, 0] - ends[:, 0, 0]), 18.0, atol=2 * CELL_M)
    np.testing.assert_allclose(ends[:, 0, 1], ends[:, 1, 1], atol=CELL_M)      # along x (east)


def kml_folder(root, name):
    for f in root.iter(f"{KML}Folder"):
        if f.findtext(f"{KML}name") == name:
            return f
    raise AssertionError(f"no KML folder {name!r}")


def kml_coords(el) -> np.ndarray:
    text = el.find(f".//{KML}coordinates").text
    return np.array([[float(c) for c in tok.split(",")] for tok in text.split()])


def test_kml_round_trips_to_the_plan(exported):
    root, plan = exported["kml"], exported["plan"]
    assert root.tag == f"{KML}kml"
    (pm,) = kml_folder(root, "path").findall(f"{KML}Placemark")
    c = kml_coords(pm)
    p = to_enu(c[:, :2], plan, alt=c[:, 2])
    assert np.max(np.abs(p[:, :2] - plan.waypoint_p_enu_m[:, :2])) <= TOL_M
    assert np.max(np.abs(p[:, 2] - plan.waypoint_p_enu_m[:, 2])) <= TOL_ALT_M
    assert pm.findtext(f".//{KML}altitudeMode") == "absolute"
    pms = kml_folder(root, "sorties").findall(f"{KML}Placemark")
    assert len(pms) == len(plan.sorties)
    for pm, s in zip(pms, plan.sorties):
        c = kml_coords(pm)
        p = to_enu(c[:, :2], plan, alt=c[:, 2])
        assert np.max(np.abs(p - s["waypoint_p_enu_m"])) <= max(TOL_M, TOL_ALT_M)
    (pm,) = kml_folder(root, "launch").findall(f"{KML}Placemark")
    xy = to_enu(kml_coords(pm)[:, :2], plan)[0]
    assert np.max(np.abs(xy - np.asarray(plan.data["launch_enu_m"]))) <= TOL_M
    (pm,) = kml_folder(root, "fence").findall(f"{KML}Placemark")
    ring = kml_coords(pm.find(f".//{KML}outerBoundaryIs"))
    assert len(ring) >= 4 and np.array_equal(ring[0], ring[-1])
    assert len(kml_folder(root, "rows").findall(f"{KML}Placemark")) == 3


def test_exports_use_the_projects_geodesy(monkeypatch):
    """The exports go through ``frames.enu2geodetic`` by name (whatever it becomes)."""
    from companion.geo_export import geojson_dict
    from companion.map_layers import MapLayers

    monkeypatch.setattr(frames, "enu2geodetic", lambda x, y, z, lat0, lon0, alt0: (y / 10, x / 10, z + 100))
    layers = MapLayers("t", (0.0, 0.0, 0.0), np.array([[10.0, 20.0, 1.0], [30.0, 40.0, 2.0]]))
    (path,) = geojson_dict(layers)["features"]
    assert path["geometry"]["coordinates"] == [[1.0, 2.0], [3.0, 4.0]]      # [lon, lat] = [x/10, y/10]
    assert path["properties"]["alt_amsl_m"] == [101.0, 102.0]


def test_clockwise_ring_is_reversed():
    from companion.geo_export import _ccw_closed

    cw = [[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]]        # clockwise square (lon, lat)
    assert _ccw_closed(cw) == [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]]


def test_unwritable_export_one_line_nothing_written(capsys, tmp_path):
    mission = ROOT / "missions" / "flat-rectangle" / "mission.yaml"
    rc = main(["plan", str(mission), "-o", str(tmp_path / "plan.json"), "--kml", str(tmp_path / "no" / "p.kml")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "p.kml" in err[0] and "does not exist" in err[0]
    assert list(tmp_path.iterdir()) == []
