"""Issue 18 speed-ups keep their results exactly: each optimised function against
the straightforward implementation it replaced, kept here as the reference, on
several fields (random masks and images, chunk boundaries forced small)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from companion.coverage import blockgraph
from companion.coverage.blockgraph import block_size, build_block_graph
from mavcore.maps import ogm
from mavcore.maps.ogm import Shades, classify


# --- block graph: labels held per block -------------------------------------------------

def reference_labels(eroded, bbox):
    """The sub-component id of every window cell as one ``ndimage.label`` over the
    whole stack of blocks numbers them (the implementation before issue 18)."""
    r0, r1, c0, c1 = bbox
    win = eroded[r0:r1, c0:c1]
    f = block_size(win.size)
    nbr, nbc = -(-win.shape[0] // f), -(-win.shape[1] // f)
    padded = np.zeros((nbr * f, nbc * f), dtype=bool)
    padded[: win.shape[0], : win.shape[1]] = win
    stack = padded.reshape(nbr, f, nbc, f).transpose(0, 2, 1, 3).reshape(nbr * nbc, f, f)
    structure = np.zeros((3, 3, 3), dtype=bool)
    structure[1] = True
    lab, k = ndimage.label(stack, structure=structure)
    B = lab.reshape(nbr, nbc, f, f)
    grid_ids = B.transpose(0, 2, 1, 3).reshape(nbr * f, nbc * f)[: win.shape[0], : win.shape[1]]
    return grid_ids, k, f


def reference_edges(grid_ids):
    """Undirected pairs of different ids that hold 8-adjacent cells (brute force over the grid)."""
    pairs = set()
    g = np.pad(grid_ids, 1)
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = g[1:-1, 1:-1]
        b = g[1 + dr: g.shape[0] - 1 + dr, 1 + dc: g.shape[1] - 1 + dc]
        m = (a > 0) & (b > 0) & (a != b)
        pairs |= {(int(min(x, y)), int(max(x, y))) for x, y in zip(a[m], b[m])}
    return pairs


def random_fields():
    rng = np.random.default_rng(18)
    out = []
    for shape, p in (((97, 131), 0.55), ((64, 64), 0.35), ((150, 90), 0.8), ((33, 257), 0.5)):
        mask = ndimage.binary_opening(rng.random(shape) < p) | (rng.random(shape) < 0.05)
        out.append(mask)
    vine = np.ones((120, 140), dtype=bool)
    vine[::5] = False                         # rows every 5 cells, cut by a track
    vine[:, 60:63] = True
    out.append(vine)
    return out


@pytest.mark.parametrize("label_cells", [blockgraph._LABEL_CELLS, 64 * 3, 64])
@pytest.mark.parametrize("field", range(5))
def test_block_graph_ids_edges_and_components_match_the_whole_stack_labelling(monkeypatch, field, label_cells):
    monkeypatch.setattr(blockgraph, "_LABEL_CELLS", label_cells)       # 1 or 3 blocks a call
    mask = random_fields()[field]
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    bbox = (int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1)
    bg = build_block_graph(mask, bbox)
    ref, k, f = reference_labels(mask, bbox)
    assert bg.block == f and bg.graph.shape == (k + 1, k + 1)
    rr, cc = np.indices(ref.shape)
    got = np.array([bg.sub_at(r + bbox[0], c + bbox[2]) for r, c in zip(rr.ravel(), cc.ravel())]).reshape(ref.shape)
    np.testing.assert_array_equal(got, ref)
    # the graph's edges are exactly the 8-adjacent pairs of different sub-components
    coo = bg.graph.tocoo()
    assert {(int(u), int(v)) for u, v in zip(coo.row, coo.col) if u < v} == reference_edges(ref)
    # components: two sub-components share one exactly when their cells are 8-connected
    fine, _ = ndimage.label(mask[bbox[0]:bbox[1], bbox[2]:bbox[3]], structure=np.ones((3, 3), bool))
    comp = bg.components_of(rr.ravel() + bbox[0], cc.ravel() + bbox[2]).reshape(ref.shape)
    assert np.all((comp >= 0) == (ref > 0))
    for lab in range(1, fine.max() + 1):
        assert len(np.unique(comp[fine == lab])) == 1
    assert len(np.unique(comp[ref > 0])) == fine.max()
    # cells_of gives back exactly the cells of the asked sub-components
    subs = np.unique(ref[ref > 0])[::3]
    r, c = bg.cells_of(subs)
    want = np.isin(ref, subs)
    assert sorted(zip(r.tolist(), c.tolist())) == sorted(zip((rr[want] + bbox[0]).tolist(),
                                                              (cc[want] + bbox[2]).tolist()))
    # block_of: the block that holds each sub-component's cells
    for s in subs:
        i, j = np.argwhere(ref == s)[0]
        assert tuple(bg.block_of[s]) == (i // f, j // f)


def test_block_labels_take_one_byte_a_cell_for_small_blocks():
    """At most ceil(f/2)^2 pieces fit in an f x f block (one per 2 x 2 tile): a
    checkerboard of isolated cells reaches it, and the local numbers fit one byte."""
    mask = np.zeros((200, 200), dtype=bool)
    mask[::2, ::2] = True
    bg = build_block_graph(mask, (0, 200, 0, 200))
    f = bg.block
    assert bg.local.dtype == np.uint8
    assert int(bg.local.max()) == ((f + 1) // 2) ** 2


# --- map classification: table looked up in bounded chunks, flipped on the way ---------

def reference_classify(img, negate, occ_t, free_t, mode):
    """Nav2's rules as the straightforward table lookup (the implementation before issue 18)."""
    m, key, n = img.maxval, img.channel_sum, img.n_channels
    if img.alpha is not None and mode == "trinary":
        key = key.astype(np.int64) + img.alpha
        n += 1
    shade = np.arange(n * m + 1, dtype=float) / (n * m)
    if mode == "raw":
        v = np.rint(shade * 255.0)
        known = v <= 100
        occ_lut, free_lut = known & (v / 100.0 > occ_t), known & (v / 100.0 < free_t)
    else:
        occ = shade if negate else 1.0 - shade
        occ_lut = occ > occ_t
        free_lut = (occ < free_t) & ~occ_lut
    occupied, free = occ_lut[key], free_lut[key]
    if mode == "scale" and img.alpha is not None:
        opaque = img.alpha == m
        occupied &= opaque
        free &= opaque
    return occupied, free


