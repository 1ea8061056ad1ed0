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
"""

from __future__ import annotations

import threading

import numpy as np

_local = threading.local()


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
