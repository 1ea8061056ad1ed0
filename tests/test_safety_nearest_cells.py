"""The guard's nearest row cells a tile at a time (companion.safety.nearest_cells, issue 18):
the same cell as scipy's feature transform of the whole grid, for every cell, ties included.

The reference is ``scipy.ndimage.distance_transform_edt(~occupied, return_indices=True)``
of the whole grid (what ``RowField`` held before); tiles and halos are made small so
that the halo doubling, clipped windows and tiles at the grid's edge are all exercised.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from mavcore.maps.grid import ElevationModel, OccupancyGrid
from companion.safety.nearest_cells import NearestCells
from companion.safety.scene import RowField, TerrainField
from mavcore.maps.heightfield import HeightField


def _grids(seed: int, n: int):
    """Random grids with the ties a vineyard has: rows at regular spacing (a corridor's
    middle cell is equidistant from two rows), isolated cells, blocks, sparse noise."""
    rng = np.random.default_rng(seed)
    for k in range(n):
        R, C = (int(x) for x in rng.integers(5, 50, 2))
        kind = k % 4
        if kind == 0:
            occ = rng.random((R, C)) < rng.choice([0.002, 0.01, 0.05, 0.2])
        elif kind == 1:
            occ = np.zeros((R, C), bool)
            step = int(rng.integers(2, 9))
            occ[:, int(rng.integers(0, step))::step] = True
            occ &= rng.random((R, C)) > 0.05
        elif kind == 2:
            occ = np.zeros((R, C), bool)
            for _ in range(int(rng.integers(1, 5))):
                r, c = int(rng.integers(0, R)), int(rng.integers(0, C))
                occ[r:r + int(rng.integers(1, 6)), c:c + int(rng.integers(1, 6))] = True
        else:
            occ = np.zeros((R, C), bool)
            occ[int(rng.integers(0, R)), int(rng.integers(0, C))] = True
            occ[int(rng.integers(0, R)), int(rng.integers(0, C))] = True
        if occ.any():
            yield occ, int(rng.integers(1, 9)), int(rng.integers(1, 5))


def _reference(occ):
    return ndimage.distance_transform_edt(~occ, return_distances=False, return_indices=True)


def test_every_cell_matches_the_whole_grid_transform():
    count = 0
    for occ, tile, halo in _grids(7, 300):
        ref = _reference(occ)
        near = NearestCells(occ, tile=tile, halo=halo, cache_tiles=3)
        R, C = occ.shape
        rr, cc = np.mgrid[0:R, 0:C]
        gr, gc = near.gather(rr, cc)
        assert np.array_equal(gr, ref[0]) and np.array_equal(gc, ref[1]), (occ.shape, tile, halo)
        # the scalar path, in a scattered order (tiles evicted and recomputed)
        for r, c in zip(*np.unravel_index(np.random.default_rng(count).permutation(R * C)[:40], (R, C))):
            assert near.at(int(r), int(c)) == (ref[0, r, c], ref[1, r, c])
        count += 1
    assert count > 250


def test_a_lone_cell_far_away_grows_the_halo_to_the_whole_grid():
    occ = np.zeros((40, 70), bool)
    occ[39, 69] = True
    near = NearestCells(occ, tile=4, halo=1)
    assert near.at(0, 0) == (39, 69)
    assert near.at(20, 3) == (39, 69)


def test_no_occupied_cell_is_refused():
    with pytest.raises(ValueError):
        NearestCells(np.zeros((3, 3), bool))


def test_a_vineyard_grid_cell_by_cell():
    """The bundled 1 ha parcel's map (rows 2.5 m apart at 0.1 m: ties in every corridor)
    with the default tile and halo: every cell."""
    from mavcore.maps.field import load_mission_maps
    from mavcore.mission import load_mission

    grid, _ = load_mission_maps(load_mission("missions/vineyard-1ha/mission.yaml"))
    occ = np.asarray(grid.occupied, bool)
    ref = _reference(occ)
    rr, cc = np.mgrid[0:occ.shape[0], 0:occ.shape[1]]
    gr, gc = NearestCells(occ).gather(rr, cc)
    assert np.array_equal(gr, ref[0]) and np.array_equal(gc, ref[1])


def test_row_field_distance_is_the_distance_to_the_nearest_cells_square():
    """RowField through the tiles: a point in a 0.1 m grid with one row cell at (r, c) = (2, 5):
    the horizontal distance is the distance to that cell's square [0.5, 0.6] x [0.2, 0.3],
    and above the canopy the hypotenuse with the height over it."""
    occ = np.zeros((10, 12), bool)
    occ[2, 5] = True
    grid = OccupancyGrid(occ, ~occ, 0.1)
    terrain = TerrainField(HeightField(ElevationModel(np.zeros((3, 3)), 0.0, 0.0, 1.0)))
    rows = RowField(grid, terrain, 1.0)
    x, y = 0.95, 0.73                      # 0.35 m east of the square, 0.43 m north of it
    assert rows.distance_one(x, y, 0.5) == pytest.approx(math.hypot(0.35, 0.43), abs=1e-12)
    assert rows.distance_one(x, y, 1.5) == pytest.approx(math.hypot(math.hypot(0.35, 0.43), 0.5), abs=1e-12)
    d = rows.distance(np.array([[x, y, 0.5], [0.55, 0.25, 0.2], [x, y, 1.5]]))
    assert d == pytest.approx([math.hypot(0.35, 0.43), 0.0, math.hypot(math.hypot(0.35, 0.43), 0.5)], abs=1e-12)


def test_row_field_matches_the_whole_grid_table_on_random_points():
    """RowField.distance and distance_one against the distance computed from the whole
    grid's transform (the table RowField held before), on random points of a row grid."""
    rng = np.random.default_rng(3)
    occ = np.zeros((120, 90), bool)
    occ[:, 4::25] = True                   # rows 2.5 m apart: the corridors' middles tie
    occ[40:44, 30:60] = True
    grid = OccupancyGrid(occ, ~occ, 0.1, origin_xy_m=(-3.0, 2.0), origin_yaw_rad=0.3)
    terrain = TerrainField(HeightField(ElevationModel(np.zeros((3, 3)), -10.0, -10.0, 20.0)))
    rows = RowField(grid, terrain, 1.0)
    ref = _reference(occ)
    pts = np.column_stack([rng.uniform(-6, 12, 4000), rng.uniform(-1, 17, 4000), rng.uniform(0, 2, 4000)])
    c, s = math.cos(0.3), math.sin(0.3)
    dx, dy = pts[:, 0] + 3.0, pts[:, 1] - 2.0
    gx, gy = c * dx + s * dy, -s * dx + c * dy
    r = np.clip(np.floor(gy / 0.1).astype(int), 0, 119)
    k = np.clip(np.floor(gx / 0.1).astype(int), 0, 89)
    rr, cc = ref[0, r, k], ref[1, r, k]
    ex = np.maximum(np.maximum(cc * 0.1 - gx, gx - (cc + 1) * 0.1), 0.0)
    ey = np.maximum(np.maximum(rr * 0.1 - gy, gy - (rr + 1) * 0.1), 0.0)
    hz = np.hypot(ex, ey)
    above = pts[:, 2] - 1.0
    want = np.where(above > 0, np.hypot(hz, np.maximum(above, 0.0)), hz)
    assert np.array_equal(rows.distance(pts), want)
    assert [rows.distance_one(*p) for p in pts[:300]] == want[:300].tolist()
