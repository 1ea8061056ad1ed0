"""Scanline rasterisation of vector fields (mavcore/maps/field.py): the same
cells as the point-by-point even-odd test (``points_in_polygon``, the former
rasteriser, vectorised over cells and looping over edges) on random polygons,
on polygons whose vertices sit exactly on cell centres, and on whole fields
(boundary, hole, exclusion, rows), and fast under the vertex cap."""

from __future__ import annotations

import time

import numpy as np
import pytest

from mavcore.errors import MapError
from mavcore.inputs import Limits
from mavcore.maps.field import points_in_polygon, polygon_mask, rasterize_field


def _grid(rows, cols, res=0.5, x0=-1.0, y0=-1.0):
    return x0 + (np.arange(cols) + 0.5) * res, y0 + (np.arange(rows) + 0.5) * res


@pytest.mark.parametrize("seed", range(40))
def test_polygon_mask_is_the_even_odd_rule_cell_for_cell(seed):
    rng = np.random.default_rng(seed)
    ring = rng.uniform(0, 40, size=(int(rng.integers(3, 60)), 2))
    if seed % 2:
        ring = np.round(ring * 2) / 2 + 0.25          # vertices and edges through cell centres
    xc, yc = _grid(90, 100)
    X, Y = np.meshgrid(xc, yc)
    assert np.array_equal(polygon_mask(ring, xc, yc), points_in_polygon(X, Y, ring))


def _reference_field(boundary, exclusions, rows_xy, res, width, x_lo, y_lo, rows, cols):
    """The former rasteriser: every cell against every edge and every row segment."""
    xc = x_lo + (np.arange(cols) + 0.5) * res
    yc = y_lo + (np.arange(rows) + 0.5) * res
    X, Y = np.meshgrid(xc, yc)
    inside = points_in_polygon(X, Y, boundary[0])
    for hole in boundary[1:]:
        inside &= ~points_in_polygon(X, Y, hole)
    blocked = ~inside
    for ex in exclusions:
        blocked |= points_in_polygon(X, Y, ex)
    vine = np.zeros(X.shape, dtype=bool)
    for line in rows_xy:
        for (ax, ay), (bx, by) in zip(line[:-1], line[1:]):
            dx, dy = bx - ax, by - ay
            L2 = dx * dx + dy * dy
            t = np.clip(((X - ax) * dx + (Y - ay) * dy) / L2, 0.0, 1.0) if L2 > 0 else 0.0
            vine |= np.hypot(X - ax - t * dx, Y - ay - t * dy) <= width / 2
    return inside & ~blocked & ~vine, inside & (blocked | vine)


@pytest.mark.parametrize("res", [0.1, 0.25])
def test_whole_fields_rasterise_as_before(res):
    """The test_gis field (40 m x 20 m, a shed, rows every 2.5 m) turned 20 degrees,
    with a hole and a zig-zag row."""
    c, s = np.cos(0.35), np.sin(0.35)

    def rot(pts):
        p = np.asarray(pts, float)
        return np.column_stack([c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1]])

    outer = rot([(0, 0), (40, 0), (40, 20), (0, 20)])
    hole = rot([(30, 14), (34, 14), (32, 18)])
    shed = rot([(17, 8), (23, 8), (23, 12), (17, 12)])
    rows = [rot([(4, 2.5 * k), (36, 2.5 * k)]) for k in range(1, 8)] + [rot([(2, 1), (5, 3), (8, 1), (11, 3)])]
    g = rasterize_field([outer, hole], [shed], rows, res, 0.4, 2.0, "f")
    rws, cls = g.shape
    free, occ = _reference_field([outer, hole], [shed], rows, res, 0.4, g.origin_xy_m[0], g.origin_xy_m[1], rws, cls)
    assert np.array_equal(g.free, free) and np.array_equal(g.occupied, occ)
    assert g.free.sum() > 0.5 * (40 * 20) / res ** 2          # most of the field is free


def test_a_boundary_of_190k_vertices_is_fast():
    """The former rasteriser took 81 s for 10^6 vertices: under the cap now well under a second."""
    t = np.linspace(0, 2 * np.pi, 190_000, endpoint=False)
    ring = np.column_stack([50 + 40 * np.cos(t) * (1 + 0.05 * np.sin(60 * t)), 50 + 40 * np.sin(t)])
    t0 = time.process_time()
    g = rasterize_field([ring], [], [], 0.1, 0.4, 2.0, "f")
    assert time.process_time() - t0 < 3.0
    # the area agrees with the shoelace formula within a cell per boundary metre
    x, y = ring[:, 0], ring[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    assert abs(g.free.sum() * 0.01 - area) < 0.1 * 2 * np.pi * 42


def test_crossing_cap():
    # the two vertical edges each cross the 100 rows whose centres lie in 0 <= y < 10
    ring = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)
    rasterize_field([ring], [], [], 0.1, 0.4, 2.0, "f", Limits(raster_crossings=200))
    with pytest.raises(MapError, match="is 200, above the limit 199 .COMPANION_MAX_RASTER_CROSSINGS"):
        rasterize_field([ring], [], [], 0.1, 0.4, 2.0, "f", Limits(raster_crossings=199))
