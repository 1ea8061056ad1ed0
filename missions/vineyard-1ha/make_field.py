"""Writes field.geojson: a ~1 ha vineyard parcel as farm software exports it.

    python missions/vineyard-1ha/make_field.py     # rewrites field.geojson byte for byte

Deterministic. The parcel is drawn in metres east/north of its south-west
corner (the mission's home) and written as WGS-84 longitude/latitude
(RFC 7946) through the local tangent plane (``mavcore.geodesy``):

- ``boundary``: a quadrilateral of 1.05 ha;
- ``exclusion``: a 12 m x 8 m shed inside the parcel;
- ``row``: vine rows running north-south, 2.5 m apart, ending 5 m from the
  boundary (the headlands) and 4 m from the shed;
- ``launch``: a point in the southern headland.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mavcore.geodesy import enu2geodetic

HERE = Path(__file__).resolve().parent
HOME = (44.81, -0.58, 35.0)                     # lat, lon, alt (m AMSL) of the south-west corner
BOUNDARY = [(0.0, 0.0), (118.0, 6.0), (122.0, 92.0), (-4.0, 86.0)]
SHED = [(50.0, 30.0), (62.0, 30.0), (62.0, 38.0), (50.0, 38.0)]
SPACING_M = 2.5
HEADLAND_M = 5.0
SHED_GAP_M = 4.0
LAUNCH = (60.0, 5.0)


def chord_y(poly, x):
    """(y_lo, y_hi) of the vertical line at x inside the convex polygon."""
    ys = []
    for (x1, y1), (x2, y2) in zip(poly, poly[1:] + poly[:1]):
        if (x1 - x) * (x2 - x) <= 0 and x1 != x2:
            ys.append(y1 + (x - x1) * (y2 - y1) / (x2 - x1))
    return (min(ys), max(ys)) if len(ys) >= 2 else None


def rows():
    out = []
    for x in np.arange(2.5, 118.0, SPACING_M):
        c = chord_y(BOUNDARY, x)
        if c is None:
            continue
        lo, hi = c[0] + HEADLAND_M, c[1] - HEADLAND_M
        if hi - lo < 10.0:
            continue
        if SHED[0][0] - SHED_GAP_M <= x <= SHED[1][0] + SHED_GAP_M:
            out += [[(x, lo), (x, SHED[0][1] - SHED_GAP_M)], [(x, SHED[2][1] + SHED_GAP_M), (x, hi)]]
        else:
            out.append([(x, lo), (x, hi)])
    return out


def lonlat(points):
    e = np.array([p[0] for p in points])
    n = np.array([p[1] for p in points])
    lat, lon, _ = enu2geodetic(e, n, 0.0, *HOME)
    return [[round(float(a), 8), round(float(b), 8)] for a, b in zip(np.atleast_1d(lon), np.atleast_1d(lat))]


def feature(role, name, geometry):
    return {"type": "Feature", "properties": {"role": role, "name": name}, "geometry": geometry}


def field_geojson() -> str:
    ring = lonlat(BOUNDARY + BOUNDARY[:1])
    shed = lonlat(SHED + SHED[:1])
    feats = [feature("boundary", "parcel 12", {"type": "Polygon", "coordinates": [ring]}),
             feature("exclusion", "shed", {"type": "Polygon", "coordinates": [shed]})]
    feats += [feature("row", f"row {i + 1}", {"type": "LineString", "coordinates": lonlat(r)})
              for i, r in enumerate(rows())]
    feats.append(feature("launch", "take-off", {"type": "Point", "coordinates": lonlat([LAUNCH])[0]}))
    # one feature per line: readable, and a diff shows which feature changed
    return ('{"type": "FeatureCollection", "features": [\n'
            + ",\n".join(json.dumps(f) for f in feats) + "\n]}\n")


if __name__ == "__main__":
    (HERE / "field.geojson").write_text(field_geojson(), encoding="utf-8")
