"""A mission's maps in the ENU frame about ``home``: occupancy grid and elevation model.

:func:`load_mission_maps` is the one place the planner and the SITL read maps:

Occupancy grid
    * ``map``: a Nav2 / map_server YAML + image (:mod:`ogm`) in the map's
      local frame;
    * ``field``: a vector field as farm-management software exports it, a
      GeoJSON (RFC 7946, WGS-84 longitude/latitude) or KML file: the largest
      polygon (or the one whose ``role``/name is ``boundary``) is the field,
      every other polygon, and every inner ring of the boundary, is an
      exclusion (a building, a pond: occupied), and line strings are vine
      rows (occupied, ``row_width_m`` wide). It is rasterised at
      ``resolution_m`` (:func:`rasterize_field`, pure): cells inside the
      boundary are free, outside unknown.
Elevation model
    * a local ESRI/GDAL ASCII grid (:mod:`dem`), or
    * a georeferenced raster (:mod:`gis`, the ``gis`` extra): a GeoTIFF, or any
      raster with a ``.prj`` beside it or the mission key ``dem_crs``, or
    * none: a flat field at ``elevation_m`` (m AMSL), or at ``home.alt_m``
      with a warning (:func:`flat_dem`).
Heading
    ``home.heading_deg`` is the compass bearing of the local map files' x
    axis (90 = east, the default). Local files are rotated into ENU: the
    grid's origin pose by ``90 - heading`` degrees, the local DEM resampled
    (:func:`rotate_dem`). Vector fields and georeferenced DEMs are already
    geodetic.
"""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import MapError
from ..textfile import read_text
from .dem import bilinear, load_dem
from .gis import lonlat_to_enu
from .grid import ElevationModel, OccupancyGrid
from .ogm import MAX_COORD_M, load_ogm

#: Most cells a rasterised field may have (a 10 ha field at 0.05 m is 4e7).
MAX_FIELD_CELLS = 60_000_000
_TIFF_MAGIC = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")


# --- vector fields -------------------------------------------------------------

def _rings_geojson(doc, src: str):
    """(polygons, lines): polygons as (name, [outer, holes...]) lon/lat rings, lines as lon/lat arrays."""
    polys, lines = [], []

    def geom(g, name):
        if not isinstance(g, dict):
            return
        t = g.get("type")
        c = g.get("coordinates")
        try:
            if t == "Polygon":
                polys.append((name, [np.asarray(r, float)[:, :2] for r in c]))
            elif t == "MultiPolygon":
                for p in c:
                    polys.append((name, [np.asarray(r, float)[:, :2] for r in p]))
            elif t == "LineString":
                lines.append(np.asarray(c, float)[:, :2])
            elif t == "MultiLineString":
                lines.extend(np.asarray(x, float)[:, :2] for x in c)
            elif t == "GeometryCollection":
                for x in g.get("geometries", []):
                    geom(x, name)
        except (TypeError, ValueError, IndexError):
            raise MapError(src, f"malformed {t} coordinates") from None

    def feature(f):
        props = f.get("properties") or {}
        name = str(props.get("role") or props.get("name") or "").lower() if isinstance(props, dict) else ""
        geom(f.get("geometry"), name)

    if not isinstance(doc, dict):
        raise MapError(src, "expected a GeoJSON object")
    if doc.get("type") == "FeatureCollection":
        for f in doc.get("features", []) or []:
            if isinstance(f, dict):
                feature(f)
    elif doc.get("type") == "Feature":
        feature(doc)
    else:
        geom(doc, "")
    return polys, lines


def _kml_coords(text: str | None, src: str) -> np.ndarray:
    pts = []
    for tok in (text or "").split():
        parts = tok.split(",")
        try:
            pts.append((float(parts[0]), float(parts[1])))
        except (ValueError, IndexError):
            raise MapError(src, f"bad KML coordinate {tok[:40]!r}") from None
    return np.array(pts, dtype=float).reshape(-1, 2)


