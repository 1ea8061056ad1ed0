"""Issue 18's third round of planning speed-ups keeps every result exactly: each
changed function against the implementation it replaced (kept here as the
reference) or an independent definition, with the edge cases forced."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from companion.coverage import rows as rows_mod
from companion.coverage.freespace import Raster, dilate_runs
from companion.coverage.gridpath import cell_path
from mavcore.maps.grid import OccupancyGrid

ROOT = Path(__file__).resolve().parents[1]


# --- beam sampling: only the samples that can fall on the mask ------------------------------

def reference_sample_lines(r: Raster, alpha, offsets, t, dtype=np.float32):
    """``Raster.sample_lines`` as one whole-array pass over every sample (the definition)."""
    u0, u1 = np.cos(alpha), np.sin(alpha)
    inv = 1.0 / r.cell_m
    ax = ((offsets * -u1 - r.x0_m) * inv + 1.0).astype(dtype)
    ay = ((offsets * u0 - r.y0_m) * inv + 1.0).astype(dtype)
    bx, by = (t * (u0 * inv)).astype(dtype), (t * (u1 * inv)).astype(dtype)
    x = np.clip(ax[:, None] + bx[None, :], 0, r.cols + 1)
    y = np.clip(ay[:, None] + by[None, :], 0, r.rows + 1)
    return r.flat.take(y.astype(np.int64) * (r.cols + 2) + x.astype(np.int64))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_sample_lines_over_the_lines_ranges_equals_every_sample(dtype):
    rng = np.random.default_rng(183)
    for shape in ((41, 67), (90, 33), (1, 50), (60, 1)):
        mask = rng.random(shape) < 0.7
        mask[0, 0] = mask[-1, -1] = True        # cells on the mask's very edge
        r = Raster(mask, 0.1, -0.05 * shape[1] + 0.013, -0.05 * shape[0] - 0.007)
        extent = 0.1 * max(shape)
        for alpha in (0.0, np.pi / 2, np.pi / 4, 1e-9, np.pi - 1e-9, 2.9, rng.uniform(0, np.pi)):
            # unsorted offsets, some missing the mask altogether
            offsets = np.r_[rng.uniform(-0.8 * extent, 0.8 * extent, 30), 3 * extent, -3 * extent, 0.0]
            t = -extent + 0.05 * np.arange(int(2 * extent / 0.05))
            ref = reference_sample_lines(r, alpha, offsets, t, dtype)
            assert ref.any()
            for block in (None, 1, 4, 7, 1000):
                np.testing.assert_array_equal(r.sample_lines(alpha, offsets, t, dtype, block=block), ref)
            # t not ascending: every sample is computed (no range), the same values
            tp = rng.permutation(t)
            np.testing.assert_array_equal(r.sample_lines(alpha, offsets, tp, dtype),
                                          reference_sample_lines(r, alpha, offsets, tp, dtype))


def test_line_ranges_hold_every_sample_on_the_mask_and_end_a_quarter_cell_out():
    """Independent check of the ranges: a full mask, a horizontal line through row 2
    (cells of 1 m, lower-left corner at the origin): columns 0..9 are at t in [0, 10)."""
    r = Raster(np.ones((5, 10), dtype=bool), 1.0, 0.0, 0.0)
    t = np.arange(-3.0, 14.0, 0.125)
    ax = np.array([1.0], np.float32)             # padded coordinates: x = 1 + t
    ay = np.array([3.5], np.float32)
    j0, j1 = r._line_ranges(ax, ay, 1.0, 0.0, t)
    # padded x in [0.75, 11.25]: t in [-0.25, 10.25]
    assert t[j0[0]] == -0.25 and t[j1[0] - 1] == 10.25
    # a line beside the mask (padded y = 6.5 >= rows + 1 + 0.25): an empty range
    j0, j1 = r._line_ranges(ax, np.array([6.5], np.float32), 1.0, 0.0, t)
    assert j1[0] == j0[0]


# --- row detection: points only for the subsamples -----------------------------------------

def reference_occupied_points(grid: OccupancyGrid) -> np.ndarray:
    """``rows.occupied_points_g`` before: every border cell's centre, in np.nonzero order."""
    h = grid.resolution_m
    k = max(2, int(np.ceil(0.3 / h)))
    rows, cols = np.nonzero(grid.free)
    r0, r1 = max(0, rows.min() - k), min(grid.shape[0], rows.max() + 1 + k)
    c0, c1 = max(0, cols.min() - k), min(grid.shape[1], cols.max() + 1 + k)
    near = dilate_runs(grid.free[r0:r1, c0:c1], k - np.abs(np.arange(-k, k + 1)), outside=False)
    r, c = np.nonzero(grid.occupied[r0:r1, c0:c1] & near)
    return np.column_stack([(c + c0 + 0.5) * h, (r + r0 + 0.5) * h])


