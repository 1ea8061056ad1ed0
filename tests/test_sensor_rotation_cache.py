"""The cache of CUSTOM rangefinder rotations (mavcore.codec.sensor_rotation_flu)
gives exactly the uncached rotation, keyed by the quaternion's bits, and stays bounded."""

from __future__ import annotations

import numpy as np

from mavcore import frames
from mavcore import codec


def test_cached_rotation_equals_the_computed_one():
    rng = np.random.default_rng(5)
    qs = [tuple(float(c) for c in rng.normal(size=4)) for _ in range(400)]
    qs += [(1.0, 0.0, 0.0, 0.0), (1.0, -0.0, 0.0, -0.0), (0.0, 0.0, 0.0, 1.0)]   # signed zeros are other keys
    codec.companion_end._CUSTOM_R_FLU.clear()
    for _ in range(2):                                   # first pass fills the cache, the second reads it
        for q in qs:
            got = codec.sensor_rotation_flu(codec.MAV_SENSOR_ROTATION_CUSTOM, q)
            short = sum(c * c for c in q) < 0.25             # not a rotation: None, as before the cache
            assert got == (None if short else codec.companion_end._sensor_R_flu(frames.quat_wxyz2rotmat(list(q))))
            assert len(codec.companion_end._CUSTOM_R_FLU) <= codec.companion_end._CUSTOM_CACHE_MAX
    assert codec.sensor_rotation_flu(codec.MAV_SENSOR_ROTATION_CUSTOM, (0.0, 0.0, 0.0, 0.0)) is None
    assert codec.sensor_rotation_flu(codec.MAV_SENSOR_ROTATION_CUSTOM, (float("nan"), 0.0, 0.0, 1.0)) is None