def _rings_kml(text: str, src: str):
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise MapError(src, f"not valid KML/XML: {exc}") from None
    polys, lines = [], []
    for pm in root.iter():
        if not pm.tag.endswith("Placemark"):
            continue
        name = ""
        for el in pm:
            if el.tag.endswith("name"):
                name = (el.text or "").strip().lower()
        for el in pm.iter():
            if el.tag.endswith("Polygon"):
                rings = []
                for part in el:
                    if part.tag.endswith("outerBoundaryIs") or part.tag.endswith("innerBoundaryIs"):
                        for c in part.iter():
                            if c.tag.endswith("coordinates"):
                                ring = _kml_coords(c.text, src)
                                rings.insert(0, ring) if part.tag.endswith("outerBoundaryIs") else rings.append(ring)
                if rings:
                    polys.append((name, rings))
            elif el.tag.endswith("LineString"):
                for c in el:
                    if c.tag.endswith("coordinates"):
                        lines.append(_kml_coords(c.text, src))
    return polys, lines


def points_in_polygon(x: np.ndarray, y: np.ndarray, ring: np.ndarray) -> np.ndarray:
    """Even-odd point in polygon: x, y broadcast; ring (K, 2). Vectorised over the points,
    a loop over the ring's edges."""
    inside = np.zeros(np.broadcast(x, y).shape, dtype=bool)
    a = ring
    b = np.roll(ring, -1, axis=0)
    for (x1, y1), (x2, y2) in zip(a, b):
        if y1 == y2:
            continue
        crosses = (y1 > y) != (y2 > y)
        xc = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
        inside ^= crosses & (x < xc)
    return inside


def _polygon_area(ring: np.ndarray) -> float:
    x, y = ring[:, 0], ring[:, 1]
    return abs(float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))) / 2.0