@pytest.mark.parametrize("chunk", [ogm._LOOKUP_CELLS, 1, 37])
@pytest.mark.parametrize("mode", ["trinary", "scale", "raw"])
def test_classify_matches_the_whole_image_lookup(monkeypatch, chunk, mode):
    monkeypatch.setattr(ogm, "_LOOKUP_CELLS", chunk)
    rng = np.random.default_rng(7)
    for maxval, n_ch, alpha in ((255, 1, False), (255, 3, True), (65535, 1, False), (100, 1, True)):
        key = rng.integers(0, n_ch * maxval + 1, size=(23, 19)).astype(np.uint16 if maxval > 255 else np.int64)
        a = rng.integers(0, maxval + 1, size=key.shape) if alpha else None
        if a is not None:
            a[rng.random(key.shape) < 0.5] = maxval
        for negate in (False, True):
            img = Shades(key, n_ch, maxval, a)
            flipped = Shades(key[::-1], n_ch, maxval, None if a is None else a[::-1])
            want = reference_classify(img, negate, 0.65, 0.196, mode)
            got = classify(flipped, negate, 0.65, 0.196, mode)
            for w, g in zip(want, got):
                assert g.flags.c_contiguous
                np.testing.assert_array_equal(g, w[::-1])


# --- companion fly: the maps are read once ----------------------------------------------

