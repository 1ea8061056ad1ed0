"""ISOA coverage: rows detection, corridors flown once, path in eroded free space.

Every expected number is derived from how the synthetic vineyards are drawn
(row positions, lengths, margins), not copied from the planner's output.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from companion.coverage import detect_row_spacing, plan_coverage
from mavcore.errors import PlanError
from mavcore.maps.grid import OccupancyGrid
from mavcore.mission.schema import CoverageConfig

RES = 0.1
# A real SLAM map of a simulated vineyard (LCAS bacchus_lcas, MIT; see its README).
LCAS = Path(__file__).resolve().parents[1] / "missions" / "lcas-stage0" / "vineyard_stage0_map.yaml"


def vineyard(angle_deg=0.0, n_rows=5, spacing=3.0, length=20.0, width=0.3, head=4.0, border=1.0,
             obstacle=None, origin=(-7.0, 4.0)):
    """Rows of vines centred in a field; everything outside the field is occupied.

    Row k (k = 0..n_rows-1) is the band |d - o_k| <= width/2, |t| <= length/2,
    o_k = (k - (n_rows-1)/2) spacing, in a frame (t along the rows, d across)
    centred at ``centre`` and rotated by ``angle_deg``. The free field is
    |t| <= length/2 + head, |d| <= (n_rows-1) spacing/2 + head.
    ``obstacle`` = (t, d, radius): a disc in the same frame.
    """
    half_t = length / 2 + head
    half_d = (n_rows - 1) * spacing / 2 + head
    n = int(np.ceil(2 * np.hypot(half_t + border, half_d + border) / RES)) + 4
    g = (np.arange(n) + 0.5) * RES
    X, Y = np.meshgrid(g, g)
    centre = np.array([n * RES / 2, n * RES / 2])
    a = np.deg2rad(angle_deg)
    t = (X - centre[0]) * np.cos(a) + (Y - centre[1]) * np.sin(a)
    d = -(X - centre[0]) * np.sin(a) + (Y - centre[1]) * np.cos(a)
    offsets = (np.arange(n_rows) - (n_rows - 1) / 2) * spacing
    occ = np.zeros((n, n), dtype=bool)
    for o in offsets:
        occ |= (np.abs(d - o) <= width / 2) & (np.abs(t) <= length / 2)
    if obstacle is not None:
        ot, od, r = obstacle
        occ |= np.hypot(t - ot, d - od) <= r
    field = (np.abs(t) <= half_t) & (np.abs(d) <= half_d)
    occ |= ~field
    grid = OccupancyGrid(occupied=occ, free=field & ~occ, resolution_m=RES, origin_xy_m=origin)
    centre_world = centre + np.asarray(origin)
    return grid, dict(offsets=offsets, centre=centre_world, a=a, half_t=half_t, length=length,
                      spacing=spacing, width=width)


def to_row_frame(xy, info):
    """World points -> (t, d) in the drawing frame."""
    q = np.asarray(xy, float) - info["centre"]
    a = info["a"]
    return q[..., 0] * np.cos(a) + q[..., 1] * np.sin(a), -q[..., 0] * np.sin(a) + q[..., 1] * np.cos(a)


def angle_diff_deg(a, b):
    return abs((a - b + 90.0) % 180.0 - 90.0)


def nonfree_tree(grid):
    """KD-tree of the centres of non-free cells, including a ring just outside the map."""
    rows, cols = grid.shape
    nf = np.ones((rows + 2, cols + 2), dtype=bool)
    nf[1:-1, 1:-1] = ~grid.free
    r, c = np.nonzero(nf)
    x, y = grid.cell_to_world(r - 1, c - 1)
    return cKDTree(np.column_stack([x, y]))


def dense(path, step):
    out = [path[:1]]
    for p, q in zip(path[:-1], path[1:]):
        n = max(2, int(np.ceil(np.hypot(*(q - p)) / step)) + 1)
        s = np.linspace(0.0, 1.0, n)[1:, None]
        out.append((1 - s) * p + s * q)
    return np.vstack(out)


@pytest.mark.parametrize("angle", [0.0, 30.0, 117.0])
def test_detect_row_spacing_on_drawn_rows(angle):
    grid, info = vineyard(angle_deg=angle)
    spacing, orientation = detect_row_spacing(grid)
    assert abs(spacing - 3.0) <= RES
    assert angle_diff_deg(orientation, angle) <= 1.0


def test_detect_row_spacing_other_spacing():
    grid, _ = vineyard(spacing=2.5, n_rows=7, angle_deg=-12.0)
    spacing, orientation = detect_row_spacing(grid)
    assert abs(spacing - 2.5) <= RES
    assert angle_diff_deg(orientation, -12.0) <= 1.0


def test_detect_row_spacing_on_lcas_laser_map():
    from mavcore.maps.ogm import load_ogm
    grid = load_ogm(LCAS)
    spacing, orientation = detect_row_spacing(grid)
    # the image shows six east-west rows 60 px (3.0 m) apart
    assert abs(spacing - 3.0) <= 0.3
    assert angle_diff_deg(orientation, 0.0) <= 1.0


def check_corridors_flown_once(plan, info, margin):
    """Each corridor holds exactly one main segment, mid-corridor, along the rows,
    as long as the field minus the eroded ends (corridors open onto the headlands)."""
    offs = info["offsets"]
    mids = 0.5 * (offs[:-1] + offs[1:])
    segs = np.array(plan.main_segments)
    t0, d0 = to_row_frame(segs[:, 0], info)
    t1, d1 = to_row_frame(segs[:, 1], info)
    tm, dm = 0.5 * (t0 + t1), 0.5 * (d0 + d1)
    # the planner's eroded cells keep margin + one cell between their centre
    # and non-free centres; the first non-free centres lie about half a cell
    # beyond the field edge |t| = half_t, and a segment's end sample can lie
    # up to half a cell past its last eroded centre: each end sits at about
    # half_t + h/2 - (margin + h) + h/2 = half_t - margin
    expected_len = 2 * (info["half_t"] - margin)
    for c in mids:
        inside = (np.abs(dm - c) < (info["spacing"] - info["width"]) / 2) & (np.abs(tm) < info["length"] / 2)
        assert inside.sum() == 1, f"corridor at d={c}: {inside.sum()} main segments"
        i = int(np.flatnonzero(inside)[0])
        assert abs(d0[i] - c) <= RES and abs(d1[i] - c) <= RES          # in the middle
        # +-1.5 cells: on a rotated grid the field edge is a staircase
        assert abs(abs(t1[i] - t0[i]) - expected_len) <= 3 * RES
    return tm, dm


@pytest.mark.parametrize("angle", [0.0, 30.0])
def test_every_corridor_flown_once_and_path_in_free_space(angle):
    margin = 0.5
    grid, info = vineyard(angle_deg=angle)
    plan = plan_coverage(grid, CoverageConfig(safety_margin_m=margin))
    assert angle_diff_deg(plan.orientation_deg, angle) <= 1.0
    assert abs(plan.line_spacing_m - 3.0) <= RES
    check_corridors_flown_once(plan, info, margin)
    assert plan.coverage_fraction >= 0.99
    # path clearance from an independent KD-tree of non-free cell centres
    pts = dense(plan.path_xy_m, RES / 4)
    clearance = nonfree_tree(grid).query(pts)[0]
    assert clearance.min() >= margin - RES / 2
    # continuity: the path runs through every main segment in flight order
    path_len = np.sum(np.hypot(*np.diff(plan.path_xy_m, axis=0).T))
    assert plan.path_length_m == pytest.approx(path_len)
    assert np.allclose(plan.path_xy_m[0], plan.main_segments[0][0])
    assert np.allclose(plan.path_xy_m[-1], plan.main_segments[-1][1])


def test_boustrophedon_alternates_direction():
    grid, info = vineyard()
    plan = plan_coverage(grid, CoverageConfig(safety_margin_m=0.5))
    segs = np.array(plan.main_segments)
    direction = np.sign(to_row_frame(segs[:, 1], info)[0] - to_row_frame(segs[:, 0], info)[0])
    assert np.all(direction[1:] == -direction[:-1])
    # lines in offset order, one spacing apart
    d = to_row_frame(segs.mean(axis=1), info)[1]
    assert np.allclose(np.abs(np.diff(d)), 3.0, atol=RES)
    # the auxiliary connections are single straight steps across the headland
    assert all(len(a) == 2 for a in plan.aux_paths)
    assert len(plan.aux_paths) == len(plan.main_segments) - 1


def test_obstacle_in_a_corridor_splits_its_line_and_is_avoided():
    margin, radius = 0.4, 0.1
    grid, info = vineyard(obstacle=(2.0, 1.5, radius))
    plan = plan_coverage(grid, CoverageConfig(safety_margin_m=margin, line_spacing_m=3.0))
    segs = np.array(plan.main_segments)
    t0, d0 = to_row_frame(segs[:, 0], info)
    t1, d1 = to_row_frame(segs[:, 1], info)
    dm = 0.5 * (d0 + d1)
    here = np.flatnonzero(np.abs(dm - 1.5) < 1.0)
    assert len(here) == 2
    lo = np.minimum(t0[here], t1[here])
    hi = np.maximum(t0[here], t1[here])
    order = np.argsort(lo)
    lo, hi = lo[order], hi[order]
    assert hi[0] < lo[1]                     # no overlap: the corridor is flown once
    # the gap is the obstacle eroded by margin + one cell on the line through its centre
    gap = lo[1] - hi[0]
    assert abs(gap - 2 * (radius + margin + RES)) <= 3 * RES
    # the path detours round the obstacle and keeps the margin everywhere
    pts = dense(plan.path_xy_m, RES / 4)
    assert nonfree_tree(grid).query(pts)[0].min() >= margin - RES / 2
    # the other corridors are still flown exactly once
    for c in (-4.5, -1.5, 4.5):
        assert np.sum(np.abs(dm - c) < 1.0) == 1
    # the 1.2 m gap is within half a spacing (1.5 m) of the two pieces' ends,
    # so by the measure's definition the corridor is still fully covered
    assert plan.coverage_fraction >= 0.99


def test_forced_orientation_and_given_spacing():
    grid, info = vineyard()
    plan = plan_coverage(grid, CoverageConfig(line_spacing_m=1.5, orientation_deg=0.0))
    assert plan.orientation_deg == pytest.approx(0.0)
    assert plan.line_spacing_m == 1.5


def test_plan_errors_name_the_map():
    occ = np.zeros((50, 50), dtype=bool)
    empty = OccupancyGrid(occupied=occ, free=np.zeros_like(occ), resolution_m=0.1, source="m.yaml")
    with pytest.raises(PlanError, match="m.yaml"):
        plan_coverage(empty, CoverageConfig(line_spacing_m=1.0))
    open_field = OccupancyGrid(occupied=occ, free=~occ, resolution_m=0.1, source="open.yaml")
    with pytest.raises(PlanError, match="line_spacing_m"):
        plan_coverage(open_field, CoverageConfig())
    with pytest.raises(PlanError):
        detect_row_spacing(open_field)


def test_open_rectangle_beam_runs_along_the_long_side():
    # 30 m x 10 m free rectangle, no rows: fewest/longest segments run east-west
    free = np.zeros((120, 320), dtype=bool)
    free[10:110, 10:310] = True
    grid = OccupancyGrid(occupied=~free, free=free, resolution_m=RES)
    plan = plan_coverage(grid, CoverageConfig(line_spacing_m=2.0, safety_margin_m=0.5))
    assert angle_diff_deg(plan.orientation_deg, 0.0) <= 1.0
    # 10 m wide, eroded by 0.6 m each side: 8.8 m of offsets at 2 m -> 4 or 5 lines
    assert len(plan.main_segments) in (4, 5)
    assert plan.coverage_fraction >= 0.9


# --- row alignment: every corridor flown in its middle along its whole length ----------

def max_offcentre_per_corridor(plan, info):
    """For each corridor of a ``vineyard`` field: (number of main segments in it,
    largest distance (m) of the segment from the corridor's centre line along
    its whole length, covered fraction of the rows' length).

    A segment is straight, so its largest distance from the (straight)
    centre line is reached at one of its ends.
    """
    offs = info["offsets"]
    mids = 0.5 * (offs[:-1] + offs[1:])
    segs = np.array(plan.main_segments)
    t0, d0 = to_row_frame(segs[:, 0], info)
    t1, d1 = to_row_frame(segs[:, 1], info)
    out = []
    for c in mids:
        inside = np.flatnonzero(np.abs(0.5 * (d0 + d1) - c) < (info["spacing"] - info["width"]) / 2)
        worst = max((max(abs(d0[i] - c), abs(d1[i] - c)) for i in inside), default=np.inf)
        half = info["length"] / 2
        cover = sum(max(0.0, min(max(t0[i], t1[i]), half) - max(min(t0[i], t1[i]), -half))
                    for i in inside) / info["length"]
        out.append((len(inside), worst, cover))
    return out


@pytest.mark.parametrize("angle", [23.0, 30.0, 151.3])
def test_beam_follows_tilted_rows_mid_corridor_along_their_length(angle):
    # 40 m rows: a 1 deg error would drift 0.7 m across a corridor
    margin = 0.5
    grid, info = vineyard(angle_deg=angle, n_rows=6, length=40.0)
    rows = detect_row_spacing(grid)
    assert angle_diff_deg(rows.orientation_deg, angle) <= 0.1
    plan = plan_coverage(grid, CoverageConfig(safety_margin_m=margin))
    assert plan.orientation_source == "rows"
    assert plan.orientation_deg == pytest.approx(rows.orientation_deg, abs=1e-9)
    assert plan.isoa_orientation_deg is not None and plan.isoa_score_m > 0
    for n_seg, worst, cover in max_offcentre_per_corridor(plan, info):
        assert n_seg == 1
        assert worst < 1.5 * RES
        assert cover == pytest.approx(1.0)


def test_given_line_spacing_equal_to_rows_also_follows_rows():
    grid, info = vineyard(angle_deg=23.0, n_rows=6, length=40.0)
    plan = plan_coverage(grid, CoverageConfig(safety_margin_m=0.5, line_spacing_m=3.02))
    assert plan.orientation_source == "rows"
    assert angle_diff_deg(plan.orientation_deg, 23.0) <= 0.1
    for n_seg, worst, _ in max_offcentre_per_corridor(plan, info):
        assert n_seg == 1
        # a 0.02 m spacing error accumulates over at most 2.5 spacings from the
        # mean phase: 0.05 m, plus the 1.5-cell tolerance
        assert worst < 1.5 * RES + 0.05


def test_tilted_hexagon_mission_rows_and_beam_match_the_generator():
    import sys
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "missions"))
    import generate
    from mavcore.maps.ogm import load_ogm

    spec = generate.tilted_hexagon()
    root = Path(__file__).resolve().parents[1] / "missions" / spec.name
    grid = load_ogm(root / "map.yaml")
    rows = detect_row_spacing(grid)
    assert angle_diff_deg(rows.orientation_deg, spec.row_angle_deg) <= 0.1
    assert abs(rows.spacing_m - spec.row_spacing_m) <= RES
    plan = plan_coverage(grid, CoverageConfig(line_spacing_m=spec.row_spacing_m,
                                              safety_margin_m=spec.safety_margin_m))
    assert plan.orientation_source == "rows"
    assert angle_diff_deg(plan.orientation_deg, spec.row_angle_deg) <= 0.1
    # lines v = off + (k + 1/2) s between the drawn rows v = off + k s (generator frame)
    a = np.deg2rad(spec.row_angle_deg)
    s, off = spec.row_spacing_m, generate.row_offset(spec)
    poly = np.asarray(spec.polygon_m, float)
    segs = np.array(plan.main_segments)
    u = segs @ np.array([np.cos(a), np.sin(a)])          # (k, 2) along the rows
    v = segs @ np.array([-np.sin(a), np.cos(a)])          # (k, 2) across
    drawn = []
    for k in range(-10, 11):
        lo, hi = generate.chord(poly, off + k * s, spec.row_angle_deg, spec.headland_m - 1e-9)
        if hi - lo >= spec.min_row_length_m:
            drawn.append((k, lo, hi))
    assert len(drawn) >= 3
    for (k, lo0, hi0), (k1, lo1, hi1) in zip(drawn[:-1], drawn[1:]):
        assert k1 == k + 1
        centre = off + (k + 0.5) * s
        here = np.flatnonzero(np.abs(v.mean(axis=1) - centre) < s / 2)
        assert len(here) == 1
        i = here[0]
        assert np.abs(v[i] - centre).max() < 1.5 * RES
        # flown along the whole stretch where both rows exist
        assert u[i].min() <= max(lo0, lo1) and u[i].max() >= min(hi0, hi1)


def test_erosion_matches_the_exact_distance_transform():
    from scipy import ndimage
    from companion.coverage.freespace import erode_free_space

    rng = np.random.default_rng(7)
    occ = rng.random((90, 120)) < 0.02
    unknown = np.zeros_like(occ)
    unknown[:, :4] = True
    free = ~occ & ~unknown
    free[70:, 100:] = False                      # an unknown corner
    for margin in (0.0, 0.25, 0.3, 0.5, 0.72):
        grid = OccupancyGrid(occupied=occ, free=free, resolution_m=RES)
        fs = erode_free_space(grid, margin)
        # independent: scipy's exact EDT, the outside of the map padded as non-free
        edt = ndimage.distance_transform_edt(np.pad(free & ~occ, 1))[1:-1, 1:-1] * RES
        expected = edt >= margin + RES - 1e-9
        assert np.array_equal(fs.eroded, expected), margin


def test_vectorised_visibility_matches_segment_test():
    from companion.coverage.freespace import FreeSpace
    from companion.coverage.gridpath import is_clear, visible_from

    rng = np.random.default_rng(3)
    mask = rng.random((60, 60)) > 0.04
    fs = FreeSpace(eroded=mask, free=mask, resolution_m=RES, threshold_m=RES)
    for _ in range(50):
        a = rng.random(2) * 6
        targets = rng.random((6, 2)) * 7 - 0.5
        assert list(visible_from(fs, a, targets)) == [is_clear(fs, a, b) for b in targets]


def test_farthest_visible_is_the_last_clear_segment_of_a_per_segment_check():
    """The strided pre-test must never drop a clear segment nor keep a blocked one:
    single-cell obstacles that long segments' every-16th samples step over."""
    from companion.coverage.freespace import FreeSpace
    from companion.coverage.gridpath import _STRIDE, _sample_counts, _samples_clear, farthest_visible

    def clear(mask, a, b):        # independent: every half cell, nearest cell, off-map blocked
        n = int(np.ceil(np.hypot(*(b - a)) / (RES / 2))) + 1
        p = a + (np.arange(n) / max(n - 1, 1))[:, None] * (b - a)
        r, c = np.floor(p[:, 1] / RES).astype(int), np.floor(p[:, 0] / RES).astype(int)
        inside = (r >= 0) & (r < mask.shape[0]) & (c >= 0) & (c < mask.shape[1])
        return bool(inside.all() and mask[r, c].all())

    rng = np.random.default_rng(11)
    mask = rng.random((120, 120)) > 0.003
    fs = FreeSpace(eroded=mask, free=mask, resolution_m=RES, threshold_m=RES)
    stepped_over = 0
    for _ in range(200):
        a = rng.random(2) * 12
        targets = rng.random((int(rng.integers(1, 40)), 2)) * 12.5 - 0.25
        ok = [clear(mask, a, b) for b in targets]
        want = int(np.flatnonzero(ok)[-1]) if any(ok) else -1
        assert farthest_visible(fs, a, targets) == want
        coarse = _samples_clear(fs, a, targets, _sample_counts(fs, a, targets), _STRIDE)
        stepped_over += int(np.sum(coarse & ~np.array(ok)))
    assert stepped_over > 100     # blocked segments that only the full test catches


def test_mask_graph_and_min_pool_match_their_reference_constructions():
    """The grid-of-node-numbers graph is the searchsorted graph of the same cells (same
    CSR arrays, so Dijkstra breaks ties the same way); min-pooling is the 4-D ``all``."""
    from companion.coverage.freespace import min_pool
    from companion.coverage.gridpath import NEIGHBOURS_4, cell_graph, mask_graph

    rng = np.random.default_rng(9)
    mask = rng.random((41, 57)) > 0.3
    for kw in ({}, {"neighbours": NEIGHBOURS_4, "edge_cells": 0}):
        g1, order = cell_graph(*np.nonzero(mask), **kw)
        g2, rows, cols = mask_graph(mask, **kw)
        assert np.array_equal(order, np.arange(len(order)))
        assert np.array_equal(np.column_stack([rows, cols]), np.column_stack(np.nonzero(mask)))
        for attr in ("indptr", "indices", "data"):
            assert np.array_equal(getattr(g1, attr), getattr(g2, attr)), (kw, attr)
    for f in (1, 2, 3):
        R, C = -(-mask.shape[0] // f), -(-mask.shape[1] // f)
        padded = np.zeros((R * f, C * f), dtype=bool)
        padded[: mask.shape[0], : mask.shape[1]] = mask
        assert np.array_equal(min_pool(mask, f), padded.reshape(R, f, C, f).all(axis=(1, 3))), f


def test_cell_graph_neighbour_lookups_agree(monkeypatch):
    """The grid-of-node-numbers lookup and the searchsorted lookup give the same CSR
    arrays for shuffled, offset cell lists (both ways of cell_graph)."""
    from companion.coverage import gridpath

    rng = np.random.default_rng(1)
    for _ in range(100):
        mask = rng.random((int(rng.integers(1, 30)), int(rng.integers(1, 30)))) > rng.random()
        rr, cc = np.nonzero(mask)
        if len(rr) == 0:
            continue
        perm = rng.permutation(len(rr))
        rr, cc = rr[perm] + rng.integers(0, 50), cc[perm] + rng.integers(0, 50)
        for kw in ({}, {"neighbours": gridpath.NEIGHBOURS_4, "edge_cells": 0}):
            monkeypatch.setattr(gridpath, "_DENSE_BOX", 10**9)
            g1, o1 = gridpath.cell_graph(rr, cc, **kw)
            monkeypatch.setattr(gridpath, "_DENSE_BOX", 0)
            g2, o2 = gridpath.cell_graph(rr, cc, **kw)
            assert np.array_equal(o1, o2)
            for attr in ("indptr", "indices", "data"):
                assert np.array_equal(getattr(g1, attr), getattr(g2, attr))


def test_lock_step_string_pulling_and_transits_equal_one_at_a_time():
    """simplify_many / paths_to answer every polyline's questions in shared calls: the
    result must be what each gets alone, and every kept hop must be clear (checked
    with the per-segment test)."""
    from companion.coverage.freespace import FreeSpace
    from companion.coverage.gridpath import aux_path, aux_paths, cell_path, is_clear, simplify, simplify_many
    from companion.coverage.transit import build_transit_tree

    rng = np.random.default_rng(4)
    mask = np.ones((150, 150), dtype=bool)
    for _ in range(25):                      # rectangular obstacles
        r, c = rng.integers(0, 140, 2)
        mask[r: r + rng.integers(2, 12), c: c + rng.integers(2, 12)] = False
    mask[[0, -1], :] = mask[:, [0, -1]] = False
    fs = FreeSpace(eroded=mask, free=mask, resolution_m=RES, threshold_m=RES)
    rr, cc = np.nonzero(mask)
    lines = []
    while len(lines) < 12:
        a, b = rng.integers(0, len(rr), 2)
        cells = cell_path(rr, cc, (rr[a], cc[a]), (rr[b], cc[b]))
        if cells is not None and len(cells) > 2:
            lines.append(np.column_stack([(cells[:, 1] + 0.5) * RES, (cells[:, 0] + 0.5) * RES]))
    together = simplify_many(fs, lines)
    for line, got in zip(lines, together):
        assert np.array_equal(got, simplify(fs, line))
        assert np.array_equal(got[[0, -1]], line[[0, -1]])
        assert all(is_clear(fs, p, q) for p, q in zip(got[:-1], got[1:]))
    starts, ends = np.array([x[0] for x in lines]), np.array([x[-1] for x in lines])
    for p, q, got in zip(starts, ends, aux_paths(fs, starts, ends)):
        assert np.array_equal(got, aux_path(fs, p, q))
    tree = build_transit_tree(fs, lines[0][0])
    qs = [line[-1] for line in lines]
    assert tree.distances_m(qs) == [tree.distance_m(q) for q in qs]
    for q, got in zip(qs, tree.paths_to(qs)):
        assert np.array_equal(got, tree.path_to(q))
        assert all(is_clear(fs, p, r) for p, r in zip(got[:-1], got[1:]))


def test_mask_centroid_is_the_mean_of_the_true_cells():
    from mavcore.maps.grid import mask_centroid_rc

    rng = np.random.default_rng(5)
    mask = rng.random((37, 53)) < 0.3
    r, c = np.nonzero(mask)
    assert mask_centroid_rc(mask) == (r.mean(), c.mean())
    assert all(np.isnan(mask_centroid_rc(np.zeros((3, 4), bool))))


def test_lcas_mission_flies_each_detected_corridor_once_inside_free_space():
    """The bundled real SLAM map: rows from sparse laser hits, spacing detected.

    Independent reference: the vine rows are the clusters of occupied cells'
    y (east-west rows, gaps > 1 m between clusters); each corridor between
    two consecutive rows must hold exactly one main segment, near its middle.
    """
    from mavcore.maps.ogm import load_ogm

    grid = load_ogm(LCAS)
    margin = 0.5
    plan = plan_coverage(grid, CoverageConfig(safety_margin_m=margin))
    assert abs(plan.line_spacing_m - 3.0) <= 0.1
    r, c = np.nonzero(grid.occupied)
    x, y = grid.cell_to_world(r, c)
    inside = (np.abs(x) < 10) & (np.abs(y) < 11)      # the vineyard block, not the map's border hits
    ys = np.sort(y[inside])
    rows = [np.median(g) for g in np.split(ys, np.flatnonzero(np.diff(ys) > 1.0) + 1) if g.size > 20]
    assert len(rows) >= 5
    segs = np.array(plan.main_segments)
    seg_y = segs[:, :, 1].mean(axis=1)
    for lo, hi in zip(rows[:-1], rows[1:]):
        mid = 0.5 * (lo + hi)
        between = (seg_y > lo) & (seg_y < hi)
        assert between.sum() == 1, f"corridor {lo:.2f}..{hi:.2f} m: {between.sum()} main segments"
        assert abs(seg_y[between][0] - mid) <= 0.3
    # every path point keeps the margin from any cell that is not free
    path = plan.path_xy_m
    pts = np.concatenate([np.linspace(a, b, max(2, int(np.linalg.norm(b - a) / 0.02)))
                          for a, b in zip(path[:-1], path[1:])])
    nr, nc = np.nonzero(~grid.free)
    nx, ny = grid.cell_to_world(nr, nc)
    near = (np.abs(nx) < 15) & (np.abs(ny) < 15)
    d, _ = cKDTree(np.column_stack([nx[near], ny[near]])).query(pts)
    assert d.min() >= margin - grid.resolution_m / 2


# --- the coverage statistic against hand-derived fractions (issue 7: tolerance mutations) -----

def _corridor_setup():
    """The 5-row vineyard (4 equal corridors, 20 m long), its corridors, eroded space and
    main segments (G frame) of the flown plan."""
    from companion.coverage.corridors import find_corridors
    from companion.coverage.freespace import erode_free_space, world_to_grid
    from companion.coverage.rows import detect_rows

    grid, info = vineyard()
    plan = plan_coverage(grid, CoverageConfig(safety_margin_m=0.5))
    corr = find_corridors(detect_rows(grid))
    free = erode_free_space(grid, 0.5)
    main_g = world_to_grid(grid, np.array(plan.main_segments))
    return grid, info, corr, free, main_g


def test_coverage_fraction_counts_a_missing_corridor():
    """Four corridors of equal length (the rows are drawn 20 m long): flying all but one
    covers 3/4 of their centre lines. A widened distance tolerance (a segment "covers" a
    corridor one spacing away) or a widened direction tolerance would report more."""
    from companion.coverage.corridors import coverage_fraction
    from companion.coverage.freespace import world_to_grid

    grid, info, corr, free, main_g = _corridor_setup()
    assert len(corr.offset_m) == 4
    assert np.ptp(corr.t1_m - corr.t0_m) <= 2 * RES           # equal lengths, as drawn
    assert coverage_fraction(corr, free, main_g, 3.0) == pytest.approx(1.0)
    # the corridor at d = +1.5 m (between the rows at 0 and +3 m) loses its segment
    mid_d = to_row_frame(grid_to_world_pts(grid, main_g.mean(axis=1)), info)[1]
    keep = np.abs(mid_d - 1.5) > 0.5
    assert np.count_nonzero(~keep) == 1
    assert coverage_fraction(corr, free, main_g[keep], 3.0) == pytest.approx(0.75, abs=0.01)
    # a segment across that corridor at 40 deg to the rows is not flown along it: still 3/4
    c = info["centre"]
    a = info["a"] + np.deg2rad(40.0)
    cross = np.array([c + 2.0 * np.array([np.cos(a), np.sin(a)]) + (1.5 * np.array([-np.sin(info["a"]), np.cos(info["a"])])),
                      c - 2.0 * np.array([np.cos(a), np.sin(a)]) + (1.5 * np.array([-np.sin(info["a"]), np.cos(info["a"])]))])
    with_cross = np.concatenate([main_g[keep], world_to_grid(grid, cross)[None]])
    assert coverage_fraction(corr, free, with_cross, 3.0) == pytest.approx(0.75, abs=0.01)
    # the missing corridor flown from its middle (t = 0) to its end (t = 10 m): its samples
    # within half a spacing (1.5 m) of that segment count, i.e. t in [-1.5, 10]:
    # (3 x 20 + 11.5) / 80
    t_half = np.array([[0.0, 1.5], [10.0, 1.5]])
    half_seg = np.array([c + t * np.array([np.cos(info["a"]), np.sin(info["a"])])
                         + dd * np.array([-np.sin(info["a"]), np.cos(info["a"])]) for t, dd in t_half])
    with_half = np.concatenate([main_g[keep], world_to_grid(grid, half_seg)[None]])
    assert coverage_fraction(corr, free, with_half, 3.0) == pytest.approx(71.5 / 80, abs=0.01)


def grid_to_world_pts(grid, gxy):
    from companion.coverage.freespace import grid_to_world
    return grid_to_world(grid, gxy)


def test_coverage_fraction_without_rows_is_the_swept_share_of_the_eroded_space():
    """No rows: the share of eroded cells within half a spacing (plus one cell) of a main
    segment. A 30 m x 10 m open field eroded by 0.6 m is 28.8 m x 8.8 m; one line along
    its middle sweeps a band 2 x (0.5 x 2 m + 0.1 m) = 2.2 m wide: 2.2 / 8.8 = 1/4."""
    from companion.coverage.corridors import coverage_fraction
    from companion.coverage.freespace import erode_free_space

    free = np.zeros((120, 320), dtype=bool)
    free[10:110, 10:310] = True
    grid = OccupancyGrid(occupied=~free, free=free, resolution_m=RES)
    fs = erode_free_space(grid, 0.5)
    y_mid = 6.0                                         # rows 10..110 -> 1.0 .. 11.0 m
    line = np.array([[[1.6, y_mid], [30.4, y_mid]]])
    frac = coverage_fraction(None, fs, line, 2.0)
    assert frac == pytest.approx(2.2 / 8.8, abs=0.02)
