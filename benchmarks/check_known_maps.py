#!/usr/bin/env python3
"""The companion's maps built a new way give the same answers as the old way, every cell.

Usage::

    python benchmarks/check_known_maps.py MISSION.yaml [MISSION.yaml ...]

For each mission, on its occupancy grid: the guard's nearest row cell of every
cell (``companion.safety.nearest_cells``, a tile at a time) against scipy's
feature transform of the whole grid (what ``RowField`` held before), and the
replanner's known map (``KnownMap.from_mission``: the eroded free space and the
rows dilated by the tolerance) against ``erode_free_space`` / ``dilate_runs`` on
the whole grid at once. Needs the whole grid's transform in memory (~0.6 GB on a
10 ha field at 0.1 m). Exit 1 on the first difference.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from companion.coverage.freespace import dilate_runs, disk_half_widths  # noqa: E402
from mavcore.maps.field import load_mission_maps  # noqa: E402
from companion.margins import planning_clearance_m  # noqa: E402
from mavcore.mission import load_mission  # noqa: E402
from companion.replan import KnownMap  # noqa: E402
from companion.safety.nearest_cells import NearestCells  # noqa: E402


def whole_grid_erosion(free: np.ndarray, threshold_cells: float) -> np.ndarray:
    """The eroded free cells computed on the whole grid in one dilation (the definition)."""
    return free & ~dilate_runs(~free, disk_half_widths(threshold_cells), outside=True)


def check(path: str) -> bool:
    mission = load_mission(path)
    grid, dem = load_mission_maps(mission)
    occ = np.asarray(grid.occupied, bool)
    ok = True
    if occ.any():
        ref = ndimage.distance_transform_edt(~occ, return_distances=False, return_indices=True).astype(np.int32)
        near = NearestCells(occ)
        T = near._tile
        diff = 0
        for ti in range(-(-occ.shape[0] // T)):
            for tj in range(-(-occ.shape[1] // T)):
                t = near.tile(ti, tj)
                r0, c0 = ti * T, tj * T
                diff += int((t != ref[:, r0:r0 + t.shape[1], c0:c0 + t.shape[2]]).any(axis=0).sum())
        del ref
        print(f"{path}: nearest row cell: {occ.size} cells, {diff} differ")
        ok &= diff == 0
    known = KnownMap.from_mission(mission, grid, dem)
    h = grid.resolution_m
    free = grid.free & ~grid.occupied
    eroded = whole_grid_erosion(free, (planning_clearance_m(mission) + h) / h)
    rows = dilate_runs(occ, disk_half_widths(mission.replan.known_tolerance_m / h + 1.0), outside=False)
    d_e = int((np.asarray(known.free.eroded) != eroded).sum())
    d_r = int((np.asarray(known.known_rows) != rows).sum())
    d_f = int((np.asarray(known.free.free) != free).sum())
    print(f"{path}: known map: eroded {d_e}, known rows {d_r}, free {d_f} cells differ")
    return ok and d_e == 0 and d_r == 0 and d_f == 0


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__)
        return 2
    return 0 if all([check(p) for p in argv]) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
