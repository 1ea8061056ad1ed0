"""Issue 18's second round of speed-ups keeps every result exactly: each changed
function against the implementation it replaced (kept here as the reference) or
an independent definition, on random inputs with the edge cases forced."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from companion.coverage.freespace import Raster
from companion.coverage.rows import _sharpness
from mavcore.inputs import json_depth
from companion.plan_io import _dumps


# --- beam sampling: a few lines at a time ----------------------------------------------

def reference_sample_lines(r: Raster, alpha, offsets, t, dtype=np.float32):
    """``Raster.sample_lines`` before issue 18's second round: one whole-array pass."""
    u0, u1 = np.cos(alpha), np.sin(alpha)
    n0, n1 = -u1, u0
    inv = 1.0 / r.cell_m
    ax = ((offsets * n0 - r.x0_m) * inv + 1.0).astype(dtype)
    ay = ((offsets * n1 - r.y0_m) * inv + 1.0).astype(dtype)
    bx, by = (t * (u0 * inv)).astype(dtype), (t * (u1 * inv)).astype(dtype)
    x = ax[:, None] + bx[None, :]
    y = ay[:, None] + by[None, :]
    np.clip(x, 0, r.cols + 1, out=x)
    np.clip(y, 0, r.rows + 1, out=y)
    it = np.int32 if r.flat.size < 2**31 else np.int64
    idx = y.astype(it)
    idx *= r.cols + 2
    idx += x.astype(it)
    return r.flat.take(idx)


def test_sample_lines_in_blocks_equals_one_pass():
    rng = np.random.default_rng(182)
    for shape in ((41, 67), (90, 33), (7, 200)):
        mask = rng.random(shape) < 0.6
        # the mask centred on the G origin, lines from well outside it to well outside it
        r = Raster(mask, 0.1, -0.05 * shape[1] + 0.013, -0.05 * shape[0] - 0.007)
        extent = 0.1 * max(shape)
        for alpha in (0.0, 0.3, np.pi / 2, 1.78, 3.0, rng.uniform(0, np.pi)):
            offsets = np.sort(np.r_[0.0, 0.021, rng.uniform(-0.6 * extent, 0.6 * extent, 21)])
            t = -extent + 0.05 * np.arange(int(2 * extent / 0.05))
            for dtype in (np.float32, np.float64):
                ref = reference_sample_lines(r, alpha, offsets, t, dtype)
                assert ref.any() and not ref.all()
                for block in (None, 1, 3, 4, 23, 100):
                    got = r.sample_lines(alpha, offsets, t, dtype, block=block)
                    np.testing.assert_array_equal(got, ref)
    # every sample of a line inside one cell reads that cell (independent definition)
    mask = np.zeros((5, 5), dtype=bool)
    mask[2, 3] = True
    r = Raster(mask, 1.0, 0.0, 0.0)
    got = r.sample_lines(0.0, np.array([2.5, 1.5]), np.array([0.5, 3.5, 4.5]))
    np.testing.assert_array_equal(got, [[False, True, False], [False, False, False]])


# --- row sharpness: bins numbered within the points' range ------------------------------

def reference_sharpness(pts, alphas, bin_m, tile_m):
    """``rows._sharpness`` before: every point's bin among all ``ntiles * nbins``."""
    n = len(pts)
    radius = float(np.hypot(*(pts.max(axis=0) - pts.min(axis=0)))) + 2 * bin_m
    centre = 0.5 * (pts.max(axis=0) + pts.min(axis=0))
    q = pts - centre
    nbins = int(np.ceil(2 * radius / bin_m)) + 2
    ntiles = int(np.ceil(2 * radius / tile_m)) + 1
    out = np.empty(len(alphas))
    for i, a in enumerate(alphas):
        ca, sa = np.cos(a), np.sin(a)
        t, d = q[:, 0] * ca + q[:, 1] * sa, -q[:, 0] * sa + q[:, 1] * ca
        key = ((t + radius) / tile_m).astype(np.int64) * nbins + ((d + radius) / bin_m).astype(np.int64)
        h = np.bincount(key, minlength=ntiles * nbins)
        out[i] = float(np.dot(h, h)) / (n * n)
    return out