def rasterize_field(boundary: list[np.ndarray], exclusions: list[np.ndarray], rows_xy: list[np.ndarray],
                    resolution_m: float, row_width_m: float, border_m: float, source: str) -> OccupancyGrid:
    """Occupancy grid of a vector field in ENU metres (module doc). Pure.

    ``boundary``: outer ring then holes, (k, 2) each; ``exclusions`` and
    ``rows_xy``: rings and polylines. Cells are classified at their centres;
    a row occupies the cells within ``row_width_m / 2`` of its polyline.
    """
    outer = boundary[0]
    x_lo, y_lo = outer.min(axis=0) - border_m
    x_hi, y_hi = outer.max(axis=0) + border_m
    # snapped to whole cells, with a micrometre's slack (coordinates written with
    # a finite number of decimals must not move the grid by a cell)
    x_lo = math.floor(round(x_lo / resolution_m, 4)) * resolution_m
    y_lo = math.floor(round(y_lo / resolution_m, 4)) * resolution_m
    cols = int(math.ceil(round((x_hi - x_lo) / resolution_m, 4)))
    rows = int(math.ceil(round((y_hi - y_lo) / resolution_m, 4)))
    if rows * cols > MAX_FIELD_CELLS:
        raise MapError(source, f"the field rasterised at {resolution_m:g} m is {cols} x {rows} cells "
                               f"(more than {MAX_FIELD_CELLS}); use a coarser field.resolution_m")
    xc = x_lo + (np.arange(cols) + 0.5) * resolution_m
    yc_all = y_lo + (np.arange(rows) + 0.5) * resolution_m
    inside = np.zeros((rows, cols), dtype=bool)
    blocked = np.zeros((rows, cols), dtype=bool)

    def window(pts: np.ndarray, pad_m: float):
        """Row and column slices of the cells whose centres may lie within pad_m of pts' box."""
        c0 = max(0, int(math.floor((pts[:, 0].min() - pad_m - x_lo) / resolution_m)) - 1)
        c1 = min(cols, int(math.ceil((pts[:, 0].max() + pad_m - x_lo) / resolution_m)) + 1)
        r0 = max(0, int(math.floor((pts[:, 1].min() - pad_m - y_lo) / resolution_m)) - 1)
        r1 = min(rows, int(math.ceil((pts[:, 1].max() + pad_m - y_lo) / resolution_m)) + 1)
        return slice(r0, max(r0, r1)), slice(c0, max(c0, c1))

    # every shape is evaluated only over the cells of its bounding box (a 1 ha
    # field has ~10^6 cells and ~50 rows: a row touches 1 % of them)
    chunk = max(1, 2_000_000 // max(cols, 1))
    for r0 in range(0, rows, chunk):
        X, Y = np.meshgrid(xc, yc_all[r0: r0 + chunk])
        ins = points_in_polygon(X, Y, outer)
        for hole in boundary[1:]:
            ins &= ~points_in_polygon(X, Y, hole)
        inside[r0: r0 + X.shape[0]] = ins
    for ex in exclusions:
        rs, cs = window(ex, 0.0)
        X, Y = np.meshgrid(xc[cs], yc_all[rs])
        blocked[rs, cs] |= points_in_polygon(X, Y, ex)
    half = row_width_m / 2
    for line in rows_xy:
        for a, b in zip(line[:-1], line[1:]):
            (ax, ay), (bx, by) = a, b
            rs, cs = window(np.array([a, b]), half)
            X, Y = np.meshgrid(xc[cs], yc_all[rs])
            dx, dy = bx - ax, by - ay
            L2 = dx * dx + dy * dy
            t = np.clip(((X - ax) * dx + (Y - ay) * dy) / L2, 0.0, 1.0) if L2 > 0 else 0.0
            blocked[rs, cs] |= np.hypot(X - ax - t * dx, Y - ay - t * dy) <= half
    free = inside & ~blocked
    occ = inside & blocked
    return OccupancyGrid(occupied=occ, free=free, resolution_m=resolution_m, origin_xy_m=(x_lo, y_lo),
                         source=source)


def load_field(path: str | Path, home: tuple[float, float, float], resolution_m: float, row_width_m: float,
               border_m: float = 2.0) -> OccupancyGrid:
    """Read a GeoJSON or KML field and rasterise it in ENU about ``home`` (module doc).

    Raises
    ------
    MapError
        Missing or malformed file, no polygon, a degenerate boundary.
    """
    p = Path(path)
    src = str(p)
    text = read_text(p, MapError, "field")
    if p.suffix.lower() == ".kml" or text.lstrip().startswith("<"):
        polys, lines = _rings_kml(text, src)
    else:
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise MapError(f"{src}: line {exc.lineno}", f"not valid JSON: {exc.msg}") from None
        polys, lines = _rings_geojson(doc, src)
    polys = [(n, [r for r in rings if len(r) >= 3]) for n, rings in polys]
    polys = [(n, rings) for n, rings in polys if rings and _polygon_area(rings[0]) > 0]
    if not polys:
        raise MapError(src, "no polygon (with an area) to use as the field boundary")
    for _, rings in polys:
        for r in rings:
            if not (np.all(np.abs(r[:, 0]) <= 180) and np.all(np.abs(r[:, 1]) <= 90)):
                raise MapError(src, "coordinates are not WGS-84 longitude/latitude (GeoJSON and KML are)")
    named = [i for i, (n, _) in enumerate(polys) if n == "boundary"]
    b = named[0] if named else int(np.argmax([_polygon_area(r[0]) for _, r in polys]))

    def enu(ring):
        x, y = lonlat_to_enu(ring[:, 0], ring[:, 1], home)
        return np.column_stack([x, y])

    boundary = [enu(r) for r in polys[b][1]]
    if max(np.abs(boundary[0]).max(), 0) > MAX_COORD_M:
        raise MapError(src, "the field is implausibly far from home")
    exclusions = [enu(rings[0]) for i, (_, rings) in enumerate(polys) if i != b]
    rows_xy = [enu(line) for line in lines if len(line) >= 2]
    return rasterize_field(boundary, exclusions, rows_xy, resolution_m, row_width_m, border_m, src)


# --- rotation of local files ---------------------------------------------------------

def rotate_grid(grid: OccupancyGrid, yaw_rad: float) -> OccupancyGrid:
    """The grid with its origin pose rotated by ``yaw_rad`` about the frame origin."""
    if yaw_rad == 0.0:
        return grid
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    x, y = grid.origin_xy_m
    return replace(grid, origin_xy_m=(c * x - s * y, s * x + c * y), origin_yaw_rad=grid.origin_yaw_rad + yaw_rad)


def rotate_dem(dem: ElevationModel, yaw_rad: float) -> ElevationModel:
    """The DEM rotated by ``yaw_rad`` about the frame origin, resampled (bilinear) on an
    axis-aligned grid of the same cell size covering the rotated extent."""
    if yaw_rad == 0.0:
        return dem
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    x_min, x_max, y_min, y_max = dem.extent_m
    corners = np.array([[x_min, y_min], [x_max, y_min], [x_min, y_max], [x_max, y_max]])
    rx = c * corners[:, 0] - s * corners[:, 1]
    ry = s * corners[:, 0] + c * corners[:, 1]
    cell = dem.cellsize_m
    x0, y0 = rx.min() + 0.5 * cell, ry.min() + 0.5 * cell
    nx = int(math.floor((rx.max() - rx.min()) / cell))
    ny = int(math.floor((ry.max() - ry.min()) / cell))
    X, Y = np.meshgrid(x0 + cell * np.arange(max(nx, 1)), y0 + cell * np.arange(max(ny, 1)))
    # back into the file's frame, then fractional cell-centre indices
    fx, fy = c * X + s * Y, -s * X + c * Y
    h = bilinear(dem.heights_m, (fy - dem.y0_m) / cell, (fx - dem.x0_m) / cell)
    return ElevationModel(heights_m=h, x0_m=float(x0), y0_m=float(y0), cellsize_m=cell, source=dem.source)


# --- the mission's maps --------------------------------------------------------------

def flat_field_warning(mission) -> str | None:
    """One line when the mission has neither ``dem`` nor ``elevation_m``, else None."""
    if mission.dem is not None or mission.elevation_m is not None:
        return None
    return (f"{mission.source}: no 'dem' and no 'elevation_m': the field is taken as flat at "
            f"home.alt_m = {mission.home.alt_m:g} m AMSL")


def is_georeferenced(path: Path, crs: str | None) -> bool:
    """A DEM for :mod:`gis`: a TIFF, a ``.prj`` beside it, or a CRS given by the mission."""
    if crs is not None or path.with_suffix(".prj").exists():
        return True
    try:
        with open(path, "rb") as fh:
            return fh.read(4) in _TIFF_MAGIC
    except OSError:
        return False


def load_mission_maps(mission) -> tuple[OccupancyGrid, ElevationModel]:
    """The mission's occupancy grid and elevation model in ENU about ``home`` (module doc).

    Raises
    ------
    MapError
        From the loaders, naming the file.
    """
    home = mission.home
    home3 = (home.lat, home.lon, home.alt_m)
    yaw = math.radians(90.0 - home.heading_deg)
    if mission.field is not None:
        f = mission.field
        grid = load_field(mission.field_path, home3, f.resolution_m, f.row_width_m, f.border_m)
    else:
        grid = rotate_grid(load_ogm(mission.map_path), yaw)
    return grid, load_mission_dem(mission)


#: Half-size (m) of the flat elevation model of a mission without a DEM: any field.
FLAT_DEM_HALF_SIZE_M = 10_000.0


def flat_dem(height_m: float, source: str) -> ElevationModel:
    """A flat elevation model at map height ``height_m`` covering +-``FLAT_DEM_HALF_SIZE_M``
    about the map origin (2 x 2 cells: the bilinear patch of a constant is that constant)."""
    cell = FLAT_DEM_HALF_SIZE_M
    return ElevationModel(heights_m=np.full((2, 2), float(height_m)), x0_m=-0.5 * cell, y0_m=-0.5 * cell,
                          cellsize_m=cell, source=source)


def load_mission_dem(mission) -> ElevationModel:
    """The mission's elevation model in ENU about ``home`` (``load_mission_maps``'s second half).

    Without ``dem`` the field is flat: at ``elevation_m`` (m AMSL) when given,
    else at ``home.alt_m`` (the planner warns: ``flat_field_warning``).
    """
    home = mission.home
    dem_path = mission.dem_path
    if dem_path is None:
        z = 0.0 if mission.elevation_m is None else float(mission.elevation_m) - home.alt_m
        return flat_dem(z, f"{mission.source}: flat field at {home.alt_m + z:g} m AMSL")
    if is_georeferenced(dem_path, mission.dem_crs):
        from .gis import load_geo_dem

        return load_geo_dem(dem_path, (home.lat, home.lon, home.alt_m), mission.dem_crs)
    return rotate_dem(load_dem(dem_path), math.radians(90.0 - home.heading_deg))