def test_fly_prepare_and_execute_share_one_reading_of_the_maps(monkeypatch):
    """``prepare``'s preflight check reads the maps through ``MissionMaps``; what
    ``execute`` gets afterwards is that reading, not a second one, and equals a
    fresh reading of the files."""
    from pathlib import Path

    import mavcore.maps.field as field
    from companion.commands.fly import MissionMaps, prepare
    from mavcore.mission import load_mission

    root = Path(__file__).resolve().parents[1]
    mission = load_mission(root / "missions" / "flat-rectangle" / "mission.yaml")
    calls = []
    real = field.load_mission_maps

    def counted(m):
        calls.append(m)
        return real(m)

    monkeypatch.setattr(field, "load_mission_maps", counted)
    maps = MissionMaps(mission)
    prepare(mission, str(root / "tests" / "data" / "replay" / "plan-flat-rectangle.json"), maps=maps)
    assert len(calls) == 1
    grid, dem = maps.get()
    assert len(calls) == 1
    fresh_grid, fresh_dem = real(mission)
    np.testing.assert_array_equal(grid.occupied, fresh_grid.occupied)
    np.testing.assert_array_equal(grid.free, fresh_grid.free)
    np.testing.assert_array_equal(dem.heights_m, fresh_dem.heights_m)


# --- cell graphs: no cost temporaries when every cell costs 1 ----------------------------

def reference_graph_of(nb, neighbours, edge_cells):
    """The weights as built before issue 18: step x cost of the cell stepped into,
    the cost an array of ones when no cell is near an edge."""
    from scipy.sparse import csr_matrix

    from companion.coverage import gridpath

    n, k = nb.shape
    ok = nb >= 0
    if edge_cells > 0:
        inner = ok.all(axis=1)
        for _ in range(edge_cells - 1):
            inner = inner & np.where(ok, inner[np.where(ok, nb, 0)], False).all(axis=1)
        cost = np.where(inner, 1.0, gridpath._EDGE_COST)
    else:
        cost = np.ones(n)
    step = np.array([s for _, _, s in neighbours])
    to = nb[ok]
    w = np.broadcast_to(step, (n, k))[ok] * cost[to]
    indptr = np.concatenate([[0], np.cumsum(ok.sum(axis=1))])
    return csr_matrix((w, to, indptr), shape=(n, n))


@pytest.mark.parametrize("edge_cells", [0, 1, 2, 3])
@pytest.mark.parametrize("four", [False, True])
@pytest.mark.parametrize("field", range(5))
def test_mask_graph_weights_match_the_cost_array_build(field, four, edge_cells):
    from companion.coverage import gridpath

    neighbours = gridpath.NEIGHBOURS_4 if four else None
    graph, rows, cols = gridpath.mask_graph(random_fields()[field], neighbours=neighbours, edge_cells=edge_cells)
    nb = np.full((len(rows), 4 if four else 8), -1, dtype=np.int64)
    index = {(r, c): i for i, (r, c) in enumerate(zip(rows.tolist(), cols.tolist()))}
    offsets = gridpath.NEIGHBOURS_4 if four else gridpath._NEIGHBOURS
    for i, (r, c) in enumerate(zip(rows.tolist(), cols.tolist())):
        for j, (dr, dc, _) in enumerate(offsets):
            nb[i, j] = index.get((r + dr, c + dc), -1)
    ref = reference_graph_of(nb, offsets, edge_cells)
    assert graph.data.dtype == np.float64
    np.testing.assert_array_equal(graph.indptr, ref.indptr)
    np.testing.assert_array_equal(graph.indices, ref.indices)
    np.testing.assert_array_equal(graph.data, ref.data)          # bit for bit


# --- erosion: one running OR, no copy per half-width -------------------------------------

def reference_dilate_runs(mask, half_widths, outside):
    """The dilation as built before issue 18: a copy of the running OR kept per half-width."""
    w = np.asarray(half_widths, dtype=np.int64)
    if len(w) == 0:
        return mask.copy()
    k = (len(w) - 1) // 2
    p = max(k, int(w.max()), 0)
    rows, cols = mask.shape
    padded = np.full((rows + 2 * p, cols + 2 * p), outside, dtype=bool)
    padded[p: p + rows, p: p + cols] = mask
    runs = {0: padded[:, p: p + cols]}
    acc = runs[0].copy()
    for v in range(1, int(w.max()) + 1):
        acc |= padded[:, p + v: p + v + cols]
        acc |= padded[:, p - v: p - v + cols]
        runs[v] = acc.copy()
    out = np.zeros((rows, cols), dtype=bool)
    for i, v in enumerate(w.tolist()):
        if v >= 0:
            out |= runs[v][p + i - k: p + i - k + rows]
    return out


