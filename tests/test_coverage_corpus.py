"""Coverage on adversarial fields: the planner never fails where a connection exists,
drops only what cannot be reached, covers >= 99 % of the reachable corridors (by the
independent checker of ``missions/corpus.py``) and keeps the safety margin.

The 100-field corpus is ``benchmarks/plan_corpus.py``; here a fast subset and
hand-built cases whose answers are derived from their drawing.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from companion.coverage import plan_coverage
from companion.coverage.freespace import erode_free_space
from companion.coverage.gridpath import aux_path
from mavcore.errors import PlanError
from mavcore.maps.grid import OccupancyGrid
from mavcore.mission.schema import CoverageConfig

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "missions"))
import corpus  # noqa: E402

RES = 0.1


def clearance_m(grid: OccupancyGrid, path_xy_m: np.ndarray, step_m: float = RES / 4) -> float:
    """Smallest distance (m) from the path to a non-free cell centre (``corpus.path_clearance_m``)."""
    return corpus.path_clearance_m(grid, path_xy_m, step_m)


@pytest.mark.parametrize("seed", range(10))
def test_adversarial_field_plans_covers_and_keeps_the_margin(seed):
    f = corpus.draw_field(seed, size_m=45.0 + 3 * seed)
    grid = corpus.grid_of(f)
    plan = plan_coverage(grid, CoverageConfig(line_spacing_m=f.row_spacing_m, safety_margin_m=f.safety_margin_m))
    check = corpus.check_coverage(f, plan.path_xy_m)
    assert check.reachable_samples > 0.3 * check.corridor_samples
    assert check.fraction >= 0.99, (f.kind, check)
    assert clearance_m(grid, plan.path_xy_m) >= f.safety_margin_m - 1e-9
    # every dropped segment is unreachable: no admissible path joins it to the flown ones
    if plan.dropped_segments:
        assert plan.warnings and "cannot be reached" in plan.warnings[0]
        clr = ndimage.distance_transform_edt(np.pad(grid.free, 1))[1:-1, 1:-1] * RES
        lab, _ = ndimage.label(clr >= f.safety_margin_m + RES - 1e-9, structure=np.ones((3, 3), bool))
        r0, c0 = (int(np.floor(v + 0.5)) for v in grid.world_to_cell(*plan.path_xy_m[0]))
        for a, _ in plan.dropped_segments:
            ra, ca = (int(np.floor(v + 0.5)) for v in grid.world_to_cell(*a))
            assert lab[ra, ca] != lab[r0, c0]
    else:
        assert plan.warnings == ()


def _hall(neck_m: float, length_m: float = 40.0):
    """Two 2 m wide lanes (y in [0, 2] and [4, 6] m) 0.1 m cells, separated by a 2 m
    wall (y in [2, 4]) with one opening, ``neck_m`` wide, at x in [L, L + neck]; the
    lanes go on 2 m beyond it. Everything else (the outside) is not free."""
    nx, ny = int(round((length_m + neck_m + 2.0) / RES)), int(round(6.0 / RES))
    free = np.ones((ny, nx), dtype=bool)
    free[int(2.0 / RES): int(4.0 / RES)] = False
    free[int(2.0 / RES): int(4.0 / RES), int(round(length_m / RES)): int(round((length_m + neck_m) / RES))] = True
    return OccupancyGrid(occupied=~free, free=free, resolution_m=RES)


def test_connection_the_long_way_round_through_a_narrow_neck():
    """The lanes meet only through an opening 40 m away, 1.4 m wide: with a 0.5 m margin
    (threshold 0.6 m between cell centres) its admissible cells are those with centres
    0.55..0.85 m into it, four cells. The straight hop across the wall is blocked; the
    connection must go round, at least 2 x 39 m long, and keep the margin everywhere."""
    free = erode_free_space(_hall(1.4), 0.5)
    a = np.array([1.0, 1.0])
    b = np.array([1.0, 5.0])
    path = aux_path(free, a, b, "hall")
    assert np.allclose(path[0], a) and np.allclose(path[-1], b)
    length = float(np.sum(np.hypot(*np.diff(path, axis=0).T)))
    assert length >= 2 * 39.0
    assert path[:, 0].max() >= 40.5                 # it went through the opening
    assert clearance_m(_hall(1.4), path) >= 0.5 - 1e-9
    # 1.0 m wide, admissible centres would need x >= 0.55 and <= 0.45: closed
    closed = erode_free_space(_hall(1.0), 0.5)
    with pytest.raises(PlanError, match="no collision-free connection"):
        aux_path(closed, a, b, "hall")


def test_pocket_closed_off_by_the_margin_is_dropped_with_a_warning():
    """A 20 m x 10 m field with rows along x, and a 6 m x 6 m side room (its own two
    rows) whose door is 0.9 m wide: with a 0.5 m margin the door is closed, so the room's
    segments are dropped, named near the room's centre (x ~ 23, y ~ 5), and the rest
    is planned as usual."""
    nx, ny = int(30 / RES), int(12 / RES)
    occ = np.zeros((ny, nx), dtype=bool)
    free = np.zeros((ny, nx), dtype=bool)
    free[int(1 / RES): int(11 / RES), int(0.5 / RES): int(20 / RES)] = True            # main field
    free[int(2 / RES): int(8 / RES), int(20.5 / RES): int(26.5 / RES)] = True          # the room
    free[int(4.55 / RES): int(5.45 / RES), int(20 / RES): int(20.5 / RES)] = True      # 0.9 m door
    y = (np.arange(ny) + 0.5) * RES
    x = (np.arange(nx) + 0.5) * RES
    X, Y = np.meshgrid(x, y)
    rows_main = (np.abs(((Y - 1.0) % 2.5) - 1.25) > 1.05) & (X > 3) & (X < 17.5) & (Y > 2) & (Y < 10)
    rows_room = (np.abs(Y - 4.0) < 0.2) | (np.abs(Y - 6.0) < 0.2)
    rows_room &= (X > 22) & (X < 25)
    occ |= (rows_main | rows_room) & free
    free &= ~occ
    occ |= ~free
    grid = OccupancyGrid(occupied=occ, free=free, resolution_m=RES, source="room.yaml")
    plan = plan_coverage(grid, CoverageConfig(line_spacing_m=2.5, safety_margin_m=0.5, orientation_deg=0.0))
    assert plan.dropped_segments
    for a, b in plan.dropped_segments:
        assert 20.5 <= min(a[0], b[0]) and max(a[0], b[0]) <= 26.5
    assert len(plan.warnings) == 1 and plan.warnings[0].startswith("room.yaml:")
    assert "(23." in plan.warnings[0] and "not flown" in plan.warnings[0]
    assert np.array(plan.path_xy_m)[:, 0].max() < 20.0
    assert clearance_m(grid, np.array(plan.path_xy_m)) >= 0.5 - 1e-9


def test_independent_checker_on_a_hand_drawn_field():
    """Rows along x at y = 3, 6, 9 m from x = 5 to 25 m in a 30 m x 12 m field: two
    corridors, 20 m each, centre lines y = 4.5 and 7.5 m. A path along one of them covers
    half of the corridor samples; along both, all; a path 1 m off the centre line (more
    than a quarter spacing, 0.75 m) covers none."""
    nx, ny = int(30 / RES), int(12 / RES)
    x = (np.arange(nx) + 0.5) * RES
    y = (np.arange(ny) + 0.5) * RES
    X, Y = np.meshgrid(x, y)
    vine = ((np.abs(Y - 3) <= 0.2) | (np.abs(Y - 6) <= 0.2) | (np.abs(Y - 9) <= 0.2)) & (X >= 5) & (X <= 25)
    pix = np.full((ny, nx), corpus.PIX_FREE, dtype=np.uint8)
    pix[vine] = corpus.PIX_OCCUPIED
    f = corpus.Field(name="hand", kind="hand", pixels=pix[::-1].copy(), origin_xy_m=(0.0, 0.0), resolution_m=RES,
                     row_angle_deg=0.0, row_spacing_m=3.0, row_offset_m=0.0, vine=vine, safety_margin_m=0.5,
                     area_m2=0.0)
    one = corpus.check_coverage(f, np.array([[1.0, 4.5], [29.0, 4.5]]))
    both = corpus.check_coverage(f, np.array([[1.0, 4.5], [29.0, 4.5], [29.0, 7.5], [1.0, 7.5]]))
    off = corpus.check_coverage(f, np.array([[1.0, 5.5], [29.0, 5.5]]))
    # samples every h/2 over 20 m, two corridors
    assert both.reachable_samples == pytest.approx(2 * 20.0 / (RES / 2), abs=4)
    assert both.fraction == 1.0
    assert one.fraction == pytest.approx(0.5, abs=0.01)
    assert off.fraction == 0.0