def test_sharpness_equals_all_bins_numbering():
    rng = np.random.default_rng(183)
    # vine rows 2.1 m apart at 20 deg with gaps, plus scattered hits
    t = rng.uniform(0, 80, 3000)
    k = rng.integers(0, 30, 3000)
    a = np.deg2rad(20)
    rows = np.column_stack([t * np.cos(a) - 2.1 * k * np.sin(a), t * np.sin(a) + 2.1 * k * np.cos(a)])
    for pts in (rows + rng.normal(0, 0.05, rows.shape), rng.uniform(-30, 50, (500, 2)), rows[:3]):
        for step_deg in (1.0, 0.1, 0.01):
            cand = np.deg2rad(np.r_[np.arange(0.0, 180.0, 7.3), 20.0 + step_deg * np.arange(-5, 6)])
            tile = 0.2 / np.tan(np.deg2rad(step_deg))
            np.testing.assert_array_equal(_sharpness(pts, cand, 0.2, tile),
                                          reference_sharpness(pts, cand, 0.2, tile))
    # one point per bin: the sharpness is 1/n (definition: sum of squared shares)
    pts = np.column_stack([np.zeros(4), np.arange(4) * 1.0])
    assert _sharpness(pts, np.array([0.0]), 0.2, 50.0)[0] == 1 / 4


# --- plan.json encoding by orjson -------------------------------------------------------

def reference_dumps(value):
    return json.dumps(value, allow_nan=False, separators=(",", ":"))


def test_dumps_writes_the_json_modules_values():
    rng = np.random.default_rng(184)
    floats = (rng.standard_normal(2000) * 10.0 ** rng.integers(-30, 30, 2000)).tolist()
    docs = [
        {"t": floats, "p": rng.standard_normal((50, 3)).tolist(), "corner": [True, False], "n": None},
        {"name": "Côte-d'Or \u2013 parcel", "k": [1, 2**70, -0.0, 5e-324, 1.7976931348623157e308]},
        [np.float64(1.5), {"a": [np.float64(0.25)]}],                  # numpy floats: json's path
        {1: "integer key", "x": (1.0, 2.0)},
        [1e308, 1e308, -1e308],                                         # a sum that overflows is not NaN
        "plain", 3, None, [],
    ]
    for doc in docs:
        assert json.loads(_dumps(doc)) == json.loads(reference_dumps(doc))
    assert json.loads(_dumps(floats)) == floats     # shortest round-trip floats, bit for bit


@pytest.mark.parametrize("bad", [
    [1.0, float("nan")], {"a": [[0.0, float("inf")]]}, {"a": None, "b": [-math.inf]},
    [1e308, 1e308, float("nan")], float("nan"),
])
def test_dumps_refuses_nan_and_infinity(bad):
    with pytest.raises(ValueError):
        reference_dumps(bad)
    with pytest.raises(ValueError):
        _dumps(bad)


# --- JSON depth scan on the structural bytes only ----------------------------------------

def _depth(doc) -> int:
    if isinstance(doc, list):
        return 1 + max((_depth(x) for x in doc), default=0)
    if isinstance(doc, dict):
        return 1 + max((_depth(x) for x in doc.values()), default=0)
    return 0


def test_json_depth_on_texts_without_backslashes():
    rng = np.random.default_rng(185)

    def gen(d):
        if d == 0 or rng.random() < 0.3:
            return ["a[b{", "}]", "\"", 2.5, None, "ok"][int(rng.integers(0, 6))]
        if rng.random() < 0.5:
            return [gen(d - 1) for _ in range(int(rng.integers(0, 4)))]
        return {f"k{i}[": gen(d - 1) for i in range(int(rng.integers(0, 4)))}

    for _ in range(60):
        doc = gen(9)
        text = json.dumps(doc, ensure_ascii=False).replace("\\\"", "'")   # no backslash left
        assert "\\" not in text
        doc = json.loads(text)
        for chunk in (1, 2, 5, 1 << 20):
            assert json_depth(text, chunk) == _depth(doc), text
    # a backslash run carried over a chunk boundary escapes the quote after it
    text = '["a\\\\\\"[[", 1]'
    assert json.loads(text) == ['a\\"[[', 1]
    for chunk in range(1, len(text) + 1):
        assert json_depth(text, chunk) == 1