def brute_dilate(mask, half_widths, outside):
    """The definition: a cell is set when some (dr, dc), |dc| <= w[K + dr], reaches a set cell."""
    k = (len(half_widths) - 1) // 2
    rows, cols = mask.shape
    out = np.zeros_like(mask)
    for r in range(rows):
        for c in range(cols):
            for i, wv in enumerate(half_widths):
                for dc in range(-wv, wv + 1):
                    rr, cc = r + i - k, c + dc
                    inside = 0 <= rr < rows and 0 <= cc < cols
                    if (mask[rr, cc] if inside else outside):
                        out[r, c] = True
    return out


@pytest.mark.parametrize("outside", [False, True])
def test_dilate_runs_matches_the_per_width_copies_and_the_definition(outside):
    from companion.coverage.freespace import dilate_runs, disk_half_widths

    rng = np.random.default_rng(3)
    shapes = [disk_half_widths(r) for r in (0.7, 1.5, 3.2, 6.0, 11.0)]
    shapes += [np.array([2, -1, 0, 3, 1]), np.array([-1, -1, -1]), np.array([0]), 2 - np.abs(np.arange(-2, 3))]
    for field in random_fields():
        for w in shapes:
            np.testing.assert_array_equal(dilate_runs(field, w, outside), reference_dilate_runs(field, w, outside))
    small = rng.random((17, 13)) < 0.1
    for w in shapes[:3] + shapes[5:]:
        np.testing.assert_array_equal(dilate_runs(small, w, outside), brute_dilate(small, w, outside))


# --- SITL rows: compact, the same rays ---------------------------------------------------

_INF = math.inf
_EPS_T = 1e-9


class ReferenceRowField:
    """``sitl.world.RowField`` as it was before issue 18: nested lists of every cell's
    occupancy, leap and base height (~90 bytes a cell)."""

    def __init__(self, grid: OccupancyGrid, terrain: Terrain, canopy_height_m: float) -> None:
        occ = np.asarray(grid.occupied, dtype=bool)
        self.nr, self.nc = occ.shape
        self.res = float(grid.resolution_m)
        self.X0, self.Y0 = float(grid.origin_xy_m[0]), float(grid.origin_xy_m[1])
        self.c, self.s = math.cos(grid.origin_yaw_rad), math.sin(grid.origin_yaw_rad)
        self.any = bool(occ.any())
        self.occ = occ.tolist()
        if self.any:
            edt = ndimage.distance_transform_edt(~occ)
        else:
            edt = np.full(occ.shape, float(self.nr + self.nc))
        # Leap length (cells) that provably stays clear of every occupied cell
        # from any point of the cell: centre distance minus both half diagonals.
        self.leap = (edt - 1.5).tolist()
        rows, cols = np.nonzero(occ)
        base = np.zeros(occ.shape)
        if rows.size:
            xs, ys = grid.cell_to_world(rows, cols)
            base[rows, cols] = [terrain.height(float(x), float(y)) for x, y in zip(xs, ys)]
        self.base = base.tolist()
        self.canopy = float(canopy_height_m)

    def _band_hit(self, r, c, oz, dz, t_en, t_ex):
        base = self.base[r][c]
        top = base + self.canopy
        z = oz + dz * t_en
        if base <= z <= top:
            return t_en
        if z > top and dz < 0.0:
            tc = (top - oz) / dz
        elif z < base and dz > 0.0:
            tc = (base - oz) / dz
        else:
            return None
        return tc if tc <= t_ex else None

    def raycast(self, ox, oy, oz, dx, dy, dz, max_m) -> float:
        if not self.any:
            return _INF
        res, c, s = self.res, self.c, self.s
        ex, ey = ox - self.X0, oy - self.Y0
        u = (c * ex + s * ey) / res          # column coordinate (cells)
        v = (-s * ex + c * ey) / res         # row coordinate (cells)
        du = (c * dx + s * dy) / res         # cells per metre along the ray
        dv = (-s * dx + c * dy) / res
        nc, nr = self.nc, self.nr
        # Clip to the grid box [0, nc] x [0, nr] (slabs).
        t0, t1 = 0.0, max_m
        for q, dq, hi in ((u, du, nc), (v, dv, nr)):
            if dq == 0.0:
                if q < 0.0 or q >= hi:
                    return _INF
            else:
                ta, tb = (0.0 - q) / dq, (hi - q) / dq
                if ta > tb:
                    ta, tb = tb, ta
                if ta > t0:
                    t0 = ta
                if tb < t1:
                    t1 = tb
        if t0 > t1:
            return _INF
        occ, leap = self.occ, self.leap
        sp = math.hypot(du, dv)
        if sp * (t1 - t0) < 1e-12:   # vertical ray: one column of cells
            r, cc = int(v), int(u)
            if 0 <= r < nr and 0 <= cc < nc and occ[r][cc]:
                hit = self._band_hit(r, cc, oz, dz, t0, t1)
                return _INF if hit is None else hit
            return _INF
        t = t0
        t_in = t0      # exact entry of the current cell (t itself is nudged past boundaries)
        while t <= t1:
            uu = u + du * t
            vv = v + dv * t
            cc = int(uu) if uu < nc else nc - 1
            r = int(vv) if vv < nr else nr - 1
            # On a cell boundary moving toward lower indices the ray is in the
            # lower cell (else the exit distance is 0 and t only creeps by _EPS_T).
            if du < 0.0 and cc == uu:
                cc -= 1
            if dv < 0.0 and r == vv:
                r -= 1
            if cc < 0:
                cc = 0
            if r < 0:
                r = 0
            if occ[r][cc]:
                t_ex = _ref_cell_exit(uu, vv, du, dv, cc, r) + t
                hit = self._band_hit(r, cc, oz, dz, t_in, min(t_ex, t1))
                if hit is not None:
                    return hit
                t_in = t_ex
                t = t_ex + _EPS_T
                continue
            lp = leap[r][cc]
            if lp > 1.0:
                t += lp / sp
                t_in = t
            else:
                t_in = t + _ref_cell_exit(uu, vv, du, dv, cc, r)
                t = t_in + _EPS_T
        return _INF


