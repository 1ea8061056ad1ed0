"""The guard's distance to a re-route's added cells, taken as rectangles of one top
(``companion.safety.obstacles.added_rectangles``), is the per-cell minimum to the last bit.

The reference below is the per-cell computation written out cell by cell (each cell a
square ``[c h, (c + 1) h] x [r h, (r + 1) h]`` in the grid frame, a column up to its top),
independent of the merged boxes; equality is exact (``np.array_equal``), because the merge
is a speed-up that must not move any decision of the guard.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from companion.safety.obstacles import _AddedCells, added_rectangles


def _per_cell(known, x, y, z):
    g = known.grid
    h = float(g.resolution_m)
    ox, oy = float(g.origin_xy_m[0]), float(g.origin_xy_m[1])
    c, s = np.cos(g.origin_yaw_rad), np.sin(g.origin_yaw_rad)
    out = np.full(len(x), np.inf)
    rr, cc = np.nonzero(known.added)
    tops = None if known.added_top is None else np.asarray(known.added_top, float)
    finite = tops is not None and np.isfinite(tops[rr, cc]).any()
    for i in range(len(x)):
        dx, dy = x[i] - ox, y[i] - oy
        gx, gy = c * dx + s * dy, -s * dx + c * dy
        best = np.inf
        for r, col in zip(rr, cc):
            ex = max(max(col * h - gx, gx - (col + 1) * h), 0.0)
            ey = max(max(r * h - gy, gy - (r + 1) * h), 0.0)
            e2 = ex * ex + ey * ey
            if finite:
                ez = max(z[i] - tops[r, col], 0.0)
                e2 = e2 + ez * ez
            best = min(best, e2)
        out[i] = math.sqrt(best)
    return out


def _known(rng, shape=(40, 50), unknown_tops=False):
    added = np.zeros(shape, bool)
    top = np.full(shape, -np.inf, np.float32)
    for _ in range(rng.integers(1, 5)):             # a few blocks, some overlapping, each one top
        r0, c0 = rng.integers(0, shape[0] - 8), rng.integers(0, shape[1] - 8)
        hr, hc = rng.integers(1, 8, size=2)
        added[r0:r0 + hr, c0:c0 + hc] = True
        top[r0:r0 + hr, c0:c0 + hc] = rng.choice([np.inf, rng.uniform(0.5, 2.5)])
    scatter = rng.random(shape) < 0.02               # and single cells of their own tops
    added |= scatter
    top[scatter] = rng.uniform(0.5, 2.5, scatter.sum()).astype(np.float32)
    grid = SimpleNamespace(resolution_m=float(rng.choice([0.1, 0.05, 0.2])),
                           origin_xy_m=(float(rng.uniform(-5, 5)), float(rng.uniform(-5, 5))),
                           origin_yaw_rad=float(rng.uniform(-math.pi, math.pi)))
    return SimpleNamespace(added=added, added_top=None if unknown_tops else top, grid=grid)


@pytest.mark.parametrize("seed", range(12))
def test_rectangles_give_the_per_cell_distance_bit_for_bit(seed):
    rng = np.random.default_rng([2026_11_28, seed])
    known = _known(rng, unknown_tops=seed % 4 == 3)
    span = known.grid.resolution_m * 55
    n = 300
    x = rng.uniform(-span, span, n) + known.grid.origin_xy_m[0]
    y = rng.uniform(-span, span, n) + known.grid.origin_xy_m[1]
    z = rng.uniform(0.0, 3.5, n)
    got = _AddedCells().distance(known, x, y, z)
    assert np.array_equal(got, _per_cell(known, x, y, z))


def test_points_on_cell_boundaries_and_inside_blocks():
    # the merged span has no gap between cells: a point on a shared edge or anywhere inside
    # a block is 0 away (below its top), exactly as in the cell that holds it
    added = np.zeros((10, 10), bool)
    added[2:5, 3:7] = True
    top = np.where(added, np.float32(1.5), np.float32(-np.inf))
    known = SimpleNamespace(added=added, added_top=top,
                            grid=SimpleNamespace(resolution_m=0.1, origin_xy_m=(0.0, 0.0), origin_yaw_rad=0.0))
    x = np.array([0.4, 0.5, 0.35, 0.65, 0.8, 0.5])
    y = np.array([0.3, 0.3, 0.25, 0.45, 0.3, 0.3])
    z = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 2.0])
    got = _AddedCells().distance(known, x, y, z)
    assert np.array_equal(got, _per_cell(known, x, y, z))
    assert got[:4].tolist() == [0.0, 0.0, 0.0, 0.0]
    assert got[4] == pytest.approx(0.1, abs=1e-12)          # 0.8 - 0.7 east of the block
    assert got[5] == pytest.approx(0.5, abs=1e-6)           # 2.0 over the 1.5 m top


def test_blocks_merge_into_few_rectangles():
    # a 6 x 5 block of one top is one rectangle; a second top beside it another; a cell
    # of a third top inside the first splits its rows
    rr, cc = np.nonzero(np.ones((6, 5), bool))
    top = np.full(len(rr), 1.25)
    r0, r1, c0, c1, t = added_rectangles(rr, cc, top)
    assert (r0.tolist(), r1.tolist(), c0.tolist(), c1.tolist(), t.tolist()) == ([0], [5], [0], [4], [1.25])
    top2 = top.copy()
    top2[(rr == 2) & (cc == 2)] = 2.0
    r0, r1, c0, c1, t = added_rectangles(rr, cc, top2)
    cells = sum((b - a + 1) * (d - c + 1) for a, b, c, d in zip(r0, r1, c0, c1))
    assert cells == 30 and len(r0) == 5     # rows 0-1, row 2 split in three, rows 3-5
