"""WGS-84 geodetic <-> local ENU about a home point, through pyproj (PROJ).

The local frame of a mission is the **local tangent plane** at ``home``
(docs/frames.md, "Geodetic"): geodetic (lat, lon, h) -> ECEF (PROJ's
``cart``) -> ENU (PROJ's ``topocentric``, the rotation of ECEF about the
home's ECEF position). Both steps are exact on the WGS-84 ellipsoid: no
flat-earth shortcut. The inverse is PROJ's inverse of the same pipeline.

Heights: the pipeline needs ellipsoidal heights; the project's altitudes are
"m AMSL". Over a field the geoid undulation is one constant (it cancels in
every difference), so AMSL heights are passed as ellipsoidal ones; the
tangent plane then sits <= 100 m off the ellipsoid, a scale error below
2e-5 (0.03 mm over 2 km).

Why this replaced the flat-earth map (``lat = lat0 + y / R_M``, ``lon = lon0
+ x / (R_N cos lat0)``, ``z = h - h0``): that map drops the curvature of the
earth (z is off by d^2 / 2R, 0.31 m at 2 km) and the convergence of the
meridians (x off by ~x y tan(lat0) / R, ~0.4 m at 2 km and 45 deg);
``tests/test_geodesy.py`` records both figures.

Transformers are built once per home and thread (PROJ objects must not be
shared between threads) and cost ~2 us per point afterwards.

``tangent_plane_enu`` is the forward direction in closed form, the same two
steps written out (geodetic -> ECEF, the ECEF offset from the home rotated
into ENU): field input (GeoJSON/KML rings, a launch point in lat/lon) goes
through it, so neither ``companion plan`` nor ``companion fly`` of a WGS-84
field imports pyproj (~0.1 s) for it. It agrees with PROJ's pipeline to
~1e-9 m over 2 km (ECEF coordinates of ~6.4e6 m rounded to a double;
``tests/test_geodesy.py``).
"""

from __future__ import annotations

import threading

import numpy as np

_local = threading.local()

#: WGS-84 semi-major axis (m) and first eccentricity squared (from 1/f = 298.257223563),
#: as PROJ's ``+ellps=WGS84``.
WGS84_A_M = 6378137.0
WGS84_E2 = (1.0 / 298.257223563) * (2.0 - 1.0 / 298.257223563)


def _ecef(lat_rad, lon_rad, h_m):
    """Geodetic (rad, rad, m above the ellipsoid) -> ECEF (m): N = a / sqrt(1 - e^2 sin^2 lat),
    X = (N + h) cos lat cos lon, Y = (N + h) cos lat sin lon, Z = (N (1 - e^2) + h) sin lat."""
    s = np.sin(lat_rad)
    c = np.cos(lat_rad)
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * s * s)
    return (n + h_m) * c * np.cos(lon_rad), (n + h_m) * c * np.sin(lon_rad), (n * (1.0 - WGS84_E2) + h_m) * s


def tangent_plane_enu(lat_deg, lon_deg, alt_m, lat0_deg: float, lon0_deg: float, alt0_m: float):
    """WGS-84 (lat deg, lon deg, alt m) -> ENU (x east, y north, z up) m about the home, in closed
    form: :func:`geodetic2enu` without PROJ (module doc). Arrays (broadcast together) give arrays."""
    lat = np.radians(np.asarray(lat_deg, float))
    lon = np.radians(np.asarray(lon_deg, float))
    phi0, lam0 = np.radians(float(lat0_deg)), np.radians(float(lon0_deg))
    x, y, z = _ecef(lat, lon, np.asarray(alt_m, float))
    x0, y0, z0 = _ecef(phi0, lam0, float(alt0_m))
    dx, dy, dz = x - x0, y - y0, z - z0
    sp, cp, sl, cl = np.sin(phi0), np.cos(phi0), np.sin(lam0), np.cos(lam0)
    east = -sl * dx + cl * dy
    north = -sp * cl * dx - sp * sl * dy + cp * dz
    up = cp * cl * dx + cp * sl * dy + sp * dz
    return np.asarray(east, float), np.asarray(north, float), np.asarray(up, float)


def _transformer(lat0_deg: float, lon0_deg: float, alt0_m: float):
    """The cached geodetic -> ENU pyproj Transformer of one home (this thread)."""
    cache = getattr(_local, "cache", None)
    if cache is None:
        cache = _local.cache = {}
    key = (float(lat0_deg), float(lon0_deg), float(alt0_m))
    tr = cache.get(key)
    if tr is None:
        import pyproj   # ~0.15 s: imported only when geodesy is needed
        if len(cache) > 32:
            cache.clear()
        tr = pyproj.Transformer.from_pipeline(
            "+proj=pipeline +step +proj=cart +ellps=WGS84 "
            f"+step +proj=topocentric +ellps=WGS84 +lat_0={key[0]!r} +lon_0={key[1]!r} +h_0={key[2]!r}")
        cache[key] = tr
    return tr


def geodetic2enu(lat_deg, lon_deg, alt_m, lat0_deg: float, lon0_deg: float, alt0_m: float):
    """WGS-84 (lat deg, lon deg, alt m) -> ENU (x east, y north, z up) m about the home.

    Scalars give floats, arrays (broadcast together) give arrays.
    """
    if type(lat_deg) is float and type(lon_deg) is float and type(alt_m) is float:
        # one point (the telemetry path, every few frames): the same PROJ call
        # without the array round trip (~2 us instead of ~11 us)
        x, y, z = _transformer(lat0_deg, lon0_deg, alt0_m).transform(lon_deg, lat_deg, alt_m, errcheck=True)
        return float(x), float(y), float(z)
    lat, lon, alt = np.broadcast_arrays(np.asarray(lat_deg, float), np.asarray(lon_deg, float),
                                        np.asarray(alt_m, float))
    x, y, z = _transformer(lat0_deg, lon0_deg, alt0_m).transform(lon, lat, alt, errcheck=True)
    if np.ndim(x) == 0:
        return float(x), float(y), float(z)
    return np.asarray(x, float), np.asarray(y, float), np.asarray(z, float)


def enu2geodetic(x_east_m, y_north_m, z_up_m, lat0_deg: float, lon0_deg: float, alt0_m: float):
    """ENU (m) about the home -> WGS-84 (lat deg, lon deg, alt m); the inverse of :func:`geodetic2enu`."""
    if type(x_east_m) is float and type(y_north_m) is float and type(z_up_m) is float:
        lon, lat, alt = _transformer(lat0_deg, lon0_deg, alt0_m).transform(x_east_m, y_north_m, z_up_m,
                                                                            direction="INVERSE", errcheck=True)
        return float(lat), float(lon), float(alt)
    x, y, z = np.broadcast_arrays(np.asarray(x_east_m, float), np.asarray(y_north_m, float),
                                  np.asarray(z_up_m, float))
    lon, lat, alt = _transformer(lat0_deg, lon0_deg, alt0_m).transform(x, y, z, direction="INVERSE",
                                                                        errcheck=True)
    if np.ndim(lat) == 0:
        return float(lat), float(lon), float(alt)
    return np.asarray(lat, float), np.asarray(lon, float), np.asarray(alt, float)