def _ref_cell_exit(uu, vv, du, dv, cc, r):
    """Ray parameter (m) from (uu, vv) to the boundary of cell (r, cc)."""
    if du > 0.0:
        tu = (cc + 1 - uu) / du
    elif du < 0.0:
        tu = (cc - uu) / du
    else:
        tu = _INF
    if dv > 0.0:
        tv = (r + 1 - vv) / dv
    elif dv < 0.0:
        tv = (r - vv) / dv
    else:
        tv = _INF
    return tu if tu < tv else tv


def sitl_fields():
    """(grid, dem) pairs: rows on a slope, a yawed offset grid, random posts."""
    from mavcore.maps.grid import ElevationModel, OccupancyGrid

    rng = np.random.default_rng(11)
    out = []
    occ = np.zeros((60, 80), dtype=bool)
    occ[5::8, 4:76] = True
    occ[:, 40:42] = False
    X, Y = np.meshgrid(np.arange(12) * 0.5, np.arange(10) * 0.5)
    out.append((OccupancyGrid(occ, ~occ, 0.1), ElevationModel(0.3 * X - 0.2 * Y + 1.0, -1.0, -1.0, 0.5)))
    out.append((OccupancyGrid(occ.T.copy(), ~occ.T, 0.05, (3.0, -2.0), 0.4), None))
    posts = rng.random((50, 50)) < 0.03
    h = rng.random((8, 8))
    out.append((OccupancyGrid(posts, ~posts, 0.2, (-1.0, 0.5), -1.1), ElevationModel(h, -2.0, -2.0, 2.0)))
    return out


