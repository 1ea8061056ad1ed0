"""Margins from the airframe (companion/margins.py): the plan keeps the safety margin
from the vehicle's surface, i.e. airframe radius + margin from its centre, measured
here independently on the map (scipy's exact distance transform, a KD-tree of the
non-free cells); a margin below the airframe radius is planned with a warning naming
both values; the export tolerances follow their documented rules."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial import cKDTree

from companion import margins
from mavcore.mission import load_mission

ROOT = Path(__file__).resolve().parents[1]
RECT = ROOT / "missions" / "flat-rectangle" / "mission.yaml"
R_DEFAULT = 0.315 + 0.127          # vehicle.arm_m + a 10-inch propeller


@pytest.fixture(scope="module")
def rect():
    from companion.planner import plan_mission

    mission = load_mission(RECT)
    return mission, plan_mission(mission)


def _nonfree_xy(grid):
    r, c = np.nonzero(~(grid.free & ~grid.occupied))
    x, y = grid.cell_to_world(r, c)
    return np.column_stack([x, y])


def test_launch_point_keeps_radius_plus_margin_from_every_non_free_cell(rect):
    """The default launch point is the admissible cell nearest the free centroid; on
    flat-rectangle the centroid is on a row (generate.py), so the launch point sits at
    the edge of the admissible space: exactly where the rule binds."""
    mission, plan = rect
    grid = plan.grid
    need = R_DEFAULT + mission.coverage.safety_margin_m
    edt = ndimage.distance_transform_edt(grid.free & ~grid.occupied) * grid.resolution_m   # to non-free centres
    r, c = grid.world_to_cell(*plan.sorties.launch_xy_m)
    d = float(edt[int(r), int(c)])
    assert d >= need
    assert d < need + 0.3           # it does bind: the launch point is near the eroded edge


def test_path_and_transits_keep_radius_plus_margin(rect):
    mission, plan = rect
    need = R_DEFAULT + mission.coverage.safety_margin_m
    tree = cKDTree(_nonfree_xy(plan.grid))
    for s in plan.sorties.sorties:
        p = np.asarray(s.path_xy_m)
        dense = np.vstack([np.linspace(a, b, max(2, int(np.hypot(*(b - a)) / 0.02))) for a, b in zip(p[:-1], p[1:])])
        assert tree.query(dense)[0].min() >= need - 1e-9


def test_margin_below_the_airframe_radius_warns_with_both_values(rect, capsys):
    from companion.planner import plan_mission

    mission, _ = rect
    thin = dataclasses.replace(mission, coverage=dataclasses.replace(mission.coverage, safety_margin_m=0.3))
    plan = plan_mission(thin)
    w = [x for x in plan.warnings if "safety_margin_m" in x]
    assert len(w) == 1 and "0.3 m" in w[0] and "0.442 m" in w[0] and "0.742 m" in w[0]
    # the thin margin is still kept from the surface: 0.742 m from the centre
    tree = cKDTree(_nonfree_xy(plan.grid))
    r, c = plan.grid.world_to_cell(*plan.sorties.launch_xy_m)
    assert tree.query(np.asarray(plan.sorties.launch_xy_m))[0] >= R_DEFAULT + 0.3
    assert margins.margin_warning(mission) is None                     # 0.45 >= 0.442: no warning


def test_body_radius_overrides_the_vehicle():
    m = load_mission(RECT)
    assert margins.mission_airframe_radius_m(m) == pytest.approx(R_DEFAULT)
    big = dataclasses.replace(m, replan=dataclasses.replace(m.replan, body_radius_m=0.6))
    assert margins.planning_clearance_m(big) == pytest.approx(0.6 + m.coverage.safety_margin_m)


def test_acceptance_radius_rule():
    # w / 3 binds for a small vehicle, w / 2 - R for a big one; never below the floor
    assert margins.acceptance_radius_m(3.0, 0.2) == pytest.approx(1.0)
    assert margins.acceptance_radius_m(2.1, R_DEFAULT) == pytest.approx(1.05 - R_DEFAULT)
    assert margins.acceptance_radius_m(1.0, 0.49) == margins.MIN_ACCEPTANCE_RADIUS_M
    assert margins.corridor_width_m(2.5, 0.4) == pytest.approx(2.1)


def test_corridor_width_measured_on_a_map(rect):
    """flat-rectangle's rows are 0.4 m wide strips 2.5 m apart (generate.py), classified
    at the 0.1 m cells' centres: 4 or 5 cells (0.4 or 0.5 m) wide, so the corridor
    measured on the map is 2.1 or 2.0 m."""
    _, plan = rect
    w = plan.margins.corridor_width_m
    assert w == pytest.approx(2.1, abs=1e-6) or w == pytest.approx(2.0, abs=1e-6)
    assert plan.margins.acceptance_radius_m <= plan.margins.corridor_width_m / 3.0


def test_fence_margin_rule():
    assert margins.fence_margin_m("rtk", 0.5) == pytest.approx(0.6)
    assert margins.fence_margin_m("gnss", 0.5) == pytest.approx(3.5)
    assert margins.fence_margin_m(1.2, 0.3) == pytest.approx(1.5)
