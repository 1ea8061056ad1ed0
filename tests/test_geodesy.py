"""Geodesy (mavcore/geodesy.py): the local tangent plane through pyproj, checked
against the WGS-84 formulas written out here, and the error of the flat-earth map
it replaced, recorded over 2 km."""

import math

import numpy as np
import pytest

from mavcore import frames, geodesy

A = 6378137.0                      # WGS-84 semi-major axis (m)
F = 1.0 / 298.257223563            # flattening
E2 = F * (2.0 - F)                 # first eccentricity squared
HOME = (44.8, -0.6, 30.0)


def ecef(lat_deg, lon_deg, h_m):
    """Geodetic -> ECEF (m): X = (N + h) cos(lat) cos(lon), Y = (N + h) cos(lat) sin(lon),
    Z = (N (1 - e^2) + h) sin(lat), N = a / sqrt(1 - e^2 sin^2(lat))."""
    la, lo = math.radians(lat_deg), math.radians(lon_deg)
    n = A / math.sqrt(1.0 - E2 * math.sin(la) ** 2)
    return np.array([(n + h_m) * math.cos(la) * math.cos(lo), (n + h_m) * math.cos(la) * math.sin(lo),
                     (n * (1.0 - E2) + h_m) * math.sin(la)])


def enu_by_hand(lat, lon, h, lat0, lon0, h0):
    """ECEF difference rotated into the home's east, north, up axes."""
    la, lo = math.radians(lat0), math.radians(lon0)
    R = np.array([[-math.sin(lo), math.cos(lo), 0.0],
                  [-math.sin(la) * math.cos(lo), -math.sin(la) * math.sin(lo), math.cos(la)],
                  [math.cos(la) * math.cos(lo), math.cos(la) * math.sin(lo), math.sin(la)]])
    return R @ (ecef(lat, lon, h) - ecef(lat0, lon0, h0))


def flat_earth_enu(lat, lon, h, lat0, lon0, h0):
    """The map the project used before: meridian / prime-vertical radii at lat0, z = h - h0."""
    la0 = math.radians(lat0)
    s = math.sin(la0)
    r_n = A / math.sqrt(1.0 - E2 * s * s)
    r_m = A * (1.0 - E2) / (1.0 - E2 * s * s) ** 1.5
    return np.array([math.radians(lon - lon0) * r_n * math.cos(la0), math.radians(lat - lat0) * r_m, h - h0])


POINTS = [(44.8, -0.6, 30.0), (44.8 + 0.018, -0.6 + 0.025, 35.0), (44.8 - 0.013, -0.6 - 0.02, 12.0),
          (44.81, -0.59, 30.0), (44.8, -0.6 + 0.0253, 30.0), (44.818, -0.6, 130.0)]


@pytest.mark.parametrize("p", POINTS)
def test_enu_matches_ecef_by_hand_within_1mm(p):
    got = np.array(geodesy.geodetic2enu(*p, *HOME))
    assert np.max(np.abs(got - enu_by_hand(*p, *HOME))) < 1e-3
    # and through the frames module every caller uses
    assert np.max(np.abs(np.array(frames.geodetic2enu(*p, *HOME)) - enu_by_hand(*p, *HOME))) < 1e-3


def test_round_trip_and_vectorised():
    rng = np.random.default_rng(7)
    xyz = rng.uniform(-2000.0, 2000.0, size=(50, 3))
    lat, lon, alt = geodesy.enu2geodetic(xyz[:, 0], xyz[:, 1], xyz[:, 2], *HOME)
    back = np.column_stack(geodesy.geodetic2enu(lat, lon, alt, *HOME))
    assert np.max(np.abs(back - xyz)) < 1e-6
    for i in range(3):   # scalar calls agree with the vectorised one
        assert geodesy.enu2geodetic(*xyz[i], *HOME) == pytest.approx((lat[i], lon[i], alt[i]), abs=1e-12)


