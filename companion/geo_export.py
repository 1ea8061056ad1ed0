"""GeoJSON (RFC 7946) and KML 2.2 exports of a plan's map layers (docs/maps.md).

Pure: ``MapLayers`` (``companion.map_layers``, ENU metres) in, text out.
Latitude/longitude come from the project's one ENU -> geodetic conversion,
``mavcore.frames.enu2geodetic`` about the mission home, called through the
module so that whatever that function becomes is what the exports use (in one
call on arrays where it takes them, else point by point).

GeoJSON
    A FeatureCollection in WGS 84, positions ``[lon, lat]`` (RFC 7946 section
    3.1.1: longitude first). Positions are 2D: RFC 7946 defines a third
    element as height above the WGS 84 ellipsoid, and the project's altitudes
    are AMSL (``home.alt_m``), so the AMSL altitude of each vertex is given in
    the feature's ``alt_amsl_m`` property instead. Every feature has a
    ``kind``: ``path`` (the whole route's way-points), ``sortie`` (one per
    sortie: ``index``, ``energy_wh``, ``duration_s``, ``colour``), ``launch``
    (a Point), ``fence`` (a Polygon: closed, exterior ring counter-clockwise,
    the right-hand rule of section 3.1.6) and ``row`` (one LineString per
    vine row, ``index``).
KML
    A Document with one Folder per kind (the same features); coordinates
    ``lon,lat,alt`` with the AMSL altitude and ``altitudeMode`` absolute
    (KML's sea-level datum); the launch point and the rows are clamped to
    the ground, the fence is drawn on the ground.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np

from mavcore import frames
from .map_layers import LAYER_COLOURS, MapLayers, sortie_colour

#: Decimals of the written degrees: 1e-8 deg is at most 1.2 mm on the ground.
DEG_DECIMALS = 8
#: Decimals of the written altitudes (m).
ALT_DECIMALS = 3
KML_NS = "http://www.opengis.net/kml/2.2"


def enu_to_lon_lat_alt(p_enu_m: np.ndarray, home: tuple[float, float, float]) -> np.ndarray:
    """(N, 3) ENU (m) -> (N, 3) (lon_deg, lat_deg, alt_m AMSL) through ``frames.enu2geodetic``.

    (N, 2) input is taken at z = 0 (the home altitude).
    """
    p = np.asarray(p_enu_m, dtype=float)
    if p.shape[-1] == 2:
        p = np.column_stack([p.reshape(-1, 2), np.zeros(p.reshape(-1, 2).shape[0])])
    lat0, lon0, alt0 = home
    try:        # one call where the conversion takes arrays (a pyproj transformer does) ...
        lat, lon, alt = frames.enu2geodetic(p[:, 0], p[:, 1], p[:, 2], lat0, lon0, alt0)
        return np.column_stack([np.broadcast_to(np.asarray(c, dtype=float), (p.shape[0],)) for c in (lon, lat, alt)])
    except TypeError:
        pass    # ... else point by point (the flat-earth one takes scalars)
    out = np.empty((p.shape[0], 3))
    for i, (x, y, z) in enumerate(p):
        lat, lon, alt = frames.enu2geodetic(float(x), float(y), float(z), lat0, lon0, alt0)
        out[i] = (lon, lat, alt)
    return out


def _pos(lla: np.ndarray) -> list:
    return [[round(float(lon), DEG_DECIMALS), round(float(lat), DEG_DECIMALS)] for lon, lat, _ in lla]


def _alts(lla: np.ndarray) -> list:
    return [round(float(a), ALT_DECIMALS) for a in lla[:, 2]]


def _ccw_closed(ring: list) -> list:
    """Close a ring and make it counter-clockwise in (lon, lat) (RFC 7946 section 3.1.6)."""
    if ring[0] != ring[-1]:
        ring = ring + [ring[0]]
    a = np.asarray(ring, dtype=float)
    signed2 = float(np.sum(a[:-1, 0] * a[1:, 1] - a[1:, 0] * a[:-1, 1]))
    return ring if signed2 > 0 else ring[::-1]


def _feature(geometry: dict, **props) -> dict:
    return {"type": "Feature", "geometry": geometry, "properties": props}


def geojson_dict(layers: MapLayers) -> dict:
    """The GeoJSON FeatureCollection of ``layers`` (module doc)."""
    h = layers.home
    feats = []
    lla = enu_to_lon_lat_alt(layers.path_enu_m, h)
    feats.append(_feature({"type": "LineString", "coordinates": _pos(lla)}, kind="path", name=layers.name,
                          alt_amsl_m=_alts(lla), colour=LAYER_COLOURS["path"]))
    for s in layers.sorties:
        lla = enu_to_lon_lat_alt(s.p_enu_m, h)
        feats.append(_feature({"type": "LineString", "coordinates": _pos(lla)}, kind="sortie", index=s.index,
                              name=f"sortie {s.index}", energy_wh=round(s.energy_wh, 3),
                              duration_s=round(s.duration_s, 3), alt_amsl_m=_alts(lla),
                              colour=sortie_colour(s.index)))
    if layers.launch_enu_m is not None:
        lla = enu_to_lon_lat_alt(np.asarray(layers.launch_enu_m, float)[None, :], h)
        feats.append(_feature({"type": "Point", "coordinates": _pos(lla)[0]}, kind="launch", name="launch",
                              alt_amsl_m=_alts(lla)[0], colour=LAYER_COLOURS["launch"]))
    if len(layers.fence_xy_m) >= 3:
        ring = _ccw_closed(_pos(enu_to_lon_lat_alt(layers.fence_xy_m, h)))
        feats.append(_feature({"type": "Polygon", "coordinates": [ring]}, kind="fence", name="inclusion fence",
                              colour=LAYER_COLOURS["fence"]))
    for i, row in enumerate(np.asarray(layers.rows_xy_m, float).reshape(-1, 2, 2)):
        feats.append(_feature({"type": "LineString", "coordinates": _pos(enu_to_lon_lat_alt(row, h))},
                              kind="row", index=i + 1, name=f"row {i + 1}", colour=LAYER_COLOURS["rows"]))
    return {"type": "FeatureCollection", "name": layers.name, "features": feats}


def geojson_text(layers: MapLayers) -> str:
    return json.dumps(geojson_dict(layers), allow_nan=False, separators=(",", ":")) + "\n"


def _kml_colour(hex_rgb: str, alpha: int = 255) -> str:
    """'#rrggbb' -> KML's 'aabbggrr'."""
    r, g, b = hex_rgb[1:3], hex_rgb[3:5], hex_rgb[5:7]
    return f"{alpha:02x}{b}{g}{r}"


