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

import math
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import MapError
from ..inputs import check, clip, count_tokens, limits, name, open_regular, parse_json, read_text
from .dem import bilinear, load_dem
from .gis import lonlat_to_enu
from .grid import ElevationModel, OccupancyGrid
from .ogm import MAX_COORD_M, load_ogm

_TIFF_MAGIC = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")


# --- vector fields -------------------------------------------------------------

def _points(coords) -> np.ndarray:
    """(k, 2) lon/lat of a GeoJSON position list; ValueError unless it is one."""
    a = np.asarray(coords, dtype=float)
    if a.ndim != 2 or a.shape[1] < 2:
        raise ValueError("not a list of positions")
    return a[:, :2]


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
                polys.append((name, [_points(r) for r in c]))
            elif t == "MultiPolygon":
                for p in c:
                    polys.append((name, [_points(r) for r in p]))
            elif t == "LineString":
                lines.append(_points(c))
            elif t == "MultiLineString":
                lines.extend(_points(x) for x in c)
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


def _kml_coords(text: str | None, src: str, budget: list) -> np.ndarray:
    """(k, 2) lon/lat of a KML ``coordinates`` text; ``budget[0]``: vertices still allowed
    (counted before the points are built, so a huge ring costs no memory)."""
    n = count_tokens((text or "").encode("utf-8"))
    budget[0] -= n
    if budget[0] < 0:
        lim = limits()
        check(src, "the number of polygon and line vertices", lim.polygon_vertices - budget[0],
              "polygon_vertices", MapError, lim)
    pts = []
    for tok in (text or "").split():
        parts = tok.split(",")
        try:
            pts.append((float(parts[0]), float(parts[1])))
        except (ValueError, IndexError):
            raise MapError(src, f"bad KML coordinate {tok[:40]!r}") from None
    return np.array(pts, dtype=float).reshape(-1, 2)


def _rings_kml(text: str, src: str):
    budget = [limits().polygon_vertices]
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise MapError(src, f"not valid KML/XML: {clip(exc)}") from None
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
                                ring = _kml_coords(c.text, src, budget)
                                rings.insert(0, ring) if part.tag.endswith("outerBoundaryIs") else rings.append(ring)
                if rings:
                    polys.append((name, rings))
            elif el.tag.endswith("LineString"):
                for c in el:
                    if c.tag.endswith("coordinates"):
                        lines.append(_kml_coords(c.text, src, budget))
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


def polygon_mask(ring: np.ndarray, xc: np.ndarray, yc: np.ndarray, max_crossings: int | None = None,
                 source: str = "", lim=None) -> np.ndarray:
    """Even-odd inside test of the grid of cell centres ``xc`` (cols, increasing) x
    ``yc`` (rows, increasing) against ``ring`` (K, 2): a (rows, cols) bool mask. Pure.

    The same rule as :func:`points_in_polygon` (an edge counts where
    ``(y1 > y) != (y2 > y)`` and the point lies left of its crossing
    ``x1 + (y - y1) (x2 - x1) / (y2 - y1)``), by scanlines: each edge
    crosses a contiguous run of rows (found by ``searchsorted``), each
    crossing toggles the cells left of it, and a reversed cumulative sum of
    the toggles per row gives the parity. Work: O(K log R + crossings + cells).
    """
    rows, cols = yc.size, xc.size
    a = np.asarray(ring, dtype=float)
    b = np.roll(a, -1, axis=0)
    keep = a[:, 1] != b[:, 1]
    x1, y1, x2, y2 = a[keep, 0], a[keep, 1], b[keep, 0], b[keep, 1]
    lo = np.searchsorted(yc, np.minimum(y1, y2), side="left")      # first row with y >= min(y1, y2)
    hi = np.searchsorted(yc, np.maximum(y1, y2), side="left")      # first row with y >= max(y1, y2)
    span = hi - lo
    total = int(span.sum())
    if max_crossings is not None:
        check(source, "the row crossings of the field's polygon edges", total, "raster_crossings", MapError, lim)
    toggles = np.zeros(rows * (cols + 1), dtype=np.uint8)     # counts mod 256: parity is all that matters
    done = 0
    edges = np.flatnonzero(span)
    cum = np.cumsum(span[edges])
    batch = 4_000_000
    while done < edges.size:
        stop = int(np.searchsorted(cum, (cum[done - 1] if done else 0) + batch, side="right"))
        stop = max(stop, done + 1)
        e = edges[done:stop]
        n = span[e]
        k = np.repeat(e, n)
        first = np.repeat(np.cumsum(n) - n, n)
        r = np.repeat(lo[e], n) + (np.arange(k.size) - first)
        y = yc[r]
        xcross = x1[k] + (y - y1[k]) * (x2[k] - x1[k]) / (y2[k] - y1[k])
        # cells j with xc[j] < xcross are toggled: j < searchsorted(xc, xcross, 'left')
        j = np.searchsorted(xc, xcross, side="left")
        np.add.at(toggles, r * (cols + 1) + j, 1)
        done = stop
    t = toggles.reshape(rows, cols + 1)
    # toggles of cell j: the crossings with j < their index; parity of the reversed cumulative sum
    suffix = np.cumsum(t[:, ::-1], axis=1, dtype=np.uint8)[:, ::-1]
    return (suffix[:, 1:] & 1).astype(bool)


