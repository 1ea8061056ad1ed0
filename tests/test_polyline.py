"""``companion.polyline.densify``: hand-worked cases."""

import numpy as np

from companion.polyline import densify


def test_a_metre_in_steps_of_0_3_is_cut_in_four_equal_pieces():
    got = densify(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), 0.3)
    np.testing.assert_allclose(got[:, 2], [0.0, 0.25, 0.5, 0.75, 1.0], atol=1e-15)
    assert np.all(got[:, :2] == 0.0)


def test_every_vertex_once_in_order_and_a_short_segment_left_whole():
    p = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 4.1]])        # 5 m, then 0.1 m
    got = densify(p, 1.0)
    assert len(got) == 5 + 1 + 1
    np.testing.assert_array_equal(got[[0, 5, 6]], p)
    assert np.diff(got, axis=0).shape == (6, 2)
    np.testing.assert_allclose(np.linalg.norm(np.diff(got[:6], axis=0), axis=1), 1.0, atol=1e-12)


def test_a_single_point_is_itself():
    np.testing.assert_array_equal(densify(np.array([[1.0, 2.0, 3.0]]), 0.5), [[1.0, 2.0, 3.0]])