def reference_subsample(pts: np.ndarray, n_max: int) -> np.ndarray:
    return pts if len(pts) <= n_max else pts[:: int(np.ceil(len(pts) / n_max))]


def test_border_cells_give_the_subsampled_points_of_every_border_cell():
    rng = np.random.default_rng(184)
    occ = np.zeros((120, 90), dtype=bool)
    occ[10:110:6, 5:85] = True                  # rows
    occ |= rng.random(occ.shape) < 0.02          # posts
    free = ~occ
    free[:4] = False                             # unknown strip
    grid = OccupancyGrid(occupied=occ, free=free, resolution_m=0.1)
    ref = reference_occupied_points(grid)
    cells = rows_mod.border_cells(grid)
    assert len(cells.flat) == len(ref) > 100
    np.testing.assert_array_equal(rows_mod.occupied_points_g(grid), ref)
    for n_max in (1, 7, 100, len(ref) - 1, len(ref), 10 * len(ref)):
        np.testing.assert_array_equal(cells.points(n_max), reference_subsample(ref, n_max))


def test_border_cells_of_a_grid_without_free_cells_are_none():
    grid = OccupancyGrid(occupied=np.ones((5, 5), bool), free=np.zeros((5, 5), bool), resolution_m=0.1)
    assert rows_mod.occupied_points_g(grid).shape == (0, 2)
    assert rows_mod.detect_rows(grid) is None


# --- cell paths: the predecessor walk in Python ints ------------------------------------------

def test_cell_path_is_a_shortest_8_connected_path():
    """A U-shaped set of cells: the path goes round the bend, each step to an
    8-neighbour, and its length is the hand-worked shortest one."""
    m = np.zeros((12, 12), dtype=bool)
    m[1:11, 1:4] = m[1:11, 8:11] = m[8:11, 1:11] = True
    rr, cc = np.nonzero(m)
    path = cell_path(rr, cc, (1, 2), (1, 9))
    assert tuple(path[0]) == (1, 2) and tuple(path[-1]) == (1, 9)
    steps = np.abs(np.diff(path, axis=0))
    assert steps.max() == 1 and (steps.sum(axis=1) > 0).all()
    assert m[path[:, 0], path[:, 1]].all()
    # down the left arm, across the bottom, up the right arm: 7 rows + 7 columns + 7 rows,
    # at least (rows 1 -> 9 -> 1, columns 2 -> 9): 8 + 8 steps, diagonals cutting 2 corners
    assert len(path) - 1 >= 16
    assert cell_path(rr, cc, (1, 2), (0, 0)) is None


# --- the plan comparison script ------------------------------------------------------------