def _near_polyline(line: np.ndarray, xc: np.ndarray, yc: np.ndarray, half_width_m: float,
                   out: np.ndarray) -> None:
    """Mark in ``out`` (rows, cols) the cells whose centre is within ``half_width_m`` of
    ``line``; each segment is tested on the cells of its bounding box only."""
    res = (xc[1] - xc[0]) if xc.size > 1 else (yc[1] - yc[0]) if yc.size > 1 else 1.0
    pad = half_width_m + abs(res)
    for (ax, ay), (bx, by) in zip(line[:-1], line[1:]):
        c0 = np.searchsorted(xc, min(ax, bx) - pad, side="left")
        c1 = np.searchsorted(xc, max(ax, bx) + pad, side="right")
        r0 = np.searchsorted(yc, min(ay, by) - pad, side="left")
        r1 = np.searchsorted(yc, max(ay, by) + pad, side="right")
        if c0 >= c1 or r0 >= r1:
            continue
        X, Y = np.meshgrid(xc[c0:c1], yc[r0:r1])
        dx, dy = bx - ax, by - ay
        L2 = dx * dx + dy * dy
        t = np.clip(((X - ax) * dx + (Y - ay) * dy) / L2, 0.0, 1.0) if L2 > 0 else 0.0
        out[r0:r1, c0:c1] |= np.hypot(X - ax - t * dx, Y - ay - t * dy) <= half_width_m


def rasterize_field(boundary: list[np.ndarray], exclusions: list[np.ndarray], rows_xy: list[np.ndarray],
                    resolution_m: float, row_width_m: float, border_m: float, source: str,
                    lim=None) -> OccupancyGrid:
    """Occupancy grid of a vector field in ENU metres (module doc). Pure.

    ``boundary``: outer ring then holes, (k, 2) each; ``exclusions`` and
    ``rows_xy``: rings and polylines. Cells are classified at their centres
    (even-odd rule, :func:`polygon_mask`); a row occupies the cells within
    ``row_width_m / 2`` of its polyline.

    Raises
    ------
    MapError
        More cells than the ``field_cells`` limit, or more edge crossings
        than ``raster_crossings`` (docs/limits.md).
    """
    lim = lim or limits()
    outer = boundary[0]
    x_lo, y_lo = outer.min(axis=0) - border_m
    x_hi, y_hi = outer.max(axis=0) + border_m
    # snapped to whole cells, with a micrometre's slack (coordinates written with
    # a finite number of decimals must not move the grid by a cell)
    x_lo = math.floor(round(x_lo / resolution_m, 4)) * resolution_m
    y_lo = math.floor(round(y_lo / resolution_m, 4)) * resolution_m
    cols = int(math.ceil(round((x_hi - x_lo) / resolution_m, 4)))
    rows = int(math.ceil(round((y_hi - y_lo) / resolution_m, 4)))
    check(source, f"the field rasterised at {resolution_m:g} m ({cols} x {rows} cells)", rows * cols, "field_cells",
          MapError, lim)
    xc = x_lo + (np.arange(cols) + 0.5) * resolution_m
    yc = y_lo + (np.arange(rows) + 0.5) * resolution_m
    budget = dict(max_crossings=lim.raster_crossings, source=source, lim=lim)
    inside = polygon_mask(outer, xc, yc, **budget)
    for hole in boundary[1:]:
        inside &= ~polygon_mask(hole, xc, yc, **budget)
    blocked = ~inside
    for ex in exclusions:
        blocked |= polygon_mask(ex, xc, yc, **budget)
    vine = np.zeros((rows, cols), dtype=bool)
    for line in rows_xy:
        _near_polyline(line, xc, yc, row_width_m / 2, vine)
    free = inside & ~blocked & ~vine
    occ = inside & (blocked | vine)
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
    src = name(p)
    lim = limits()
    text = read_text(p, MapError, "field", lim=lim)
    if p.suffix.lower() == ".kml" or text.lstrip().startswith("<"):
        polys, lines = _rings_kml(text, src)
    else:
        polys, lines = _rings_geojson(parse_json(text, src, MapError, lim), src)
    n_vertices = sum(len(r) for _, rings in polys for r in rings) + sum(len(line) for line in lines)
    check(src, "the number of polygon and line vertices", n_vertices, "polygon_vertices", MapError, lim)
    for r in [r for _, rings in polys for r in rings] + lines:
        if not (np.all(np.abs(r[:, 0]) <= 180) and np.all(np.abs(r[:, 1]) <= 90)):
            raise MapError(src, "coordinates are not WGS-84 longitude/latitude (GeoJSON and KML are)")
    polys = [(n, [r for r in rings if len(r) >= 3]) for n, rings in polys]
    polys = [(n, rings) for n, rings in polys if rings and _polygon_area(rings[0]) > 0]
    if not polys:
        raise MapError(src, "no polygon (with an area) to use as the field boundary")
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
    return rasterize_field(boundary, exclusions, rows_xy, resolution_m, row_width_m, border_m, src, lim)


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
    check(dem.source, f"the DEM rotated by home.heading_deg ({max(nx, 1)} x {max(ny, 1)} cells)",
          max(nx, 1) * max(ny, 1), "dem_cells", MapError)
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
        with open_regular(path, MapError, cap="dem_bytes") as fh:
            return fh.read(4) in _TIFF_MAGIC
    except MapError:
        return False        # load_dem says why


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