@pytest.mark.parametrize("field", range(3))
def test_sitl_rows_cast_the_same_rays_as_the_nested_lists(field):
    from sitl.world import RowField, Terrain, World

    grid, dem = sitl_fields()[field]
    terrain = Terrain(dem)
    new, ref = RowField(grid, terrain, 1.7), ReferenceRowField(grid, terrain, 1.7)
    rng = np.random.default_rng(field)
    ext = max(grid.shape) * grid.resolution_m
    for _ in range(3000):
        o = rng.uniform(-0.3 * ext, 1.3 * ext, 3) + np.array([grid.origin_xy_m[0], grid.origin_xy_m[1], 0.0])
        o[2] = rng.uniform(-0.5, 4.0)
        d = rng.normal(size=3)
        if rng.random() < 0.1:
            d[:2] = 0.0                                     # vertical rays
        d /= np.linalg.norm(d)
        args = (*map(float, o), *map(float, d), float(rng.uniform(0.5, 2 * ext)))
        assert new.raycast(*args) == ref.raycast(*args)     # bit for bit
    # the leaps and bases it reads are the old tables' values
    for r, c in zip(rng.integers(0, grid.shape[0], 300), rng.integers(0, grid.shape[1], 300)):
        assert new.leap_cells(int(r), int(c)) == ref.leap[r][c]
        if grid.occupied[r, c]:
            assert new.base_at(int(r), int(c)) == ref.base[r][c]
    # the collision scene's cells: the float32 bases and bounds of the full-grid build
    w = World.build(grid, dem, canopy_height_m=1.7)
    base_ref = np.where(grid.occupied, np.array(ref.base), np.nan).astype(np.float32)
    np.testing.assert_array_equal(w.geometry.rows.base, base_ref)
    edt = ndimage.distance_transform_edt(~grid.occupied)
    b = (np.maximum(edt - math.sqrt(2.0), 0.0) * grid.resolution_m).astype(np.float32)
    np.testing.assert_array_equal(w.geometry.rows._bound,
                                  np.maximum(np.nextafter(b, np.float32(-np.inf)), np.float32(0.0)))


def test_clearance_sq_cells_is_the_square_of_the_distance_transform():
    from mavcore.geometry import clearance_sq_cells

    for field in random_fields():
        d2 = clearance_sq_cells(~field)
        edt = ndimage.distance_transform_edt(field)
        assert d2.dtype == np.int32
        np.testing.assert_array_equal(np.sqrt(d2.astype(np.float64)), edt)     # bit for bit
        r, c = np.nonzero(~field)
        for i, j in zip(*np.nonzero(field[::7, ::5])):      # brute force at some cells
            i, j = 7 * i, 5 * j
            assert d2[i, j] == int(np.min((r - i) ** 2 + (c - j) ** 2))


@pytest.mark.parametrize("chunk", [ogm._LOOKUP_CELLS, 1, 37])
def test_table_lookup_of_any_table_matches_fancy_indexing(monkeypatch, chunk):
    """``_lookup``: a table True on one run of keys (compared), on several runs, all
    False or all True (looked up), for uint8, uint16 and int64 keys, flipped views."""
    monkeypatch.setattr(ogm, "_LOOKUP_CELLS", chunk)
    rng = np.random.default_rng(5)
    for n, dtype in ((256, np.uint8), (65536, np.uint16), (766, np.int64)):
        key = rng.integers(0, n, size=(31, 17)).astype(dtype)
        tables = [np.zeros(n, bool), np.ones(n, bool), rng.random(n) < 0.5]
        for a, b in ((0, 0), (0, n // 3), (n // 4, n // 2), (n - 1, n - 1), (5, n - 1)):
            t = np.zeros(n, bool)
            t[a:b + 1] = True
            tables.append(t)
        for lut in tables:
            for k in (key, key[::-1], key[:, ::-1]):
                np.testing.assert_array_equal(ogm._lookup(lut, k), lut[k])


def test_collision_cells_keep_a_ready_float32_base_and_copy_any_other():
    from mavcore.geometry import ExtrudedCells
    from mavcore.maps.grid import OccupancyGrid

    occ = random_fields()[0]
    grid = OccupancyGrid(occ, ~occ, 0.1)
    heights = np.random.default_rng(2).random(occ.shape)
    ready = np.where(occ, heights, np.nan).astype(np.float32)
    assert ExtrudedCells(grid, ready, 1.0).base is ready                 # kept: already float32, NaN off
    raw32 = heights.astype(np.float32)
    cells = ExtrudedCells(grid, raw32, 1.0)
    assert cells.base is not raw32 and not np.isnan(raw32).any()         # copied, the caller's untouched
    np.testing.assert_array_equal(cells.base, ready)
    np.testing.assert_array_equal(ExtrudedCells(grid, heights, 1.0).base, ready)    # float64 in