def test_compare_plans_ignores_timings_and_reports_every_kind_of_difference(tmp_path):
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from compare_plans import differences
    finally:
        sys.path.pop(0)
    a = {"timings_s": {"total": 1.0}, "stats": {"n": 3, "x": 0.1}, "path": [[0.0, 1.0], [2.0, 3.0]]}
    b = json.loads(json.dumps(a))
    b["timings_s"]["total"] = 2.0
    assert differences(a, b) == []
    b["stats"]["x"] = 0.1 + 1e-15
    assert differences(a, b) == [f"/stats/x: 0.1 != {0.1 + 1e-15!r}"]
    assert differences(a, b, rel_tol=1e-12) == []
    b["stats"]["n"] = 3.0                         # an int turned float is a difference
    b["path"].append([4.0, 5.0])
    b["extra"] = 1
    got = differences(a, b, rel_tol=1e-12)
    assert got == ["/extra: only in after", "/path: length 2 != 3", "/stats/n: 3 != 3.0"]
    pa, pb = tmp_path / "a.json", tmp_path / "b.json"
    pa.write_text(json.dumps(a))
    pb.write_text(json.dumps(a))
    script = str(ROOT / "benchmarks" / "compare_plans.py")
    assert subprocess.run([sys.executable, script, str(pa), str(pb)], capture_output=True).returncode == 0
    pb.write_text(json.dumps(b))
    assert subprocess.run([sys.executable, script, str(pa), str(pb)], capture_output=True).returncode == 1
    bad = subprocess.run([sys.executable, script, str(pa), str(tmp_path / "none.json")], capture_output=True)
    assert bad.returncode == 2 and b"Traceback" not in bad.stderr


# --- block graph: corridors and their cells without sparse row slicing ----------------------

def reference_corridor(bg, s_from: int, s_to: int):
    """``BlockGraph.corridor`` before: the nodes' neighbours by slicing the sparse matrix."""
    from scipy.sparse.csgraph import dijkstra
    if s_from <= 0 or s_to <= 0 or bg.component[s_from] != bg.component[s_to]:
        return None
    if s_from == s_to:
        nodes = np.array([s_from])
    else:
        _, pred = dijkstra(bg.graph, directed=True, indices=s_from, return_predecessors=True)
        path = [s_to]
        while path[-1] != s_from:
            path.append(int(pred[path[-1]]))
        nodes = np.array(path)
    return np.unique(np.concatenate([nodes, bg.graph[nodes].indices]))


def reference_cells_of(bg, subs):
    """``BlockGraph.cells_of`` before: membership by ``np.isin``."""
    f, nbc = bg.block, bg.local.shape[1]
    bi, bj = bg.block_of[subs].T
    ub = np.unique(bi * nbc + bj)
    loc = bg.local[ub // nbc, ub % nbc].astype(np.int64)
    ids = np.where(loc > 0, loc + bg.base[ub // nbc, ub % nbc][:, None, None], 0)
    m, lr, lc = np.nonzero(np.isin(ids, subs))
    return bg.r0 + (ub[m] // nbc) * f + lr, bg.c0 + (ub[m] % nbc) * f + lc


def test_corridor_and_cells_of_match_the_sparse_slicing_and_isin():
    from companion.coverage.blockgraph import build_block_graph
    from companion.coverage.freespace import bbox_cells
    rng = np.random.default_rng(185)
    mask = np.ones((160, 220), dtype=bool)
    mask[::6, 10:200] = False                   # rows, with a headland on each side
    mask[40:60, 100:130] = False                # a shed
    mask &= rng.random(mask.shape) > 0.03       # scattered posts
    bg = build_block_graph(mask, bbox_cells(mask))
    subs = np.flatnonzero(bg.component >= 0)
    comp = bg.component[subs]
    main = subs[comp == np.bincount(comp).argmax()]
    checked = 0
    for a, b in rng.choice(main, size=(25, 2)).tolist() + [(int(main[0]), int(main[0]))]:
        got, ref = bg.corridor(a, b), reference_corridor(bg, a, b)
        np.testing.assert_array_equal(got, ref)
        for g, r in zip(bg.cells_of(got), reference_cells_of(bg, ref)):
            np.testing.assert_array_equal(g, r)
        # every cell listed is eroded and belongs to one of the corridor's sub-components
        rr, cc = bg.cells_of(got)
        assert mask[rr, cc].all() and np.isin([bg.sub_at(r, c) for r, c in zip(rr, cc)], got).all()
        checked += len(rr)
    assert checked > 1000
    assert bg.corridor(0, int(main[0])) is None
