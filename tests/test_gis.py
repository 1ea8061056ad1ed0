"""Maps and DEMs as GIS users have them: GeoTIFF and GDAL ASCII DEMs in projected CRSs
(UTM 31N, Lambert-93) reprojected to ENU about home, a field as GeoJSON or KML, the home
heading, GDAL's dx/dy header; and their bad inputs as one-line errors.

Expected heights are computed independently: the ENU point -> WGS-84 (mavcore.frames)
-> the DEM's CRS (pyproj) -> the analytic surface the test wrote into the file.
These tests need the ``gis`` extra (installed by .ci/run and the README's test line).
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import pyproj
import rasterio
from rasterio.transform import from_origin

from companion.cli import main
from mavcore.errors import MapError
from mavcore.frames import enu2geodetic, geodetic2enu
from mavcore.maps import load_dem
from mavcore.maps.field import load_field, load_mission_maps
from mavcore.maps.gis import load_geo_dem
from mavcore.mission import load_mission

ROOT = Path(__file__).resolve().parents[1]
HOME = (44.80, 2.50, 30.0)          # in UTM zone 31N (0..6 deg E) and in Lambert-93's area


def plane(e, n, e0, n0):
    """The test surface in projected metres: 35 m AMSL + 3 % east, -2 % north."""
    return 35.0 + 0.03 * (e - e0) - 0.02 * (n - n0)


def write_geotiff(path: Path, crs: str, cell: float = 1.0, size=(80, 60), nodata_at=None, driver="GTiff",
                  with_crs=True):
    """A DEM around HOME in ``crs``: the plane sampled at pixel centres; returns (e0, n0)."""
    to = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    e0, n0 = to.transform(HOME[1], HOME[0])
    w, h = size
    left, top = e0 - 10.0, n0 + 30.0
    e = left + (np.arange(w) + 0.5) * cell
    n = top - (np.arange(h) + 0.5) * cell
    E, N = np.meshgrid(e, n)
    z = plane(E, N, e0, n0).astype("float32")
    if nodata_at is not None:
        z[nodata_at] = -9999.0
    kw = dict(driver=driver, height=h, width=w, count=1, dtype="float32", transform=from_origin(left, top, cell, cell),
              nodata=-9999.0)
    if with_crs:
        kw["crs"] = crs
    with rasterio.open(path, "w", **kw) as ds:
        ds.write(z, 1)
    return e0, n0


def expected_z(x, y, crs, e0, n0):
    lat, lon, _ = enu2geodetic(x, y, 0.0, *HOME)
    e, n = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True).transform(lon, lat)
    return plane(e, n, e0, n0) - HOME[2]


@pytest.mark.parametrize("crs", ["EPSG:32631", "EPSG:2154"])
def test_geotiff_reprojected_to_enu(tmp_path, crs):
    e0, n0 = write_geotiff(tmp_path / "dem.tif", crs, nodata_at=(slice(40, 45), slice(60, 65)))
    dem = load_geo_dem(tmp_path / "dem.tif", HOME)
    rng = np.random.default_rng(1)
    pts = rng.uniform([-5, -25], [45, 25], size=(40, 2))
    for x, y in pts:
        if dem.covers(x, y):
            assert float(dem.height_at(x, y)) == pytest.approx(expected_z(x, y, crs, e0, n0), abs=0.005)
    # a NODATA hole is not covered where it was written: pixel rows 40..44, cols 60..64
    to_wgs = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    lon, lat = to_wgs.transform(e0 - 10.0 + 62.5, n0 + 30.0 - 42.5)
    hx, hy, _ = geodetic2enu(lat, lon, 0.0, *HOME)
    assert not dem.covers(hx, hy)


def test_gdal_ascii_with_a_prj_and_the_dx_dy_header(tmp_path):
    e0, n0 = write_geotiff(tmp_path / "dem.asc", "EPSG:32631", driver="AAIGrid")
    assert (tmp_path / "dem.prj").exists()
    m = (ROOT / "missions" / "flat-rectangle" / "mission.yaml").read_text()
    (tmp_path / "mission.yaml").write_text(m)
    for f in ("map.yaml", "map.pgm"):
        shutil.copy(ROOT / "missions" / "flat-rectangle" / f, tmp_path / f)
    text = m.replace("home: {lat: 44.8, lon: -0.6, alt_m: 30.0}", f"home: {{lat: {HOME[0]}, lon: {HOME[1]}, alt_m: {HOME[2]}}}")
    (tmp_path / "mission.yaml").write_text(text)
    _, dem = load_mission_maps(load_mission(tmp_path / "mission.yaml"))
    for x, y in ((3.0, 4.0), (20.0, 8.0)):
        assert float(dem.height_at(x, y)) == pytest.approx(expected_z(x, y, "EPSG:32631", e0, n0), abs=0.005)
    # GDAL's rectangular-cell header, local frame: a plane is reproduced exactly
    z = np.array([[0.1 * (1 + 2 * j) + 0.2 * (0.5 + i) for j in range(4)] for i in range(3)])[::-1]
    (tmp_path / "r.asc").write_text("ncols 4\nnrows 3\nxllcorner 0\nyllcorner 0\ndx 2\ndy 1\n"
                                    + "\n".join(" ".join(f"{v:.6f}" for v in row) for row in z) + "\n")
    r = load_dem(tmp_path / "r.asc")
    assert r.cellsize_m == 1.0
    for x, y in ((3.3, 1.7), (1.0, 0.5), (6.9, 2.4)):
        assert float(r.height_at(x, y)) == pytest.approx(0.1 * x + 0.2 * y, abs=1e-9)


def _geo_mission(tmp_path: Path, dem_line: str) -> Path:
    d = tmp_path / "geo"
    shutil.copytree(ROOT / "missions" / "tilted-hexagon", d)
    text = (d / "mission.yaml").read_text()
    text = text.replace("dem: dem.asc", dem_line)
    import re
    text = re.sub(r"home: \{[^}]*\}", f"home: {{lat: {HOME[0]}, lon: {HOME[1]}, alt_m: {HOME[2]}}}", text)
    (d / "mission.yaml").write_text(text)
    return d / "mission.yaml"


def test_plan_on_a_geotiff_exports_amsl_dem_plus_agl(tmp_path):
    """The exported way-points' AMSL altitude is the GeoTIFF's height at their
    latitude/longitude (through pyproj, independently) plus the flight height, +-5 cm."""
    m = _geo_mission(tmp_path, "dem: dem.tif")
    e0, n0 = write_geotiff(m.parent / "dem.tif", "EPSG:32631", size=(80, 80))
    out = tmp_path / "o"
    out.mkdir()
    assert main(["plan", str(m), "-o", str(out / "p.json"), "--qgc", str(out / "p.plan")]) == 0
    items = json.loads((out / "p.plan").read_text())["mission"]["items"]
    to = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:32631", always_xy=True)
    agl = load_mission(m).flight.height_agl_m
    n = 0
    for it in items:
        if it["command"] == 16:
            lat, lon, alt = it["params"][4:7]
            e, nn = to.transform(lon, lat)
            assert alt == pytest.approx(plane(e, nn, e0, n0) + agl, abs=0.05)
            n += 1
    assert n > 10


@pytest.mark.parametrize("case, needle", [
    ("corrupt", "cannot read as a raster"),
    ("no_crs", "no coordinate reference system"),
    ("bad_crs", "unusable CRS"),
    ("engineering_crs", "cannot transform"),
])
def test_bad_georeferenced_dems_are_one_line_errors(tmp_path, capsys, case, needle):
    if case == "corrupt":
        m = _geo_mission(tmp_path, "dem: dem.tif")
        (m.parent / "dem.tif").write_bytes(b"II*\x00" + bytes(range(256)) * 4)
    elif case == "no_crs":
        m = _geo_mission(tmp_path, "dem: dem.tif")
        write_geotiff(m.parent / "dem.tif", "EPSG:32631", with_crs=False)
    elif case == "bad_crs":
        m = _geo_mission(tmp_path, "dem: dem.tif\ndem_crs: 'EPSG:999999'")
        write_geotiff(m.parent / "dem.tif", "EPSG:32631", with_crs=False)
    else:
        m = _geo_mission(tmp_path, "dem: dem.tif\ndem_crs: 'ENGCRS[\"site\",EDATUM[\"d\"],CS[Cartesian,2],"
                                   "AXIS[\"x\",east,LENGTHUNIT[\"metre\",1]],AXIS[\"y\",north,LENGTHUNIT[\"metre\",1]]]'")
        write_geotiff(m.parent / "dem.tif", "EPSG:32631", with_crs=False)
    out = tmp_path / "o"
    out.mkdir()
    rc = main(["plan", str(m), "-o", str(out / "p.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "dem.tif" in err[0] and needle in err[0], err
    assert list(out.iterdir()) == []


# --- fields as vectors --------------------------------------------------------

def _lonlat(x, y):
    lat, lon, _ = enu2geodetic(x, y, 0.0, *HOME)
    return [lon, lat]


def field_geojson(path: Path, with_boundary=True):
    """A 40 m x 20 m field (ENU x 0..40, y 0..20) with a 6 m x 4 m shed at x 17..23, y 8..12
    and rows along x every 2.5 m (y = 2.5 .. 17.5) from x = 4 to 36."""
    ring = [_lonlat(x, y) for x, y in ((0, 0), (40, 0), (40, 20), (0, 20), (0, 0))]
    shed = [_lonlat(x, y) for x, y in ((17, 8), (23, 8), (23, 12), (17, 12), (17, 8))]
    feats = []
    if with_boundary:
        feats.append({"type": "Feature", "properties": {"role": "boundary"},
                      "geometry": {"type": "Polygon", "coordinates": [ring]}})
        feats.append({"type": "Feature", "properties": {"role": "exclusion"},
                      "geometry": {"type": "Polygon", "coordinates": [shed]}})
    for k in range(1, 8):
        y = 2.5 * k
        feats.append({"type": "Feature", "properties": {"role": "row"},
                      "geometry": {"type": "LineString", "coordinates": [_lonlat(4, y), _lonlat(36, y)]}})
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))


def field_kml(path: Path):
    def coords(pts):
        return " ".join(f"{lo:.10f},{la:.10f},0" for lo, la in pts)
    ring = [_lonlat(x, y) for x, y in ((0, 0), (40, 0), (40, 20), (0, 20), (0, 0))]
    shed = [_lonlat(x, y) for x, y in ((17, 8), (23, 8), (23, 12), (17, 12), (17, 8))]
    rows = "".join(f"<Placemark><name>row {k}</name><LineString><coordinates>{coords([_lonlat(4, 2.5 * k), _lonlat(36, 2.5 * k)])}"
                   f"</coordinates></LineString></Placemark>" for k in range(1, 8))
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?><kml xmlns="http://www.opengis.net/kml/2.2"><Document>'
        f"<Placemark><name>boundary</name><Polygon><outerBoundaryIs><LinearRing><coordinates>{coords(ring)}"
        "</coordinates></LinearRing></outerBoundaryIs></Polygon></Placemark>"
        f"<Placemark><name>shed</name><Polygon><outerBoundaryIs><LinearRing><coordinates>{coords(shed)}"
        "</coordinates></LinearRing></outerBoundaryIs></Polygon></Placemark>" + rows + "</Document></kml>")


def test_geojson_and_kml_fields_rasterise_alike_and_as_drawn(tmp_path):
    field_geojson(tmp_path / "f.geojson")
    field_kml(tmp_path / "f.kml")
    a = load_field(tmp_path / "f.geojson", HOME, 0.1, 0.4)
    b = load_field(tmp_path / "f.kml", HOME, 0.1, 0.4)
    assert np.array_equal(a.free, b.free) and np.array_equal(a.occupied, b.occupied)

    def cls(x, y):
        r, c = (int(round(v)) for v in a.world_to_cell(x, y))
        return "o" if a.occupied[r, c] else "f" if a.free[r, c] else "u"

    assert cls(2.0, 1.25) == "f"            # headland
    assert cls(20.0, 10.0) == "o"           # the shed
    assert cls(10.0, 5.0) == "o"            # on the row y = 5
    assert cls(10.0, 6.25) == "f"           # between rows
    assert cls(-1.0, 10.0) == "u"           # outside the boundary
    assert cls(41.0, 10.0) == "u"
    # free area: 800 m^2 minus the shed (24) minus 7 rows 32 m x 0.4 m, less where a row
    # crosses the shed (the row y = 10 inside x 17..23: 6 m x 0.4 m counted once)
    expect = 800 - 24 - 7 * 32 * 0.4 + 6 * 0.4
    assert a.free.sum() * 0.01 == pytest.approx(expect, rel=0.02)


def test_field_mission_plans_and_flies_between_the_rows(tmp_path, capsys):
    field_geojson(tmp_path / "f.geojson")
    src = (ROOT / "missions" / "flat-rectangle" / "mission.yaml").read_text()
    import re
    text = src.replace("map: map.yaml", "field: {file: f.geojson, resolution_m: 0.1}")
    text = re.sub(r"home: \{[^}]*\}", f"home: {{lat: {HOME[0]}, lon: {HOME[1]}, alt_m: {HOME[2]}}}", text)
    (tmp_path / "mission.yaml").write_text(text)
    (tmp_path / "dem.asc").write_text("ncols 3\nnrows 3\nxllcorner -10\nyllcorner -10\ncellsize 30\n" + "0 0 0\n" * 3)
    assert main(["plan", str(tmp_path / "mission.yaml"), "-o", str(tmp_path / "p.json")]) == 0
    doc = json.loads((tmp_path / "p.json").read_text())
    path = np.array(doc["path"])
    # lanes between the rows: at y = 1.25 + 2.5 k; the shed's lane is split around it
    ys = np.unique(np.round(path[:, 1], 1))
    for k in range(0, 8):
        assert np.any(np.abs(ys - (1.25 + 2.5 * k)) < 0.15)
    # the path keeps the safety margin from the shed (the rectangle x 17..23, y 8..12)
    dense = np.vstack([np.linspace(p, q, 200) for p, q in zip(path[:-1], path[1:])])
    dx = np.maximum(np.maximum(17.0 - dense[:, 0], dense[:, 0] - 23.0), 0.0)
    dy = np.maximum(np.maximum(8.0 - dense[:, 1], dense[:, 1] - 12.0), 0.0)
    margin = load_mission(tmp_path / "mission.yaml").coverage.safety_margin_m
    assert np.hypot(dx, dy).min() >= margin - 0.1


@pytest.mark.parametrize("content, needle", [
    ({"type": "FeatureCollection", "features": [
        {"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[2.5, 44.8], [2.6, 44.8]]}}]},
     "no polygon"),
    ({"type": "Polygon", "coordinates": [[[500000, 4960000], [500100, 4960000], [500100, 4960100], [500000, 4960000]]]},
     "not WGS-84"),
    ("{", "not valid JSON"),
])
def test_bad_fields_are_one_line_errors(tmp_path, capsys, content, needle):
    (tmp_path / "f.geojson").write_text(content if isinstance(content, str) else json.dumps(content))
    src = (ROOT / "missions" / "flat-rectangle" / "mission.yaml").read_text()
    (tmp_path / "mission.yaml").write_text(src.replace("map: map.yaml", "field: {file: f.geojson}"))
    shutil.copy(ROOT / "missions" / "flat-rectangle" / "dem.asc", tmp_path / "dem.asc")
    rc = main(["plan", str(tmp_path / "mission.yaml"), "-o", str(tmp_path / "p.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "f.geojson" in err[0] and needle in err[0], err
    assert not (tmp_path / "p.json").exists()
    with pytest.raises(MapError):
        load_field(tmp_path / "f.geojson", HOME, 0.1, 0.4)


def test_home_heading_rotates_local_maps_into_enu(tmp_path):
    """heading_deg 0: the local files' x axis points north. A local point (x, y) is then
    ENU (-y, x): the flat rectangle's occupied cells and the DEM rotate together."""
    d = tmp_path / "m"
    shutil.copytree(ROOT / "missions" / "tilted-hexagon", d)
    text = (d / "mission.yaml").read_text().replace("alt_m: 45.0}", "alt_m: 45.0, heading_deg: 0.0}")
    assert "heading_deg" in text
    (d / "mission.yaml").write_text(text)
    plain = load_mission_maps(load_mission(ROOT / "missions" / "tilted-hexagon" / "mission.yaml"))
    rot = load_mission_maps(load_mission(d / "mission.yaml"))
    for (x, y) in ((5.0, 3.0), (10.0, 12.0), (-2.0, 7.0)):
        # the DEM: the height at local (x, y) is found at ENU (-y, x)
        if plain[1].covers(x, y) and rot[1].covers(-y, x):
            assert float(rot[1].height_at(-y, x)) == pytest.approx(float(plain[1].height_at(x, y)), abs=1e-6)
        r0, c0 = (int(round(v)) for v in plain[0].world_to_cell(x, y))
        r1, c1 = (int(round(v)) for v in rot[0].world_to_cell(-y, x))
        assert (r0, c0) == (r1, c1)
    assert math.isclose(rot[0].origin_yaw_rad, plain[0].origin_yaw_rad + math.pi / 2)


def test_utm_asc_without_a_crs_is_named_before_planning(tmp_path, capsys):
    """A UTM-referenced ASCII grid without .prj or dem_crs is read as local metres: it
    lies half a million metres away from the map; said up front, with the remedy."""
    m = _geo_mission(tmp_path, "dem: dem.asc")
    (m.parent / "dem.asc").write_text("ncols 3\nnrows 3\nxllcorner 500000\nyllcorner 4960000\ncellsize 50\n"
                                      + "35 35 35\n" * 3)
    rc = main(["plan", str(m), "-o", str(tmp_path / "p.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "dem.asc" in err[0] and "does not overlap" in err[0] and "dem_crs" in err[0]
