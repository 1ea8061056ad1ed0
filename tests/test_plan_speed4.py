"""Issue 18's fourth round of planning speed-ups keeps every result exactly: each
changed function against the implementation it replaced (kept here as the
reference) and against hand-worked values, with the edge cases forced."""

from __future__ import annotations

import numpy as np
import pytest

from companion.coverage import blockgraph as bg_mod
from companion.coverage import gridpath
from companion.coverage.gridpath import NEIGHBOURS_4, _EDGE_COST, _graph_of, _rows_count, cell_graph, mask_graph


# --- cell graphs: weights in the (n, k) layout, row counts by bit count ------------------------

def reference_graph_of(nb, neighbours, edge_cells):
    """``gridpath._graph_of`` before (two boolean selections, ``np.where`` per pass, a sum per column)."""
    from scipy.sparse import csr_matrix
    edge_cells = gridpath._EDGE_CELLS if edge_cells is None else edge_cells
    n, k = nb.shape
    ok = nb >= 0
    step = np.array([s for _, _, s in neighbours])
    to = nb[ok]
    w = np.broadcast_to(step, (n, k))[ok]
    if edge_cells > 0:
        inner = ok.all(axis=1)
        for _ in range(edge_cells - 1):
            inner = inner & np.where(ok, inner[np.where(ok, nb, 0)], False).all(axis=1)
        w = w * np.where(inner, 1.0, _EDGE_COST)[to]
    idx = np.int32 if n * k < 2**31 - 1 else np.int64
    per_row = ok[:, 0].astype(idx)
    for j in range(1, k):
        per_row += ok[:, j]
    indptr = np.zeros(n + 1, dtype=idx)
    np.cumsum(per_row, out=indptr[1:])
    return csr_matrix((w, to.astype(idx, copy=False), indptr), shape=(n, n))


