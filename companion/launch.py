"""The mission's launch point in ENU (``launch:``, docs/mission.md): ENU metres,
WGS-84 latitude/longitude, or a GeoJSON Point (inline or in a file).

Geodetic forms go through the local tangent plane at ``home``
(``mavcore.geodesy``) at the home's altitude; only x and y are kept (the
take-off starts on the terrain under them).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mavcore.errors import MissionError
from mavcore.geodesy import tangent_plane_enu
from mavcore.inputs import parse_json, read_text


def _point_of_geojson(doc, src: str) -> tuple[float, float]:
    """(lon, lat) of the one Point of a GeoJSON document (or its Point feature with
    ``role: launch``)."""
    points: list[tuple[str, list]] = []

    def geom(g, role):
        if isinstance(g, dict) and g.get("type") == "Point":
            points.append((role, g.get("coordinates")))

    if not isinstance(doc, dict):
        raise MissionError(src, "expected a GeoJSON object")
    if doc.get("type") == "FeatureCollection":
        for f in doc.get("features", []) or []:
            if isinstance(f, dict):
                props = f.get("properties") or {}
                geom(f.get("geometry"), str(props.get("role", "")).lower() if isinstance(props, dict) else "")
    elif doc.get("type") == "Feature":
        props = doc.get("properties") or {}
        geom(doc.get("geometry"), str(props.get("role", "")).lower() if isinstance(props, dict) else "")
    else:
        geom(doc, "")
    named = [c for r, c in points if r == "launch"]
    pick = named if named else [c for _, c in points]
    if len(pick) != 1:
        raise MissionError(src, f"expected one Point (or one with role 'launch') for the launch point, "
                                f"found {len(pick)}")
    c = pick[0]
    try:
        lon, lat = float(c[0]), float(c[1])
    except (TypeError, ValueError, IndexError):
        raise MissionError(src, "malformed Point coordinates (expected [lon, lat])") from None
    if not (-180.0 <= lon <= 180.0 and -90.0 <= lat <= 90.0):
        raise MissionError(src, f"Point coordinates [{lon}, {lat}] are not WGS-84 [lon, lat]")
    return lon, lat


def launch_enu_xy(mission) -> np.ndarray | None:
    """ENU [x, y] (m) of the mission's launch point: ``launch:`` in any of its forms,
    else ``energy.launch_xy_m``; None when neither is given (the planner picks one).

    Raises
    ------
    MissionError
        The launch file is missing or holds no single Point.
    """
    cfg = mission.launch
    if cfg is None:
        e = mission.energy.launch_xy_m
        return None if e is None else np.asarray(e, dtype=float)
    if cfg.enu_m is not None:
        return np.asarray(cfg.enu_m, dtype=float)
    if cfg.lat is not None:
        lon, lat = cfg.lon, cfg.lat
    elif cfg.coordinates is not None:
        lon, lat = cfg.coordinates[0], cfg.coordinates[1]
    else:
        p = Path(mission.base_dir) / cfg.file
        src = f"{mission.source}: key 'launch.file': {p}"
        doc = parse_json(read_text(p, MissionError, "GeoJSON"), str(p), MissionError)
        lon, lat = _point_of_geojson(doc, src)
    h = mission.home
    x, y, _ = tangent_plane_enu(lat, lon, h.alt_m, h.lat, h.lon, h.alt_m)
    return np.array([float(x), float(y)])


def launch_key(mission) -> str:
    """The mission key that gave the launch point (for messages)."""
    return "launch" if mission.launch is not None else "energy.launch_xy_m"
