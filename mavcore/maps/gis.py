"""Georeferenced elevation models (GeoTIFF, GDAL ASCII with a CRS, ...) -> the local ENU frame.

Needs the optional ``gis`` extra (rasterio, pyproj; wheels on PyPI, no system
libraries): ``pip install "vineyard-gnc[gis]"``. The bundled missions do not.

Reprojection (:func:`reproject_to_enu`, pure given the two transforms)
    The mission's map frame is ENU about ``home`` (``mavcore.geodesy``: the
    local tangent plane through pyproj, the same one the exports use to turn
    ENU back into latitude/longitude, so a height read here is put back at
    the same place). A square ENU grid is laid over the DEM's footprint at the DEM's
    own resolution (its smaller pixel size, in metres); every grid centre is
    taken ENU -> WGS-84 (``enu2geodetic``) -> the DEM's CRS (pyproj, always
    x = easting/longitude first) -> fractional pixel (the inverse of the
    raster's affine transform), and the heights are interpolated bilinearly
    between pixel centres. NODATA and points outside the raster are NaN
    (``ElevationModel`` treats them as not covered).
Heights
    The file's heights are taken as metres above mean sea level; the map
    frame's z = 0 is ``home.alt_m`` AMSL, so ``z = h - home.alt_m``. A DEM
    whose CRS has a vertical axis in feet is converted by pyproj's axis unit.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import MapError
from .. import geodesy
from ..inputs import check, limits, name, open_regular
from .dem import MAX_HEIGHT_M, bilinear
from .grid import ElevationModel



def _need_gis(src: str, what: str):
    try:
        import pyproj  # noqa: F401
        import rasterio  # noqa: F401
    except ImportError:
        raise MapError(src, f"{what} needs the gis extra (pip install \"vineyard-gnc[gis]\")") from None


def enu_to_lonlat(x_m: np.ndarray, y_m: np.ndarray, home: tuple[float, float, float]):
    """ENU (m, z = 0) about ``home`` -> (lon_deg, lat_deg) arrays (``mavcore.geodesy``)."""
    lat, lon, _ = geodesy.enu2geodetic(np.asarray(x_m, float), np.asarray(y_m, float), 0.0, *home)
    return lon, lat


def lonlat_to_enu(lon_deg, lat_deg, home: tuple[float, float, float]):
    """(lon_deg, lat_deg) at the home's altitude -> ENU (x_m, y_m) arrays (``mavcore.geodesy``'s
    closed form: reading a field does not import pyproj)."""
    x, y, _ = geodesy.tangent_plane_enu(np.asarray(lat_deg, float), np.asarray(lon_deg, float), home[2], *home)
    return x, y


def reproject_to_enu(z: np.ndarray, inv_affine, to_crs, footprint_lonlat: np.ndarray, cell_m: float,
                     home: tuple[float, float, float], source: str) -> ElevationModel:
    """Resample a raster onto a square ENU grid about ``home`` (module doc).

    Parameters
    ----------
    z : (rows, cols) float
        Heights (m AMSL) in raster order (row 0 = top), NaN for NODATA.
    inv_affine : callable (x, y) -> (col, row)
        Inverse of the raster's affine transform (pixel corner coordinates).
    to_crs : callable (lon, lat) -> (x, y)
        WGS-84 -> the raster's CRS.
    footprint_lonlat : (k, 2)
        Points of the raster's outline (lon, lat) whose ENU bounding box the grid covers.
    cell_m : float
        ENU cell size (m).
    """
    fx, fy = lonlat_to_enu(footprint_lonlat[:, 0], footprint_lonlat[:, 1], home)
    x_lo, x_hi = float(np.min(fx)), float(np.max(fx))
    y_lo, y_hi = float(np.min(fy)), float(np.max(fy))
    nx = int(math.floor((x_hi - x_lo) / cell_m)) + 1
    ny = int(math.floor((y_hi - y_lo) / cell_m)) + 1
    check(source, f"the DEM reprojected to {cell_m:g} m cells ({nx} x {ny}, {nx * cell_m:.0f} m x "
                  f"{ny * cell_m:.0f} m; crop it to the field)", nx * ny, "dem_cells", MapError)
    x0 = x_lo + 0.5 * cell_m
    y0 = y_lo + 0.5 * cell_m
    X, Y = np.meshgrid(x0 + cell_m * np.arange(nx), y0 + cell_m * np.arange(ny))
    lon, lat = enu_to_lonlat(X, Y, home)
    cx, cy = to_crs(lon.ravel(), lat.ravel())
    col, row = inv_affine(np.asarray(cx), np.asarray(cy))
    # pixel centres sit at (i + 0.5): fractional centre index = corner coordinate - 0.5
    h = bilinear(z, np.asarray(row).reshape(X.shape) - 0.5, np.asarray(col).reshape(X.shape) - 0.5)
    if not np.isfinite(h).any():
        raise MapError(source, "the DEM does not cover any point of its own footprint after reprojection")
    return ElevationModel(heights_m=h - home[2], x0_m=x0, y0_m=y0, cellsize_m=cell_m, source=source)


def load_geo_dem(path: str | Path, home: tuple[float, float, float], crs: str | None = None) -> ElevationModel:
    """Read a georeferenced DEM with rasterio and reproject it to ENU about ``home``.

    Parameters
    ----------
    path : path-like
        Any raster GDAL reads (GeoTIFF, GDAL/ESRI ASCII with a ``.prj``, ...).
    home : (lat_deg, lon_deg, alt_m)
        The mission home: origin of the map frame, alt_m AMSL at z = 0.
    crs : str, optional
        The raster's CRS ("EPSG:32631", WKT, ...) when the file has none.

    Raises
    ------
    MapError
        Missing extra, unreadable or corrupt file, no CRS, a CRS pyproj cannot
        transform to WGS-84, heights beyond any terrain.
    """
    src = name(path)
    _need_gis(src, "a georeferenced DEM")
    import pyproj
    import rasterio
    from rasterio.errors import RasterioIOError

    lim = limits()
    open_regular(path, MapError, "elevation model", cap="dem_bytes", lim=lim).close()
    try:
        with rasterio.open(path) as ds:
            check(src, f"the raster's cell count ({ds.width} x {ds.height})", ds.width * ds.height, "dem_cells",
                  MapError, lim)
            band = ds.read(1, masked=True).astype(float)
            transform = ds.transform
            file_crs = ds.crs
            width, height = ds.width, ds.height
    except (RasterioIOError, ValueError, OSError) as exc:
        raise MapError(src, f"cannot read as a raster: {str(exc).splitlines()[0][:200]}") from None
    z = np.where(np.ma.getmaskarray(band), np.nan, np.ma.getdata(band))
    if not np.isfinite(z).any():
        raise MapError(src, "the DEM has no valid height")
    big = np.nanmax(np.abs(z))
    if big > MAX_HEIGHT_M:
        raise MapError(src, f"height value {big:g} m beyond +-{MAX_HEIGHT_M:g} m")
    try:
        the_crs = pyproj.CRS.from_user_input(crs) if crs is not None else (
            pyproj.CRS.from_wkt(file_crs.to_wkt()) if file_crs is not None else None)
    except pyproj.exceptions.CRSError as exc:
        raise MapError(src, f"unusable CRS: {str(exc).splitlines()[0][:200]}") from None
    if the_crs is None:
        raise MapError(src, "the DEM has no coordinate reference system (give the mission key dem_crs, "
                            "e.g. 'EPSG:32631', or a .prj file)")
    try:
        to_crs = pyproj.Transformer.from_crs("EPSG:4326", the_crs, always_xy=True)
        to_wgs = pyproj.Transformer.from_crs(the_crs, "EPSG:4326", always_xy=True)
        # the outline of the raster (pixel corners along the edges) in lon/lat
        k = 16
        t = np.linspace(0.0, 1.0, k)
        edge_c = np.concatenate([t * width, np.full(k, width), (1 - t) * width, np.zeros(k)])
        edge_r = np.concatenate([np.zeros(k), t * height, np.full(k, height), (1 - t) * height])
        ex, ey = transform @ (edge_c, edge_r)
        lon, lat = to_wgs.transform(np.asarray(ex), np.asarray(ey), errcheck=True)
    except pyproj.exceptions.ProjError as exc:
        raise MapError(src, f"cannot transform its CRS ({the_crs.name}) to WGS-84: "
                            f"{str(exc).splitlines()[0][:200]}") from None
    lon, lat = np.asarray(lon), np.asarray(lat)
    if not (np.all(np.isfinite(lon)) and np.all(np.isfinite(lat))):
        raise MapError(src, f"cannot transform its CRS ({the_crs.name}) to WGS-84 (non-finite coordinates)")
    # resolution in metres: the pixel's ground size at the raster's centre
    cx, cy = transform @ (width / 2, height / 2)
    qx, qy = transform @ (width / 2 + 1, height / 2 + 1)
    (lo0, la0), (lo1, la1) = zip(*to_wgs.transform(np.array([cx, qx]), np.array([cy, qy])))
    gx, gy = lonlat_to_enu(np.array([lo0, lo1, lo0]), np.array([la0, la0, la1]), home)
    px_m = abs(float(gx[1] - gx[0]))
    py_m = abs(float(gy[2] - gy[0]))
    cell = max(min(px_m, py_m), 1e-3)
    inv = ~transform

    def inv_affine(x, y):
        c, r = inv @ (x, y)
        return np.asarray(c), np.asarray(r)

    def to_raster_crs(lo, la):
        return to_crs.transform(lo, la)

    home3 = (float(home[0]), float(home[1]), float(home[2]))
    return reproject_to_enu(z, inv_affine, to_raster_crs, np.column_stack([lon, lat]), cell, home3, src)
