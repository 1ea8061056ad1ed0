"""Map loaders against hand-made tiny files (values worked out by hand)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from mavcore.errors import MapError
from mavcore.maps import ElevationModel, load_dem, load_ogm

ROOT = Path(__file__).resolve().parents[1]


def write_map(tmp_path: Path, pixels, *, fmt="P2", maxval=255, name="map", yaml_extra="",
              negate=0, occ=0.65, free=0.196, origin="[0.0, 0.0, 0.0]", resolution=1.0, mode=None,
              image=None) -> Path:
    """Write ``name``.pgm (image order: first row = north) and ``name``.yaml."""
    px = np.asarray(pixels)
    h, w = px.shape
    img = tmp_path / f"{name}.pgm"
    if fmt == "P2":
        body = "\n".join(" ".join(str(int(v)) for v in row) for row in px)
        img.write_text(f"P2\n# a comment\n{w} {h}\n{maxval}\n{body}\n")
    else:
        dtype = ">u2" if maxval > 255 else "u1"
        img.write_bytes(f"P5\n{w} {h}\n# c\n{maxval}\n".encode() + px.astype(dtype).tobytes())
    lines = [f"image: {image or img.name}", f"resolution: {resolution}", f"origin: {origin}",
             f"negate: {negate}", f"occupied_thresh: {occ}", f"free_thresh: {free}"]
    if mode:
        lines.append(f"mode: {mode}")
    y = tmp_path / f"{name}.yaml"
    y.write_text("\n".join(lines) + "\n" + yaml_extra)
    return y


# 3 columns x 2 rows, one black (occupied) pixel at the top-left, one grey, rest white.
PIX = [[0, 254, 254],
       [254, 205, 254]]


def test_top_left_pixel_is_north_west(tmp_path):
    g = load_ogm(write_map(tmp_path, PIX))
    assert g.shape == (2, 3)
    rows, cols = np.nonzero(g.occupied)
    assert (rows.tolist(), cols.tolist()) == ([1], [0])   # row 1 = north (row 0 is south)
    x, y = g.cell_to_world(rows[0], cols[0])
    # North-west cell of a 3 x 2 m map at origin (0, 0): centre (0.5, 1.5).
    assert (x, y) == pytest.approx((0.5, 1.5))
    # The grey pixel (second image row = south row, middle column) is unknown, not free.
    assert g.unknown[0, 1] and not g.free[0, 1] and not g.occupied[0, 1]
    assert g.free.sum() == 4


def test_origin_and_resolution(tmp_path):
    g = load_ogm(write_map(tmp_path, PIX, origin="[2.0, -3.0, 0.0]", resolution=0.5))
    # Cell [0, 0] spans x 2..2.5, y -3..-2.5.
    assert g.cell_to_world(0, 0) == pytest.approx((2.25, -2.75))
    assert g.world_to_cell(2.25, -2.75) == pytest.approx((0.0, 0.0))
    assert g.resolution_m == 0.5


def test_origin_yaw_rotates_about_lower_left_corner(tmp_path):
    g = load_ogm(write_map(tmp_path, PIX, origin=f"[1.0, 0.0, {math.pi / 2}]"))
    # Cell [row 0, col 1] has grid-frame centre (1.5, 0.5); rotated by +90 deg: (-0.5, 1.5), plus origin.
    assert g.cell_to_world(0, 1) == pytest.approx((0.5, 1.5))
    assert g.world_to_cell(0.5, 1.5) == pytest.approx((0.0, 1.0))


def test_negate_swaps_dark_and_light(tmp_path):
    plain = load_ogm(write_map(tmp_path, PIX, name="a"))
    neg = load_ogm(write_map(tmp_path, PIX, name="b", negate=1))
    # With negate, p = v/255: black (0) is free and white (254) occupied; grey 205 -> p = 0.80 occupied.
    assert np.array_equal(neg.free, plain.occupied)
    assert neg.occupied[0, 1] and neg.occupied.sum() == 5


@pytest.mark.parametrize("value, occ, free, expect", [
    (100, 0.65, 0.196, "unknown"),    # p = 155/255 = 0.608: between the thresholds
    (100, 0.60, 0.196, "occupied"),   # ... above a lower occupied threshold
    (210, 0.65, 0.196, "free"),       # p = 45/255 = 0.176 < 0.196
    (200, 0.65, 0.196, "unknown"),    # p = 55/255 = 0.216
    (200, 0.65, 0.25, "free"),
])
def test_thresholds(tmp_path, value, occ, free, expect):
    g = load_ogm(write_map(tmp_path, [[value]], occ=occ, free=free))
    got = "occupied" if g.occupied[0, 0] else "free" if g.free[0, 0] else "unknown"
    assert got == expect


def test_p2_p5_and_16_bit_agree(tmp_path):
    rng = np.random.default_rng(7)
    px = rng.integers(0, 256, size=(5, 7))
    a = load_ogm(write_map(tmp_path, px, fmt="P2", name="a"))
    b = load_ogm(write_map(tmp_path, px, fmt="P5", name="b"))
    c = load_ogm(write_map(tmp_path, px * 257, fmt="P5", maxval=65535, name="c"))  # same p in 16 bit
    for g in (b, c):
        assert np.array_equal(g.occupied, a.occupied) and np.array_equal(g.free, a.free)
    # Independent classification of the 8-bit pixels, flipped north-up -> south-up.
    p = (255 - px[::-1]) / 255
    assert np.array_equal(a.occupied, p > 0.65) and np.array_equal(a.free, p < 0.196)


def test_modes_scale_and_raw(tmp_path):
    px = [[0, 50, 100, 255, 128]]
    scale = load_ogm(write_map(tmp_path, px, name="s", mode="scale"))
    trin = load_ogm(write_map(tmp_path, px, name="t", mode="trinary"))
    assert np.array_equal(scale.occupied, trin.occupied) and np.array_equal(scale.free, trin.free)
    raw = load_ogm(write_map(tmp_path, px, name="r", mode="raw"))
    # raw: value is percent occupancy; 0 free, 100 occupied, 50 between thresholds, > 100 unknown.
    assert raw.free[0].tolist() == [True, False, False, False, False]
    assert raw.occupied[0].tolist() == [False, False, True, False, False]


def test_relative_image_path_is_relative_to_yaml(tmp_path, monkeypatch):
    sub = tmp_path / "maps"
    (sub / "img").mkdir(parents=True)
    write_map(sub / "img", PIX)
    y = sub / "m.yaml"
    y.write_text("image: img/map.pgm\nresolution: 1.0\norigin: [0, 0, 0]\nnegate: 0\n"
                 "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    monkeypatch.chdir(tmp_path)
    assert load_ogm("maps/m.yaml").occupied.sum() == 1


@pytest.mark.parametrize("case, needle", [
    ("missing_key", "free_thresh"),
    ("resolution", "resolution"),
    ("origin", "origin"),
    ("bad_magic", "not an image"),
    ("truncated_p5", "truncated"),
    ("truncated_p2", "truncated"),
    ("above_maxval", "maxval"),
    ("no_image", "no such file"),
    ("bad_yaml", "line"),
    ("thresholds", "free_thresh"),
    ("mode", "mode"),
    ("header", "header"),
    ("huge_resolution", "reaches"),
    ("huge_origin", "reaches"),
])
def test_malformed_map_names_file_and_problem(tmp_path, case, needle):
    y = write_map(tmp_path, PIX)
    img = tmp_path / "map.pgm"
    text = y.read_text()
    if case == "missing_key":
        y.write_text(text.replace("free_thresh: 0.196\n", ""))
    elif case == "resolution":
        y.write_text(text.replace("resolution: 1.0", "resolution: 0"))
    elif case == "origin":
        y.write_text(text.replace("origin: [0.0, 0.0, 0.0]", "origin: [0.0, 0.0]"))
    elif case == "bad_magic":
        img.write_bytes(b"XX\n3 2\n255\n" + bytes(18))
    elif case == "truncated_p5":
        img.write_bytes(b"P5\n3 2\n255\n" + bytes(5))
    elif case == "truncated_p2":
        img.write_text("P2\n3 2\n255\n0 1 2 3 4\n")
    elif case == "above_maxval":
        img.write_text("P2\n3 2\n100\n0 1 2 3 4 200\n")
    elif case == "no_image":
        img.unlink()
    elif case == "bad_yaml":
        y.write_text(text + "origin: [1, 2\n")
    elif case == "thresholds":
        y.write_text(text.replace("free_thresh: 0.196", "free_thresh: 0.9"))
    elif case == "mode":
        y.write_text(text + "mode: fuzzy\n")
    elif case == "header":
        img.write_bytes(b"P5\n3 x\n255\n" + bytes(6))
    elif case == "huge_resolution":     # YAML 1.1 needs the exponent's sign for a float
        y.write_text(text.replace("resolution: 1.0", "resolution: 1.0e+300"))
    elif case == "huge_origin":
        y.write_text(text.replace("origin: [0.0, 0.0, 0.0]", "origin: [0.0, -2.0e+7, 0.0]"))
    with pytest.raises(MapError) as exc:
        load_ogm(y)
    msg = str(exc.value)
    assert needle in msg
    assert ("map.pgm" in msg) or ("map.yaml" in msg)
    assert "\n" not in msg


# --- DEM ----------------------------------------------------------------------

def write_asc(path: Path, z_north_first, *, ll="corner", x=0.0, y=0.0, cell=2.0, nodata=None, keycase=str.lower):
    z = np.asarray(z_north_first, dtype=float)
    head = [f"{keycase('ncols')} {z.shape[1]}", f"{keycase('nrows')} {z.shape[0]}",
            f"{keycase('xll' + ll)} {x}", f"{keycase('yll' + ll)} {y}", f"{keycase('cellsize')} {cell}"]
    if nodata is not None:
        head.append(f"{keycase('NODATA_value')} {nodata}")
    path.write_text("\n".join(head) + "\n" + "\n".join(" ".join(f"{v:g}" for v in row) for row in z) + "\n")
    return path


def test_dem_first_row_is_north_and_corner_convention(tmp_path):
    # 2 rows x 3 cols, 2 m cells, lower-left corner at (0, 0): centres x 1, 3, 5 and y 1 (south), 3 (north).
    dem = load_dem(write_asc(tmp_path / "d.asc", [[10, 11, 12], [0, 1, 2]]))
    assert dem.heights_m[0].tolist() == [0, 1, 2]    # row 0 = south = last file row
    assert (dem.x0_m, dem.y0_m) == (1.0, 1.0)
    assert dem.height_at(1.0, 3.0) == pytest.approx(10.0)
    assert dem.height_at(3.0, 1.0) == pytest.approx(1.0)
    # Midpoint of four centres = their mean; a quarter of the way = bilinear weights by hand.
    assert dem.height_at(2.0, 2.0) == pytest.approx((0 + 1 + 10 + 11) / 4)
    assert dem.height_at(1.5, 1.5) == pytest.approx(0.75 * 0.75 * 0 + 0.25 * 0.75 * 1 + 0.75 * 0.25 * 10 + 0.25 * 0.25 * 11)


def test_corner_and_center_conventions_shift_by_half_a_cell(tmp_path):
    z = [[4, 3, 7], [1, 5, 2], [0, 8, 6]]
    corner = load_dem(write_asc(tmp_path / "c.asc", z, ll="corner", x=10.0, y=20.0, cell=2.0))
    center = load_dem(write_asc(tmp_path / "m.asc", z, ll="center", x=10.0, y=20.0, cell=2.0))
    rng = np.random.default_rng(3)
    x = rng.uniform(10.0, 14.0, 50)
    y = rng.uniform(20.0, 24.0, 50)
    # The corner file's centres are half a cell (1 m) further north-east.
    assert np.allclose(corner.height_at(x + 1.0, y + 1.0), center.height_at(x, y), atol=1e-12)


def test_header_keys_case_insensitive(tmp_path):
    a = load_dem(write_asc(tmp_path / "a.asc", [[1, 2], [3, 4]], nodata=-9999))
    b = load_dem(write_asc(tmp_path / "b.asc", [[1, 2], [3, 4]], nodata=-9999, keycase=str.upper))
    assert np.array_equal(a.heights_m, b.heights_m) and (a.x0_m, a.y0_m) == (b.x0_m, b.y0_m)


def test_bilinear_is_exact_on_a_plane(tmp_path):
    a, b, c = 0.08, -0.03, 12.5
    cell = 1.5
    xs = 5.0 + cell * (np.arange(9) + 0.5)      # xllcorner 5
    ys = -4.0 + cell * (np.arange(6) + 0.5)
    X, Y = np.meshgrid(xs, ys)
    z_north_first = (a * X + b * Y + c)[::-1]
    dem = load_dem(write_asc(tmp_path / "p.asc", z_north_first, x=5.0, y=-4.0, cell=cell, nodata=-9999))
    rng = np.random.default_rng(11)
    x0, x1, y0, y1 = dem.extent_m
    assert (x0, x1, y0, y1) == pytest.approx((5.0, 5.0 + 9 * cell, -4.0, -4.0 + 6 * cell))
    px = rng.uniform(x0, x1, 200)    # includes the outer half cells
    py = rng.uniform(y0, y1, 200)
    assert np.allclose(dem.height_at(px, py), a * px + b * py + c, atol=1e-9)
    assert dem.covers(px, py).all()
    # Vectorised: shape follows broadcasting.
    assert dem.height_at(px[:4, None], py[None, :3]).shape == (4, 3)


def test_nodata_and_outside(tmp_path):
    z = [[1, 1, 1, 1], [1, 1, 1, -9999], [1, 1, 1, 1]]
    path = write_asc(tmp_path / "hole.asc", z, cell=1.0, nodata=-9999)
    dem = load_dem(path)
    # The NODATA cell is file row 1, col 3 -> grid row 1, col 3, centre (3.5, 1.5).
    assert np.isnan(dem.heights_m[1, 3]) and np.isfinite(dem.heights_m).sum() == 11
    assert dem.height_at(0.5, 0.5) == pytest.approx(1.0)
    # A point whose bilinear patch touches the hole is not covered; one a full cell away is.
    assert dem.covers([3.0, 3.5, 1.5, 2.5], [1.5, 1.5, 1.5, 0.5]).tolist() == [False, False, True, True]
    # Outside the extent (x 0..4, y 0..3).
    assert dem.covers([-0.1, 4.1, 2.0], [1.0, 1.0, 3.2]).tolist() == [False, False, False]
    for x, y in ((3.2, 1.5), (5.0, 1.0)):
        with pytest.raises(MapError) as exc:
            dem.height_at([0.5, x], [0.5, y])
        assert "hole.asc" in str(exc.value)


@pytest.mark.parametrize("text, needle", [
    ("ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\n1 2\n3 4\n", "cellsize"),
    ("ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n3\n", "expected 2 x 2"),
    ("ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n3 x\n", "non-numeric"),
    ("ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 0\n1 2\n3 4\n", "cellsize"),
    ("ncols 2\nnrows 2\nxllcorner 0\nxllcenter 0\nyllcorner 0\ncellsize 1\n1 2\n3 4\n", "xllcorner / xllcenter"),
    ("ncols 2.5\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n3 4\n", "ncols"),
    ("ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\nfoo 3\n1 2\n3 4\n", "line 6"),
    # Magnitudes beyond any terrain / local frame (they overflowed the planner's arithmetic).
    ("ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n3 1e200\n", "height value 1e+200"),
    ("ncols 2\nnrows 2\nxllcorner -1e300\nyllcorner 0\ncellsize 1\n1 2\n3 4\n", "reaches"),
    ("ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1e300\n1 2\n3 4\n", "reaches"),
])
def test_malformed_dem(tmp_path, text, needle):
    p = tmp_path / "bad.asc"
    p.write_text(text)
    with pytest.raises(MapError) as exc:
        load_dem(p)
    assert needle in str(exc.value) and "bad.asc" in str(exc.value)


def test_missing_dem_file(tmp_path):
    with pytest.raises(MapError, match="nope.asc"):
        load_dem(tmp_path / "nope.asc")


def test_elevation_model_in_memory_single_row():
    dem = ElevationModel(heights_m=np.array([[1.0, 3.0]]), x0_m=0.5, y0_m=0.5, cellsize_m=1.0)
    # One row: constant across y, linear along x.
    assert dem.height_at([0.5, 1.0, 1.5], [0.1, 0.5, 0.9]).tolist() == pytest.approx([1.0, 2.0, 3.0])


# --- generator ------------------------------------------------------------------

def _import_generator():
    sys.path.insert(0, str(ROOT / "missions"))
    try:
        import generate
    finally:
        sys.path.pop(0)
    return generate


def test_generator_rows_and_boundary(tmp_path):
    gen = _import_generator()
    spec = gen.flat_rectangle()
    gen.write_mission(spec, tmp_path)
    g = load_ogm(tmp_path / "map.yaml")
    dem = load_dem(tmp_path / "dem.asc")
    # 23 m x 10 m field; rows along x through the centroid (y = 5) and 2.5 m apart: y = 2.5, 5, 7.5
    # (y = 0 and 10 are closer than the 2.5 m headland to the boundary); 0.4 m wide; ends 2.5 m in.
    rows, cols = np.nonzero(g.occupied)
    x, y = g.cell_to_world(rows, cols)
    centres = np.unique(np.round(y / 2.5) * 2.5)
    assert centres.tolist() == [2.5, 5.0, 7.5]
    assert np.abs(y - np.round(y / 2.5) * 2.5).max() <= 0.2
    assert x.min() >= 2.5 - 0.05 and x.max() <= 23.0 - 2.5 + 0.05
    assert rows.size == 3 * 4 * 180       # 3 rows x 4 cells (0.4 m) x 180 cells (18 m)
    # Outside the rectangle is unknown, never free.
    fr, fc = np.nonzero(g.free)
    fx, fy = g.cell_to_world(fr, fc)
    assert fx.min() > 0 and fx.max() < 23 and fy.min() > 0 and fy.max() < 10
    assert g.unknown.any()
    # The centroid of the free cells (the default pointing target) is on the middle vine row.
    assert (fx.mean(), fy.mean()) == pytest.approx((11.5, 5.0))
    # Flat DEM covering the whole image.
    x0, y0 = g.origin_xy_m
    h, w = g.shape
    corners_x = [x0, x0 + w * g.resolution_m]
    corners_y = [y0, y0 + h * g.resolution_m]
    assert np.allclose(dem.height_at(*np.meshgrid(corners_x, corners_y)), 0.0)


def test_generator_is_deterministic_and_bundled_files_match(tmp_path):
    gen = _import_generator()
    for name, make in gen.BUNDLED.items():
        gen.write_mission(make(), tmp_path / name)
        for f in ("map.yaml", "map.pgm", "dem.asc", "mission.yaml"):
            assert (tmp_path / name / f).read_bytes() == (ROOT / "missions" / name / f).read_bytes(), f"{name}/{f}"


def test_generator_tilted_dem_slope(tmp_path):
    gen = _import_generator()
    spec = gen.tilted_hexagon()
    gen.write_mission(spec, tmp_path)
    dem = load_dem(tmp_path / "dem.asc")
    # Plane + undulation of amplitude A: |z - plane| <= A everywhere.
    x0, x1, y0, y1 = dem.extent_m
    X, Y = np.meshgrid(np.linspace(x0, x1, 41), np.linspace(y0, y1, 41))
    resid = dem.height_at(X, Y) - (spec.slope_x * X + spec.slope_y * Y)
    assert np.abs(resid).max() <= spec.undulation_m + 1e-3
    g = load_ogm(tmp_path / "map.yaml")
    rows, cols = np.nonzero(g.occupied)
    x, y = g.cell_to_world(rows, cols)
    a = math.radians(spec.row_angle_deg)
    v = -x * math.sin(a) + y * math.cos(a) - gen.row_offset(spec)   # across rows, from a centreline
    assert np.abs(v - np.round(v / 2.5) * 2.5).max() <= 0.2 + 0.5 * g.resolution_m * math.sqrt(2)
    # The default pointing target (centroid of the free cells) is within a few cm of a vine row,
    # i.e. about half a spacing from the nearest flight lane.
    fr, fc = np.nonzero(g.free)
    cx, cy = g.cell_to_world(fr.mean(), fc.mean())
    vc = -cx * math.sin(a) + cy * math.cos(a) - gen.row_offset(spec)
    assert abs(vc - round(vc / 2.5) * 2.5) < 0.2


def test_height_one_is_height_at_bit_for_bit():
    """The scalar lookup (per-frame truth clearance of the movers) gives the array
    path's number exactly, a plane is reproduced to the last digit of the plane's own
    formula's tolerance, and the array path's errors are kept (outside, NODATA)."""
    rng = np.random.default_rng(5)
    xs, ys = np.meshgrid(np.arange(7) * 0.5 + 0.25, np.arange(5) * 0.5 + 0.25)
    plane = 2.0 + 0.3 * xs - 0.7 * ys                          # a sloped plane on the cell centres
    bumpy = plane + rng.normal(0.0, 0.2, plane.shape)
    for h in (plane, bumpy, np.array([[1.0, 3.0]]), np.array([[4.0], [2.0]])):
        dem = ElevationModel(heights_m=h, x0_m=0.25, y0_m=0.25, cellsize_m=0.5)
        x_min, x_max, y_min, y_max = dem.extent_m
        px = np.concatenate([rng.uniform(x_min, x_max, 400), [x_min, x_max, 0.25, x_max]])
        py = np.concatenate([rng.uniform(y_min, y_max, 400), [y_min, y_max, 0.25, y_min]])
        ref = dem.height_at(px, py)
        one = np.array([dem.height_one(x, y) for x, y in zip(px.tolist(), py.tolist())])
        np.testing.assert_array_equal(one, ref)
    dem = ElevationModel(heights_m=plane, x0_m=0.25, y0_m=0.25, cellsize_m=0.5)
    assert dem.height_one(1.1, 0.9) == pytest.approx(2.0 + 0.3 * 1.1 - 0.7 * 0.9, abs=1e-12)
    with pytest.raises(MapError):
        dem.height_one(-1.0, 0.5)
    holed = plane.copy()
    holed[2, 3] = np.nan
    dem = ElevationModel(heights_m=holed, x0_m=0.25, y0_m=0.25, cellsize_m=0.5)
    with pytest.raises(MapError):
        dem.height_one(1.85, 1.3)                                # a corner is NODATA
    assert dem.height_one(0.4, 0.4) == float(dem.height_at(0.4, 0.4))