# --- the trajectory package loads the LQR solver on first use -------------------------

def test_mission_loading_does_not_import_the_lqr_solver():
    code = ("import sys; import mavcore.mission; import companion.commands.fly; import companion.plan_io; "
            "import companion.preflight, companion.trajectory.cursor, companion.trajectory.sampling; "
            "assert 'companion.trajectory.lqr' not in sys.modules, 'lqr'; "
            "assert 'scipy.linalg' not in sys.modules, 'scipy.linalg'; "
            "from companion.trajectory import generate_trajectory, Trajectory; "
            "from mavcore.mission.trajectory import TrajectoryConfig; "
            "import companion.trajectory as T; assert T.generate_trajectory.__module__ == 'companion.trajectory.lqr'; "
            "assert 'generate_trajectory' in dir(T)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    with pytest.raises(AttributeError):
        import companion.trajectory as T
        T.no_such_name


def test_flying_a_plan_does_not_import_scipy(tmp_path):
    """``companion fly --plan`` of a 2.x plan: the stored pieces, no LQR solve, no scipy."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    mission = root / "missions" / "flat-rectangle" / "mission.yaml"
    plan = tmp_path / "plan.json"
    subprocess.run([sys.executable, "-m", "companion", "plan", str(mission), "-o", str(plan)],
                   check=True, capture_output=True, timeout=120)
    code = ("import sys; from mavcore.mission import load_mission; from companion.commands.fly import prepare; "
            "fp = prepare(load_mission(sys.argv[1]), sys.argv[2]); fp.trajectory.sample(fp.trajectory.t0); "
            "bad = sorted(m for m in sys.modules if m.startswith('scipy') or m == 'companion.trajectory.lqr'); "
            "assert not bad, bad")
    proc = subprocess.run([sys.executable, "-c", code, str(mission), str(plan)], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr


# --- sorties: corner way-points found without a k-d tree ---------------------------------

def test_corner_indices_match_a_nearest_neighbour_query():
    from scipy.spatial import cKDTree

    from companion.coverage.waypoints import Waypoints
    from companion.sorties import _corner_indices

    rng = np.random.default_rng(186)
    n = 400
    p = np.column_stack([np.repeat(rng.uniform(0, 50, n // 4), 4), rng.uniform(0, 50, n), np.full(n, 2.0)])
    corner = rng.random(n) < 0.4
    w = Waypoints(t_s=np.arange(n, dtype=float), p_enu_m=p, v_enu_m_s=np.zeros((n, 3)),
                  a_enu_m_s2=np.zeros((n, 3)), corner=corner)
    cs = p[corner, :2]
    # corners exactly, corners moved by less and by more than the 1 um tolerance, other points
    q = np.vstack([cs, cs + [4e-7, -5e-7], cs + [0.0, 2e-6], p[~corner, :2], rng.uniform(0, 50, (50, 2))])
    idx = np.flatnonzero(corner)
    d, j = cKDTree(cs).query(q)
    want = np.where(d < 1e-6, idx[j], -1)
    got = _corner_indices(w, q)
    np.testing.assert_array_equal(got, want)
    assert (got[: len(cs)] == idx).all() and (got[2 * len(cs): 3 * len(cs)] == -1).all()


# --- SITL: the squared clearance capped in uint16, built a band of rows at a time --------

def open_field_grid():
    """Rows every 8 cells at both ends of a 800 x 60 grid at 5 cm, 700 empty rows between:
    cells up to 350 cells from any row, so the middle is beyond the uint16 cap (256 cells)."""
    from mavcore.maps.grid import OccupancyGrid

    occ = np.zeros((800, 60), dtype=bool)
    occ[2:50:8, 5:55] = True
    occ[752:798:8, 5:55] = True
    return OccupancyGrid(occ, ~occ, 0.05, (1.0, -2.0), 0.3)


@pytest.mark.parametrize("band_cells", [60 * 40, 1 << 20])
def test_capped_clearance_is_the_exact_one_below_the_cap(monkeypatch, band_cells):
    from mavcore import geometry
    from mavcore.geometry import CLEARANCE_SQ_CAP, clearance_sq_cells, clearance_sq_cells_capped

    monkeypatch.setattr(geometry, "_ROWS_CELLS", band_cells)       # 40-row bands: windows cut the field
    rng = np.random.default_rng(187)
    posts = rng.random((300, 60)) < 0.002
    for occ in (open_field_grid().occupied, posts, np.zeros((40, 30), dtype=bool) | (np.arange(30) == 29)):
        got = clearance_sq_cells_capped(occ)
        want = np.minimum(clearance_sq_cells(occ), CLEARANCE_SQ_CAP)
        assert got.dtype == np.uint16
        np.testing.assert_array_equal(got, want)
    assert (clearance_sq_cells_capped(open_field_grid().occupied) == CLEARANCE_SQ_CAP).sum() > 5_000


def test_sitl_rays_through_capped_cells_hit_the_same_rows():
    from test_plan_speed import ReferenceRowField

    from sitl.world import RowField, Terrain

    grid = open_field_grid()
    terrain = Terrain(None)
    new, ref = RowField(grid, terrain, 1.7), ReferenceRowField(grid, terrain, 1.7)
    rng = np.random.default_rng(188)
    ext = 800 * 0.05
    n_hit = n_exact = 0
    for _ in range(800):
        o = np.array([rng.uniform(0.0, 3.0), rng.uniform(-5.0, ext), rng.uniform(0.2, 2.5)])
        o[:2] = grid.origin_xy_m + [[math.cos(0.3), -math.sin(0.3)], [math.sin(0.3), math.cos(0.3)]] @ o[:2]
        d = rng.normal(size=3) * [0.2, 1.0, 0.05]
        d /= np.linalg.norm(d)
        args = (*map(float, o), *map(float, d), 45.0)
        a, b = new.raycast(*args), ref.raycast(*args)
        assert math.isfinite(a) == math.isfinite(b)
        if math.isfinite(a):
            n_hit += 1
            n_exact += a == b
            assert abs(a - b) <= 1e-9, (args, a, b)          # the stated tolerance: rounding of the path
    assert n_hit > 80


def test_collision_bounds_from_the_capped_table():
    from mavcore.geometry import ExtrudedCells

    grid = open_field_grid()
    cells = ExtrudedCells(grid, np.zeros(grid.shape), 1.7)
    edt = ndimage_edt(~grid.occupied)
    b = (np.maximum(edt - math.sqrt(2.0), 0.0) * grid.resolution_m).astype(np.float32)
    old = np.maximum(np.nextafter(b, np.float32(-np.inf)), np.float32(0.0))
    below = edt * edt < 65535
    np.testing.assert_array_equal(cells._bound[below], old[below])       # the old bounds, bit for bit
    assert (cells._bound[~below] <= old[~below]).all() and (~below).sum() > 5_000
    rng = np.random.default_rng(189)
    c, s = math.cos(0.3), math.sin(0.3)
    for _ in range(300):
        u, v, z = rng.uniform(0, 3.0), rng.uniform(0, 40.0), rng.uniform(0.0, 3.0)
        x, y = 1.0 + c * u - s * v, -2.0 + s * u + c * v
        lb = cells.lower_bound_m(x, y, z)
        assert lb <= max(cells.signed_distance_m(x, y, z), 0.0) + 1e-12


def ndimage_edt(mask):
    from scipy import ndimage

    return ndimage.distance_transform_edt(mask)
