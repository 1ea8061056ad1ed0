"""``companion.map_layers``: the rows found on a rotated map, obstacle
footprints, sortie colours and legend, checked by hand."""

from __future__ import annotations

import colorsys
import math
from pathlib import Path

import numpy as np

from companion.map_layers import (LAYER_COLOURS, LEGEND_SORTIES, obstacle_ring_xy, row_lines_xy, sortie_colour,
                                  sortie_legend)
from mavcore.maps import load_ogm
from mavcore.mission.sim import ObstacleConfig

ROOT = Path(__file__).resolve().parents[1]


def test_rows_of_the_tilted_hexagon():
    """missions/generate.py draws its rows at 30 deg, 2.5 m apart."""
    rows = row_lines_xy(load_ogm(ROOT / "missions" / "tilted-hexagon" / "map.yaml"))
    assert len(rows) >= 3
    d = rows[:, 1] - rows[:, 0]
    ang = np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 180
    np.testing.assert_allclose(ang, 30.0, atol=0.5)
    n = np.array([-math.sin(math.radians(30)), math.cos(math.radians(30))])
    offsets = np.sort(rows[:, 0] @ n)
    np.testing.assert_allclose(np.diff(offsets), 2.5, atol=0.1)


def test_obstacle_footprints():
    box = ObstacleConfig(type="box", x=1.0, y=2.0, height=1.0, size_x=4.0, size_y=2.0, yaw_deg=90.0)
    ring = obstacle_ring_xy(box)
    # rotated by 90 deg: 2 m along x, 4 m along y about (1, 2)
    np.testing.assert_allclose(np.sort(ring[:, 0]), [0, 0, 2, 2], atol=1e-12)
    np.testing.assert_allclose(np.sort(ring[:, 1]), [0, 0, 4, 4], atol=1e-12)
    cyl = ObstacleConfig(type="cylinder", x=-1.0, y=0.5, height=1.0, radius=0.3)
    ring = obstacle_ring_xy(cyl)
    np.testing.assert_allclose(np.hypot(ring[:, 0] + 1.0, ring[:, 1] - 0.5), 0.3, atol=1e-12)
    for r in (obstacle_ring_xy(box), ring):       # counter-clockwise: positive shoelace area
        assert np.sum(r[:, 0] * np.roll(r[:, 1], -1) - np.roll(r[:, 0], -1) * r[:, 1]) > 0


def test_sortie_colours_distinct_and_not_the_flown_blue():
    cols = [sortie_colour(i) for i in range(1, 301)]
    assert len(set(cols)) == len(cols)
    assert not set(cols) & set(LAYER_COLOURS.values())
    for c in cols:
        h, s, v = colorsys.rgb_to_hsv(*(int(c[i:i + 2], 16) / 255 for i in (1, 3, 5)))
        assert s < 0.2 or not (0.53 <= h < 0.70), c


def test_sortie_legend():
    assert sortie_legend([1, 2, 3]) == [(1, "sortie 1"), (2, "sortie 2"), (3, "sortie 3")]
    many = sortie_legend(range(1, 104))
    assert len(many) == LEGEND_SORTIES and many[-1] == (0, f"sorties {LEGEND_SORTIES}-103 (a colour each)")