def _coords_text(lla: np.ndarray, with_alt: bool) -> str:
    f = f"{{:.{DEG_DECIMALS}f}}"
    a = f"{{:.{ALT_DECIMALS}f}}"
    if with_alt:
        return " ".join(f"{f.format(lo)},{f.format(la)},{a.format(al)}" for lo, la, al in lla)
    return " ".join(f"{f.format(lo)},{f.format(la)}" for lo, la, _ in lla)


def kml_text(layers: MapLayers) -> str:
    """The KML 2.2 document of ``layers`` (module doc)."""
    ET.register_namespace("", KML_NS)
    q = (lambda tag: f"{{{KML_NS}}}{tag}")
    root = ET.Element(q("kml"))
    doc = ET.SubElement(root, q("Document"))
    ET.SubElement(doc, q("name")).text = layers.name
    h = layers.home

    def style(sid: str, colour: str, width: float, fill: bool = False):
        st = ET.SubElement(doc, q("Style"), id=sid)
        ls = ET.SubElement(st, q("LineStyle"))
        ET.SubElement(ls, q("color")).text = _kml_colour(colour)
        ET.SubElement(ls, q("width")).text = f"{width:g}"
        ps = ET.SubElement(st, q("PolyStyle"))
        ET.SubElement(ps, q("fill")).text = "1" if fill else "0"

    def placemark(folder, name: str, style_id: str):
        pm = ET.SubElement(folder, q("Placemark"))
        ET.SubElement(pm, q("name")).text = name
        ET.SubElement(pm, q("styleUrl")).text = f"#{style_id}"
        return pm

    def line(pm, lla: np.ndarray, absolute: bool):
        ls = ET.SubElement(pm, q("LineString"))
        ET.SubElement(ls, q("altitudeMode")).text = "absolute" if absolute else "clampToGround"
        ET.SubElement(ls, q("coordinates")).text = _coords_text(lla, absolute)

    style("path", LAYER_COLOURS["path"], 4)
    style("rows", LAYER_COLOURS["rows"], 1.5)
    style("fence", LAYER_COLOURS["fence"], 2)
    style("launch", LAYER_COLOURS["launch"], 1)
    for s in layers.sorties:
        style(f"sortie{s.index}", sortie_colour(s.index), 2)

    folder = ET.SubElement(doc, q("Folder"))
    ET.SubElement(folder, q("name")).text = "path"
    line(placemark(folder, "path", "path"), enu_to_lon_lat_alt(layers.path_enu_m, h), True)
    folder = ET.SubElement(doc, q("Folder"))
    ET.SubElement(folder, q("name")).text = "sorties"
    for s in layers.sorties:
        pm = placemark(folder, f"sortie {s.index}", f"sortie{s.index}")
        ET.SubElement(pm, q("description")).text = f"{s.energy_wh:.1f} Wh, {s.duration_s / 60:.1f} min"
        line(pm, enu_to_lon_lat_alt(s.p_enu_m, h), True)
    if layers.launch_enu_m is not None:
        folder = ET.SubElement(doc, q("Folder"))
        ET.SubElement(folder, q("name")).text = "launch"
        pt = ET.SubElement(placemark(folder, "launch", "launch"), q("Point"))
        ET.SubElement(pt, q("altitudeMode")).text = "clampToGround"
        lla = enu_to_lon_lat_alt(np.asarray(layers.launch_enu_m, float)[None, :], h)
        ET.SubElement(pt, q("coordinates")).text = _coords_text(lla, False)
    if len(layers.fence_xy_m) >= 3:
        folder = ET.SubElement(doc, q("Folder"))
        ET.SubElement(folder, q("name")).text = "fence"
        poly = ET.SubElement(placemark(folder, "inclusion fence", "fence"), q("Polygon"))
        ET.SubElement(poly, q("altitudeMode")).text = "clampToGround"
        ring = ET.SubElement(ET.SubElement(poly, q("outerBoundaryIs")), q("LinearRing"))
        lla = enu_to_lon_lat_alt(layers.fence_xy_m, h)
        ET.SubElement(ring, q("coordinates")).text = _coords_text(np.vstack([lla, lla[:1]]), False)
    folder = ET.SubElement(doc, q("Folder"))
    ET.SubElement(folder, q("name")).text = "rows"
    for i, row in enumerate(np.asarray(layers.rows_xy_m, float).reshape(-1, 2, 2)):
        line(placemark(folder, f"row {i + 1}", "rows"), enu_to_lon_lat_alt(row, h), False)
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