def _same_csr(a, b):
    for name in ("data", "indices", "indptr"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype, name
        np.testing.assert_array_equal(x, y, err_msg=name)


def _neighbour_table(mask, neighbours):
    rows, cols = np.nonzero(mask)
    ids = np.full(mask.shape, -1)
    ids[rows, cols] = np.arange(len(rows))
    pad = np.pad(ids, 1, constant_values=-1)
    return np.column_stack([pad[rows + 1 + dr, cols + 1 + dc] for dr, dc, _ in neighbours])


@pytest.mark.parametrize("neighbours", [gridpath._NEIGHBOURS, NEIGHBOURS_4, gridpath._NEIGHBOURS[:3]])
@pytest.mark.parametrize("edge_cells", [None, 0, 1, 2, 3])
def test_graph_of_equals_the_reference(neighbours, edge_cells):
    rng = np.random.default_rng(184)
    for shape, p in (((30, 40), 0.8), ((25, 25), 0.97), ((1, 9), 1.0), ((7, 1), 1.0), ((1, 1), 1.0)):
        mask = rng.random(shape) < p
        mask.flat[0] = True
        nb = _neighbour_table(mask, neighbours)
        _same_csr(_graph_of(nb, neighbours, edge_cells), reference_graph_of(nb, neighbours, edge_cells))
    # a non-contiguous table (a column slice): the per-row count falls back to the sum
    nb = _neighbour_table(rng.random((20, 20)) < 0.9, gridpath._NEIGHBOURS)
    nb8 = np.column_stack([nb, nb])[:, ::2]
    assert not nb8.flags.c_contiguous
    _same_csr(_graph_of(nb8, gridpath._NEIGHBOURS, 2), reference_graph_of(nb8, gridpath._NEIGHBOURS, 2))


def test_cell_graph_weights_by_hand():
    """A full 5 x 5 block of cells: only the centre is more than 2 cells from an unlisted
    cell, so only steps into the centre cost 1 (x the step); every other step costs 4 x."""
    rr, cc = np.nonzero(np.ones((5, 5), dtype=bool))
    g, order = cell_graph(rr, cc)
    np.testing.assert_array_equal(order, np.arange(25))         # already in node order
    assert g.nnz == 2 * (5 * 4) * 2 + 2 * (4 * 4) * 2                 # 80 side + 64 diagonal edges
    centre = 12
    into = g[:, centre].toarray().ravel()
    np.testing.assert_allclose(into[[7, 11, 13, 17]], 1.0)
    np.testing.assert_allclose(into[[6, 8, 16, 18]], np.sqrt(2.0))
    assert g[0, 1] == 4.0 and g[0, 6] == pytest.approx(4.0 * np.sqrt(2.0))
    assert g[6, 0] == 4.0 * np.sqrt(2.0)
    # the 4-connected mask graph of the transit tree: unit steps, 4 per interior cell
    m = np.ones((3, 4), dtype=bool)
    g4, _, _ = mask_graph(m, neighbours=NEIGHBOURS_4, edge_cells=0)
    np.testing.assert_array_equal(np.diff(g4.indptr), [2, 3, 3, 2, 3, 4, 4, 3, 2, 3, 3, 2])
    assert set(g4.data.tolist()) == {1.0}


def test_rows_count_is_the_row_sum():
    rng = np.random.default_rng(186)
    for k in (1, 3, 4, 8, 9):
        b = rng.random((50, k)) < 0.5
        np.testing.assert_array_equal(_rows_count(b), b.sum(axis=1))
    b = rng.random((50, 16)) < 0.5
    np.testing.assert_array_equal(_rows_count(b[:, ::2]), b[:, ::2].sum(axis=1))
    assert _rows_count(np.ones((2, 8), dtype=bool)).tolist() == [8, 8]


# --- block graph: repeats dropped before the unique ---------------------------------------------

def reference_pairs(a, b, k):
    """``blockgraph._pairs`` before: the unique of every labelled pair."""
    m = (a > 0) & (b > 0) & (a != b)
    if not m.any():
        return None
    lo = np.minimum(a[m], b[m]).astype(np.int64)
    return np.unique(lo * (k + 1) + np.maximum(a[m], b[m]))


def test_pairs_equal_the_reference():
    rng = np.random.default_rng(187)
    for n in (1, 2, 5, 400):
        # runs of repeated labels, as along a block's border, and zeros
        a = np.repeat(rng.integers(0, 6, n), rng.integers(1, 5, n))
        b = np.repeat(rng.integers(0, 6, n), rng.integers(1, 5, n))
        m = min(len(a), len(b))
        a, b = a[:m].reshape(1, m), b[:m].reshape(1, m)
        got, ref = bg_mod._pairs(a, b, 6), reference_pairs(a, b, 6)
        assert (got is None) == (ref is None)
        if ref is not None:
            np.testing.assert_array_equal(got, ref)
    assert bg_mod._pairs(np.array([1, 1]), np.array([1, 0]), 3) is None
    np.testing.assert_array_equal(bg_mod._pairs(np.array([2, 2, 1]), np.array([1, 1, 2]), 3), [1 * 4 + 2])


def test_block_graph_is_the_same_with_the_reference_pairs(monkeypatch):
    from companion.coverage.freespace import bbox_cells
    rng = np.random.default_rng(188)
    mask = np.ones((170, 230), dtype=bool)
    mask[::6, 10:200] = False
    mask[40:60, 100:130] = False
    mask &= rng.random(mask.shape) > 0.03
    got = bg_mod.build_block_graph(mask, bbox_cells(mask))
    monkeypatch.setattr(bg_mod, "_pairs", reference_pairs)
    ref = bg_mod.build_block_graph(mask, bbox_cells(mask))
    _same_csr(got.graph, ref.graph)
    np.testing.assert_array_equal(got.component, ref.component)
    assert got.graph.nnz > 100


# --- DEM lookups: the NODATA bookkeeping only where a corner has NODATA ---------------------------

def reference_interp(dem, x, y):
    """``ElevationModel._interp`` before: the NODATA tests for every corner."""
    x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    z_grid = dem.heights_m
    rows, cols = z_grid.shape
    x_min, x_max, y_min, y_max = dem.extent_m
    tol = 1e-9 * max(1.0, dem.cellsize_m)
    inside = (x >= x_min - tol) & (x <= x_max + tol) & (y >= y_min - tol) & (y <= y_max + tol)
    inside &= np.isfinite(x) & np.isfinite(y)
    fc = np.where(inside, (x - dem.x0_m) / dem.cellsize_m, 0.0)
    fr = np.where(inside, (y - dem.y0_m) / dem.cellsize_m, 0.0)

    def axis(f, n):
        if n == 1:
            i0 = np.zeros(f.shape, dtype=np.intp)
            return i0, i0, np.zeros(f.shape)
        i0 = np.clip(np.floor(f).astype(np.intp), 0, n - 2)
        return i0, i0 + 1, f - i0

    c0, c1, tx = axis(fc, cols)
    r0, r1, ty = axis(fr, rows)
    w = ((1 - ty) * (1 - tx), (1 - ty) * tx, ty * (1 - tx), ty * tx)
    v = (z_grid[r0, c0], z_grid[r0, c1], z_grid[r1, c0], z_grid[r1, c1])
    z = np.zeros(x.shape)
    ok = inside.copy()
    for wi, vi in zip(w, v):
        ok &= ~(np.isnan(vi) & (wi != 0.0))
        z += wi * np.where(np.isnan(vi), 0.0, vi)
    return z, ok


def test_dem_interp_equals_the_reference_with_and_without_nodata():
    from mavcore.maps.grid import ElevationModel
    rng = np.random.default_rng(189)
    heights = rng.normal(30.0, 2.0, (9, 13))
    x = np.r_[rng.uniform(-2.0, 14.0, 500), 0.0, 12.0, 5.0, -0.5, 12.5, np.nan]
    y = np.r_[rng.uniform(-2.0, 10.0, 500), 0.0, 8.0, 4.0, -0.5, 8.5, 1.0]
    for h in (heights, np.where(rng.random(heights.shape) < 0.15, np.nan, heights), heights[:1], heights[:, :1]):
        dem = ElevationModel(heights_m=h, x0_m=0.0, y0_m=0.0, cellsize_m=1.0)
        z, ok = dem._interp(x, y)
        z_ref, ok_ref = reference_interp(dem, x, y)
        np.testing.assert_array_equal(ok, ok_ref)
        np.testing.assert_array_equal(z, z_ref)
        assert ok.any() and not ok.all()
    # a point on a NODATA cell's row but with zero weight on it (exactly on a centre): covered
    h = heights.copy()
    h[3, 5] = np.nan
    dem = ElevationModel(heights_m=h, x0_m=0.0, y0_m=0.0, cellsize_m=1.0)
    z, ok = dem._interp(np.array([4.0, 4.5]), np.array([2.0, 2.5]))
    assert ok.tolist() == [True, False] and z[0] == h[2, 4]


# --- the default launch point: the transit room of the searched window only ---------------------

def reference_transit_room(free):
    """``sorties.transit_room`` before: the pooled mask repeated to full resolution."""
    from companion.coverage.freespace import min_pool
    from companion.coverage.transit import POOL_M
    h = free.resolution_m
    p = max(1, int(round(POOL_M / h)))
    r0, r1, c0, c1 = free.bbox_cells
    room = np.zeros(free.eroded.shape, dtype=bool)
    if r1 > r0:
        pooled = min_pool(free.eroded[r0:r1, c0:c1], p)
        room[r0:r1, c0:c1] = np.repeat(np.repeat(pooled, p, axis=0), p, axis=1)[: r1 - r0, : c1 - c0]
    return room


@pytest.mark.parametrize("resolution_m", [0.05, 0.1, 0.3])
def test_transit_room_and_its_windows_equal_the_reference(resolution_m):
    from companion.coverage.freespace import FreeSpace
    from companion.sorties import _pooled_room, _room_window, transit_room
    rng = np.random.default_rng(190)
    for shape in ((37, 53), (8, 9), (1, 1)):
        eroded = np.zeros(shape, dtype=bool)
        eroded[2:-3, 3:-2] = rng.random((shape[0] - 5, shape[1] - 5)) < 0.9 if min(shape) > 6 else False
        free = FreeSpace(eroded=eroded, free=eroded, resolution_m=resolution_m, threshold_m=0.5)
        ref = reference_transit_room(free)
        np.testing.assert_array_equal(transit_room(free), ref)
        pr = _pooled_room(free)
        for a0, a1, b0, b1 in ((0, shape[0], 0, shape[1]), (1, 5, 0, 7), (3, 3, 0, 2), (0, 1, 0, 1)):
            a1, b1 = min(a1, shape[0]), min(b1, shape[1])      # windows inside the grid, as searched
            a0, b0 = min(a0, a1), min(b0, b1)
            np.testing.assert_array_equal(_room_window(pr, a0, a1, b0, b1), ref[a0:a1, b0:b1])
    # by hand: 0.1 m cells pool 2 x 2; a 4 x 5 eroded box at (1, 1) holds 2 x 2 whole blocks
    eroded = np.zeros((7, 8), dtype=bool)
    eroded[1:5, 1:6] = True
    room = transit_room(FreeSpace(eroded=eroded, free=eroded, resolution_m=0.1, threshold_m=0.5))
    expect = np.zeros_like(eroded)
    expect[1:5, 1:5] = True         # the fifth column's block is half outside the box
    np.testing.assert_array_equal(room, expect)


# --- visibility samples: per-segment values repeated, the floor left to the truncation ---------

def reference_samples_clear(free, a, targets, n, stride=1):
    """``gridpath._samples_clear`` before (gathers by segment index, ``Raster.sample_points``'s
    floor-then-clip arithmetic)."""
    m = n if stride == 1 else (n - 1) // stride + 1
    ends = np.cumsum(m)
    total = int(ends[-1]) if len(ends) else 0
    if total == 0:
        return np.zeros(0, dtype=bool)
    first = ends - m
    seg = np.repeat(np.arange(len(m)), m)
    j = (np.arange(total) - first[seg]) * stride
    s = j / np.maximum(n - 1, 1)[seg]
    d = targets - a
    px = s * d[:, 0].take(seg)
    py = s * d[:, 1].take(seg)
    if a.ndim == 1:
        px, py = px + a[0], py + a[1]
    else:
        px, py = px + a[:, 0].take(seg), py + a[:, 1].take(seg)
    r = free.raster()
    ok = r.sample_points(px, py)
    return np.logical_and.reduceat(ok, first)


@pytest.mark.parametrize("stride", [1, 3, 16])
def test_samples_clear_equals_the_reference(stride):
    from companion.coverage.freespace import FreeSpace
    from companion.coverage.gridpath import _sample_counts, _samples_clear
    rng = np.random.default_rng(191)
    eroded = rng.random((60, 80)) < 0.93
    free = FreeSpace(eroded=eroded, free=eroded, resolution_m=0.1, threshold_m=0.5)
    # segments inside, crossing and leaving the map (negative coordinates, beyond the far edge),
    # zero-length ones and ones ending exactly on cell edges
    a = np.r_[rng.uniform(-0.5, 8.5, (200, 2)), [[1.0, 1.0], [0.0, 0.0], [7.9, 5.9]]]
    b = np.r_[rng.uniform(-0.5, 8.5, (200, 2)), [[1.0, 1.0], [0.3, 0.0], [8.0, 6.0]]]
    n = _sample_counts(free, a, b)
    got = _samples_clear(free, a, b, n, stride)
    np.testing.assert_array_equal(got, reference_samples_clear(free, a, b, n, stride))
    assert got.any() and not got.all()
    for origin in (a[0], np.array([-0.25, 3.3])):
        n = _sample_counts(free, origin, b)
        np.testing.assert_array_equal(_samples_clear(free, origin, b, n, stride),
                                      reference_samples_clear(free, origin, b, n, stride))
    assert _samples_clear(free, a[:0], b[:0], n[:0], stride).shape == (0,)


def test_sample_xy_is_the_floor_lookup_by_hand():
    """0.1 m cells from G (0, 0): x = 0.05 -> column 0; -0.01 m is off the map (the padding,
    False); 0.1 - 1e-12 is still column 0; exactly 0.1 is column 1."""
    from companion.coverage.freespace import Raster
    mask = np.zeros((2, 3), dtype=bool)
    mask[0, 0] = mask[1, 2] = True
    r = Raster(mask, 0.1, 0.0, 0.0)
    gx = np.array([0.05, -0.01, 0.1 - 1e-12, 0.1, 0.25, 0.31, -5.0, 0.05])
    gy = np.array([0.05, 0.05, 0.05, 0.05, 0.15, 0.15, 0.05, -0.0001])
    expect = [True, False, True, False, True, False, False, False]
    assert r.sample_xy(gx.copy(), gy.copy()).tolist() == expect
    assert r.sample_points(gx, gy).tolist() == expect


# --- farthest visible point: the per-query bookkeeping in arrays -----------------------------------

def reference_farthest_visible_many(free, origins, targets):
    """``gridpath.farthest_visible_many`` before (lists of survivors, one loop per query)."""
    from companion.coverage.gridpath import _BATCH, _STRIDE, _sample_counts, _samples_clear
    origins = np.asarray(origins, float).reshape(-1, 2)
    targets = [np.asarray(t, float).reshape(-1, 2) for t in targets]
    sizes = np.array([len(t) for t in targets], dtype=np.int64)
    res = [-1] * len(targets)
    if sizes.sum() == 0:
        return res
    tg = np.concatenate(targets)
    org = np.repeat(origins, sizes, axis=0)
    n = _sample_counts(free, org, tg)
    coarse = _samples_clear(free, org, tg, n, _STRIDE)
    offset = np.concatenate([[0], np.cumsum(sizes)])
    surv = [np.flatnonzero(coarse[offset[q]: offset[q + 1]]) + offset[q] for q in range(len(targets))]
    top = [len(x) for x in surv]
    pending = [q for q in range(len(targets)) if top[q]]
    while pending:
        batch = [surv[q][max(0, top[q] - _BATCH): top[q]] for q in pending]
        ok = _samples_clear(free, org[np.concatenate(batch)], tg[np.concatenate(batch)], n[np.concatenate(batch)])
        nxt, at = [], 0
        for q, bq in zip(pending, batch):
            hit = np.flatnonzero(ok[at: at + len(bq)])
            at += len(bq)
            if len(hit):
                res[q] = int(bq[hit[-1]] - offset[q])
            else:
                top[q] -= _BATCH
                if top[q] > 0:
                    nxt.append(q)
        pending = nxt
    return res


def test_farthest_visible_many_equals_the_reference_and_the_definition():
    from companion.coverage.freespace import FreeSpace
    from companion.coverage.gridpath import farthest_visible_many, visible_from
    rng = np.random.default_rng(192)
    eroded = np.ones((80, 120), dtype=bool)
    eroded[::7, 5:110] = False                  # rows: most long segments are blocked
    eroded &= rng.random(eroded.shape) > 0.01
    free = FreeSpace(eroded=eroded, free=eroded, resolution_m=0.1, threshold_m=0.5)
    cells = np.argwhere(eroded)
    pts = (cells[:, ::-1] + 0.5) * 0.1
    origins = pts[rng.choice(len(pts), 60)]
    targets = [pts[rng.choice(len(pts), int(k))] for k in rng.integers(0, 40, 60)]
    targets[3] = pts[:0]                        # no targets
    targets[4] = origins[4][None]               # the origin itself: visible
    got = farthest_visible_many(free, origins, targets)
    assert got == reference_farthest_visible_many(free, origins, targets)
    for o, t, j in zip(origins, targets, got):      # the definition
        vis = np.flatnonzero(visible_from(free, o, t)) if len(t) else []
        assert j == (vis[-1] if len(vis) else -1)
    assert got[3] == -1 and got[4] == 0
    assert sum(j >= 0 for j in got) > 20 and sum(j == -1 for j in got) > 2