def test_flat_earth_error_over_2km_is_recorded():
    """The flat-earth map's error 2 km from home, against the tangent plane.

    2 km east on the tangent plane, at the home's height: the flat map misses
    the curvature, d^2 / 2N = 0.313 m in height, and the meridians' convergence:
    the point is north of the home's parallel by x^2 tan(lat0) / 2N = 0.311 m,
    which the flat map puts at y = 0. 2 km east and 2 km north together: 0.69 m
    horizontally (recorded, BENCHMARKS.md "h18-fields"). The new map: < 1 mm.
    """
    lat0, lon0, h0 = HOME
    s = math.sin(math.radians(lat0))
    n_radius = A / math.sqrt(1.0 - E2 * s * s)
    lat_e, lon_e, _ = geodesy.enu2geodetic(2000.0, 0.0, 0.0, *HOME)
    true_e = np.array(geodesy.geodetic2enu(lat_e, lon_e, h0, *HOME))
    flat_e = flat_earth_enu(lat_e, lon_e, h0, *HOME)
    assert flat_e[2] - true_e[2] == pytest.approx(2000.0 ** 2 / (2 * n_radius), rel=0.01)           # 0.313 m
    assert float(np.hypot(*(flat_e - true_e)[:2])) == pytest.approx(
        2000.0 ** 2 * math.tan(math.radians(lat0)) / (2 * n_radius), rel=0.02)                    # 0.311 m
    lat_d, lon_d, _ = geodesy.enu2geodetic(2000.0, 2000.0, 0.0, *HOME)
    true_d = np.array(geodesy.geodetic2enu(lat_d, lon_d, h0, *HOME))
    flat_d = flat_earth_enu(lat_d, lon_d, h0, *HOME)
    assert 0.6 < float(np.hypot(*(flat_d - true_d)[:2])) < 0.8                                    # 0.69 m
    assert np.max(np.abs(true_d - enu_by_hand(lat_d, lon_d, h0, *HOME))) < 1e-3


def test_closed_form_tangent_plane_matches_proj_within_1mm_over_2km():
    """``tangent_plane_enu`` (no pyproj) against PROJ's pipeline (``geodetic2enu``) on a 4 km
    square about the home and 200 m of height: the same map to well under 1 mm (it is the same
    exact map; only rounding of ~6.4e6 m ECEF coordinates separates them, ~1e-9 m)."""
    rng = np.random.default_rng(18)
    xyz = np.column_stack([rng.uniform(-2000.0, 2000.0, 400), rng.uniform(-2000.0, 2000.0, 400),
                           rng.uniform(-50.0, 150.0, 400)])
    lat, lon, alt = geodesy.enu2geodetic(xyz[:, 0], xyz[:, 1], xyz[:, 2], *HOME)
    proj = np.column_stack(geodesy.geodetic2enu(lat, lon, alt, *HOME))
    closed = np.column_stack(geodesy.tangent_plane_enu(lat, lon, alt, *HOME))
    assert np.max(np.abs(closed - proj)) < 1e-6           # 1 um: far inside the 1 mm asked
    # the hand-worked formulas above, one point at a time
    for p in POINTS:
        assert np.max(np.abs(np.array(geodesy.tangent_plane_enu(*p, *HOME)) - enu_by_hand(*p, *HOME))) < 1e-6
    # the home maps to the origin, exactly
    assert [float(c) for c in geodesy.tangent_plane_enu(*HOME, *HOME)] == [0.0, 0.0, 0.0]


def test_reading_a_wgs84_field_and_its_launch_point_does_not_import_pyproj():
    """A fresh process loads the bundled GeoJSON parcel, its launch point and its maps (what
    ``companion fly`` reads) without pyproj in ``sys.modules``."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    code = ("import sys; from mavcore.mission import load_mission; from mavcore.maps.field import load_mission_maps; "
            "from companion.launch import launch_enu_xy; m = load_mission(sys.argv[1]); load_mission_maps(m); "
            "launch_enu_xy(m); print('pyproj' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code, str(root / "missions" / "vineyard-1ha" / "mission.yaml")],
                         capture_output=True, text=True, cwd=root, check=True)
    assert out.stdout.strip() == "False"
