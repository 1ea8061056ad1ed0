"""Frame conversions: round trips and hand-worked points."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavcore import frames as F


def random_rotations(n: int, seed: int = 0) -> list[np.ndarray]:
    """Uniform random rotations from normalised Gaussian quaternions (built independently of frames.py)."""
    rng = np.random.default_rng(seed)
    out = []
    for q in rng.normal(size=(n, 4)):
        w, x, y, z = q / np.linalg.norm(q)
        # Rodrigues form R = I + 2w[v]x + 2[v]x^2 with v = (x, y, z).
        K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
        out.append(np.eye(3) + 2 * w * K + 2 * K @ K)
    return out


def test_known_points():
    assert F.enu2ned([1, 2, 3]).tolist() == [2, 1, -3]
    assert F.ned2enu([2, 1, -3]).tolist() == [1, 2, 3]
    assert F.flu2frd([1, 2, 3]).tolist() == [1, -2, -3]
    assert F.frd2flu([1, -2, -3]).tolist() == [1, 2, 3]


def test_vector_round_trips_both_ways():
    v = np.random.default_rng(1).normal(size=(20, 3))
    assert np.allclose(F.ned2enu(F.enu2ned(v)), v)
    assert np.allclose(F.enu2ned(F.ned2enu(v)), v)
    assert np.allclose(F.frd2flu(F.flu2frd(v)), v)
    assert np.allclose(F.flu2frd(F.frd2flu(v)), v)


def test_attitude_round_trip_and_consistency():
    for R in random_rotations(20, seed=2):
        R_ned = F.R_enu_flu2ned_frd(R)
        assert np.allclose(F.R_ned_frd2enu_flu(R_ned), R)
        assert np.allclose(R_ned @ R_ned.T, np.eye(3)) and np.linalg.det(R_ned) == pytest.approx(1.0)
        # Rotating a body vector then converting frames = converting then rotating.
        b = np.array([0.3, -1.2, 0.7])
        assert np.allclose(F.enu2ned(R @ b), R_ned @ F.flu2frd(b))


def test_quaternion_matrix_round_trip():
    for R in random_rotations(50, seed=3):
        q = F.rotmat2quat_wxyz(R)
        assert q[0] >= 0 and np.linalg.norm(q) == pytest.approx(1.0)
        assert np.allclose(F.quat_wxyz2rotmat(q), R, atol=1e-12)
    # q and -q are the same rotation.
    q = np.array([0.2, -0.5, 0.7, 0.3])
    assert np.allclose(F.quat_wxyz2rotmat(q), F.quat_wxyz2rotmat(-q))


def test_quaternion_known_rotation():
    # 90 deg about z: [cos 45, 0, 0, sin 45] maps x to y.
    q = [math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)]
    assert np.allclose(F.quat_wxyz2rotmat(q) @ [1, 0, 0], [0, 1, 0])


def test_nose_east_level_is_yaw_90_in_ned():
    # Body FLU aligned with world ENU: the nose (body x) points east.
    roll, pitch, yaw = F.rotmat2euler_zyx(F.R_enu_flu2ned_frd(np.eye(3)))
    assert (roll, pitch) == pytest.approx((0.0, 0.0), abs=1e-12)
    assert yaw == pytest.approx(math.pi / 2)
    assert F.yaw_enu2ned(0.0) == pytest.approx(math.pi / 2)
    assert F.yaw_ned2enu(math.pi / 2) == pytest.approx(0.0)


def test_euler_round_trip():
    rng = np.random.default_rng(4)
    for roll, pitch, yaw in rng.uniform([-3, -1.5, -3], [3, 1.5, 3], size=(20, 3)):
        R = F.euler_zyx2rotmat(roll, pitch, yaw)
        assert F.rotmat2euler_zyx(R) == pytest.approx((roll, pitch, yaw), abs=1e-9)


def test_geodetic_round_trip_and_scale():
    lat0, lon0, alt0 = 44.8, -0.6, 30.0
    for x, y, z in np.random.default_rng(5).uniform(-2000, 2000, size=(10, 3)):
        lat, lon, alt = F.enu2geodetic(x, y, z, lat0, lon0, alt0)
        assert F.geodetic2enu(lat, lon, alt, lat0, lon0, alt0) == pytest.approx((x, y, z), abs=1e-6)
    # 1 m north is about 1/111 km of latitude (1 deg of latitude ~ 111.1 km at 45 deg).
    lat, lon, alt = F.enu2geodetic(0.0, 1.0, 0.0, lat0, lon0, alt0)
    assert lat - lat0 == pytest.approx(1.0 / 111_100.0, rel=3e-3)
    assert lon == pytest.approx(lon0, abs=1e-12) and alt == pytest.approx(alt0, abs=1e-6)
    # 1 m east is 1/(111.3 km * cos(lat)) degrees of longitude.
    _, lon, _ = F.enu2geodetic(1.0, 0.0, 0.0, lat0, lon0, alt0)
    assert lon - lon0 == pytest.approx(1.0 / (111_320.0 * math.cos(math.radians(lat0))), rel=3e-3)
