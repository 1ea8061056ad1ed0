"""The known map built a band of rows at a time (issue 18, the companion's memory on 10 ha):
the same cells as the whole-grid dilation, so the same answers to every query.

The reference is ``dilate_runs`` on the whole array (itself checked against the
definition in tests/test_plan_speed.py) and the erosion's definition: a free cell
is kept when no non-free cell (or the outside) lies within the disk.
"""

from __future__ import annotations

import numpy as np
import pytest

from companion.coverage.freespace import (FreeSpace, any_both, dilate_runs, dilate_runs_banded, disk_half_widths,
                                          erode_free_space)
from mavcore.maps.grid import ElevationModel, OccupancyGrid
from companion.replan import KnownMap


def _brute_erosion(free: np.ndarray, radius_cells: float) -> np.ndarray:
    """Free cells with no non-free cell (nor the outside) at centre distance < radius (loops)."""
    R, C = free.shape
    k = int(np.ceil(radius_cells))
    out = np.zeros_like(free)
    for r in range(R):
        for c in range(C):
            if not free[r, c]:
                continue
            ok = True
            for dr in range(-k, k + 1):
                for dc in range(-k, k + 1):
                    if dr * dr + dc * dc >= radius_cells ** 2 * (1 - 1e-9):
                        continue
                    rr, cc = r + dr, c + dc
                    if not (0 <= rr < R and 0 <= cc < C) or not free[rr, cc]:
                        ok = False
            out[r, c] = ok
    return out


@pytest.mark.parametrize("band", [1, 2, 5, 17, 10_000])
@pytest.mark.parametrize("outside", [False, True])
def test_banded_dilation_is_the_whole_grid_dilation(band, outside):
    rng = np.random.default_rng(band)
    for _ in range(20):
        mask = rng.random(tuple(int(x) for x in rng.integers(1, 40, 2))) < rng.choice([0.01, 0.1, 0.5])
        w = disk_half_widths(float(rng.uniform(0.5, 6.0)))
        for invert in (False, True):
            src = ~mask if invert else mask
            got = dilate_runs_banded(mask, w, outside, invert=invert, band_rows=band)
            np.testing.assert_array_equal(got, dilate_runs(src, w, outside))
    # into a window of a larger array, the rest untouched
    big = np.ones((30, 30), bool)
    dilate_runs_banded(np.zeros((10, 10), bool), disk_half_widths(2.0), False, band_rows=band, out=big[5:15, 5:15])
    assert not big[5:15, 5:15].any() and big.sum() == 900 - 100


def test_any_both_in_bands():
    a = np.zeros((9, 4), bool)
    b = np.zeros((9, 4), bool)
    a[8, 3] = True
    assert not any_both(a, b, band_rows=2)
    b[8, 3] = True
    assert any_both(a, b, band_rows=2) and any_both(a, b, band_rows=100)


def test_erosion_in_bands_is_the_definition(monkeypatch):
    import companion.coverage.freespace as fs

    rng = np.random.default_rng(5)
    for trial in range(12):
        R, C = (int(x) for x in rng.integers(5, 30, 2))
        occ = rng.random((R, C)) < 0.05
        free = ~occ & (rng.random((R, C)) > 0.03)
        grid = OccupancyGrid(occ, free, 0.1)
        margin = float(rng.uniform(0.05, 0.4))
        monkeypatch.setattr(fs, "BAND_ROWS", int(rng.integers(1, 6)))
        got = fs.erode_free_space(grid, margin)
        np.testing.assert_array_equal(got.eroded, _brute_erosion(free & ~occ, (margin + 0.1) / 0.1))


def _whole_grid_known_map(grid, dem, free: FreeSpace, canopy, tol) -> KnownMap:
    """KnownMap.build as it was: the rows dilated on the whole grid at once."""
    known = KnownMap.build(grid, dem, free, canopy, tol)
    from dataclasses import replace
    rows = dilate_runs(np.asarray(grid.occupied, bool), disk_half_widths(tol / grid.resolution_m + 1.0), False)
    return replace(known, known_rows=rows)


def test_known_map_answers_every_query_as_before():
    """A bundled mission's known map: every cell of both masks, and classify / explains
    on random hits and rays, against the map built on the whole grid at once."""
    from mavcore.maps.field import load_mission_maps
    from mavcore.mission import load_mission

    mission = load_mission("missions/obstacle-tall/mission.yaml")
    grid, dem = load_mission_maps(mission)
    new = KnownMap.from_mission(mission, grid, dem)
    h = grid.resolution_m
    free = grid.free & ~grid.occupied
    eroded = free & ~dilate_runs(~free, disk_half_widths(new.free.threshold_m / h), outside=True)
    np.testing.assert_array_equal(new.free.eroded, eroded)
    old = _whole_grid_known_map(grid, dem, FreeSpace(eroded, free, h, new.free.threshold_m),
                                mission.replan.canopy_height_m, mission.replan.known_tolerance_m)
    np.testing.assert_array_equal(new.known_rows, old.known_rows)
    rng = np.random.default_rng(11)
    x0, y0 = grid.cell_to_world(0, 0)
    x1, y1 = grid.cell_to_world(grid.shape[0] - 1, grid.shape[1] - 1)
    lo, hi = np.minimum([x0, y0], [x1, y1]) - 1.0, np.maximum([x0, y0], [x1, y1]) + 1.0
    for _ in range(3000):
        x, y = rng.uniform(lo, hi)
        z = float(rng.uniform(-0.2, 3.0))
        assert new.classify(x, y, z) == old.classify(x, y, z)
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        r = float(rng.uniform(0.1, 6.0))
        assert new.explains((x, y, z), d, r) == old.explains((x, y, z), d, r)
