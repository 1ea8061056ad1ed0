"""Elevation model loader: ESRI ASCII grid (``.asc``) in the map's local frame.

Header keys (case-insensitive, one ``key value`` pair per line, any order):
``ncols``, ``nrows``, ``xllcorner`` or ``xllcenter``, ``yllcorner`` or
``yllcenter``, ``cellsize`` (or GDAL's ``dx`` and ``dy`` for rectangular
cells), optional ``NODATA_value``. A grid with ``dx != dy`` is resampled
bilinearly onto square cells of ``min(dx, dy)`` (:func:`resample_square`), so
every ``ElevationModel`` has square cells. Georeferenced DEMs (GeoTIFF, an
``.asc`` with a ``.prj``, any CRS) go through :mod:`mavcore.maps.gis`. ``*llcorner`` is the
outer lower-left corner of the grid, ``*llcenter`` the centre of the
lower-left cell (half a cell further in). Then ``nrows`` rows of ``ncols``
numbers, the first row being the northernmost; the model is flipped so that
row 0 is the south row (``grid.py`` convention). NODATA cells become NaN.
Coordinates are the map's local metric ENU frame.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from ..errors import MapError
from ..inputs import brief, check, count_tokens, limits, name, read_bytes
from .grid import ElevationModel

#: Largest coordinate (m, +-) and height (m, +-) accepted: beyond them the grid is a
#: typo (a local metric frame wider than the Earth, heights beyond any terrain).
MAX_COORD_M = 1.0e7
MAX_HEIGHT_M = 1.0e5

_KEYS = ("ncols", "nrows", "xllcorner", "xllcenter", "yllcorner", "yllcenter", "cellsize", "dx", "dy",
         "nodata_value")


def load_dem(path: str | Path) -> ElevationModel:
    """Load an ESRI ASCII grid.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    ElevationModel
        Heights (rows, cols) with row 0 south, NaN for NODATA; ``x0_m``,
        ``y0_m`` the centre of the south-west cell.

    Raises
    ------
    MapError
        Missing file, bad or missing header key, wrong number of values,
        non-numeric data, non-positive cell size (message names the file).
    """
    p = Path(path)
    src = name(p)
    lim = limits()
    raw = read_bytes(p, MapError, "elevation model", cap="dem_bytes", lim=lim)
    if not raw.isascii():
        bad = next(i for i, c in enumerate(raw) if c >= 128)
        raise MapError(src, f"cannot read as an ASCII grid: byte 0x{raw[bad]:02x} at offset {bad} is not ASCII")

    header: dict[str, float] = {}
    pos, line_no, n = 0, 0, len(raw)
    while pos < n:
        end = raw.find(b"\n", pos)
        end = n if end < 0 else end
        parts = raw[pos:min(end, pos + 200)].decode("ascii").split()
        line_no += 1
        if not parts:
            pos = end + 1
            continue
        key = parts[0].lower()
        if key[0].isdigit() or key[0] in "+-.":
            break  # first data row
        if end - pos > 200:
            raise MapError(f"{src}: line {line_no}", f"header line of {end - pos} characters (expected 'key number')")
        if key not in _KEYS:
            raise MapError(f"{src}: line {line_no}", f"unknown header key {brief(parts[0], 30)} "
                           "(expected ncols, nrows, xllcorner|xllcenter, yllcorner|yllcenter, cellsize or dx and dy, "
                           "NODATA_value)")
        if len(parts) != 2:
            raise MapError(f"{src}: line {line_no}", f"expected '{parts[0]} <number>'")
        if key in header:
            raise MapError(f"{src}: line {line_no}", f"duplicate header key {parts[0]!r}")
        try:
            header[key] = float(parts[1])
        except ValueError:
            raise MapError(f"{src}: line {line_no}",
                           f"{parts[0]} value {brief(parts[1], 30)} is not a number") from None
        if not math.isfinite(header[key]):
            raise MapError(f"{src}: line {line_no}", f"{parts[0]} value must be finite")
        pos = end + 1

    for key in ("ncols", "nrows"):
        if key not in header:
            raise MapError(src, f"header key {key!r} missing")
    if "cellsize" in header and ("dx" in header or "dy" in header):
        raise MapError(src, "header has both cellsize and dx/dy")
    if "cellsize" not in header:
        if "dx" not in header or "dy" not in header:
            raise MapError(src, "header key 'cellsize' missing (or GDAL's 'dx' and 'dy')")
    for axis in ("x", "y"):
        have = [k for k in (f"{axis}llcorner", f"{axis}llcenter") if k in header]
        if len(have) != 1:
            raise MapError(src, f"header needs exactly one of {axis}llcorner / {axis}llcenter")
    ncols, nrows = header["ncols"], header["nrows"]
    for key, v in (("ncols", ncols), ("nrows", nrows)):
        if v != int(v) or v < 1:
            raise MapError(src, f"header {key} must be a positive integer, got {v:g}")
    ncols, nrows = int(ncols), int(nrows)
    check(src, f"the grid's cell count ({ncols} x {nrows})", ncols * nrows, "dem_cells", MapError, lim)
    cell_x = header.get("cellsize", header.get("dx"))
    cell_y = header.get("cellsize", header.get("dy"))
    for key, v in (("cellsize" if "cellsize" in header else "dx", cell_x), ("cellsize" if "cellsize" in header else "dy", cell_y)):
        if v <= 0:
            raise MapError(src, f"header {key} must be > 0, got {v:g}")
    cell = min(cell_x, cell_y)
    x0 = header["xllcenter"] if "xllcenter" in header else header["xllcorner"] + 0.5 * cell_x
    y0 = header["yllcenter"] if "yllcenter" in header else header["yllcorner"] + 0.5 * cell_y

    reach = max(abs(x0), abs(y0)) + math.hypot(nrows * cell_y, ncols * cell_x)
    if reach > MAX_COORD_M:
        raise MapError(src, f"the grid reaches {reach:.3g} m from the frame origin (more than {MAX_COORD_M:g} m; "
                       "check xll*/yll*, cellsize)")
    if cell_x != cell_y:
        nx, ny = square_shape(nrows, ncols, cell_x, cell_y)
        check(src, f"the grid resampled to square {cell:g} m cells ({nx} x {ny})", nx * ny, "dem_cells", MapError, lim)

    body = raw[pos:]
    found = count_tokens(body)
    if found != nrows * ncols:
        raise MapError(src, f"expected {nrows} x {ncols} = {nrows * ncols} values after the header, "
                       f"found {found}")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            z = np.fromstring(body, dtype=float, sep=" ")
        except (ValueError, DeprecationWarning):
            z = None
    if z is None or z.size != nrows * ncols:
        bad = next((t for t in body.split(None, nrows * ncols) if not _is_float(t)), b"?")
        raise MapError(src, f"non-numeric height value {brief(bad.decode('ascii'), 30)}")
    z = z.reshape(nrows, ncols)
    if not np.all(np.isfinite(z)):
        raise MapError(src, "height values must be finite (use NODATA_value for holes)")
    if "nodata_value" in header:
        z[z == header["nodata_value"]] = np.nan
    known = z[~np.isnan(z)]
    if known.size and np.abs(known).max() > MAX_HEIGHT_M:
        raise MapError(src, f"height value {known[np.argmax(np.abs(known))]:g} m beyond +-{MAX_HEIGHT_M:g} m")
    z = np.ascontiguousarray(z[::-1])
    if cell_x != cell_y:
        z, x0, y0 = resample_square(z, float(x0), float(y0), float(cell_x), float(cell_y))
    return ElevationModel(heights_m=z, x0_m=float(x0), y0_m=float(y0), cellsize_m=float(cell), source=src)


def bilinear(z: np.ndarray, fr: np.ndarray, fc: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of ``z`` (rows, cols) at fractional indices (row, col);
    NaN outside the centres' hull or where a NaN cell has weight. Pure."""
    rows, cols = z.shape
    out = np.full(np.shape(fr), np.nan)
    ok = (fr >= -1e-9) & (fr <= rows - 1 + 1e-9) & (fc >= -1e-9) & (fc <= cols - 1 + 1e-9)
    r, c = np.clip(fr[ok], 0, rows - 1), np.clip(fc[ok], 0, cols - 1)
    r0 = np.minimum(np.floor(r).astype(np.intp), max(rows - 2, 0))
    c0 = np.minimum(np.floor(c).astype(np.intp), max(cols - 2, 0))
    r1, c1 = np.minimum(r0 + 1, rows - 1), np.minimum(c0 + 1, cols - 1)
    tr, tc = r - r0, c - c0
    out[ok] = ((1 - tr) * ((1 - tc) * z[r0, c0] + tc * z[r0, c1]) + tr * ((1 - tc) * z[r1, c0] + tc * z[r1, c1]))
    return out


def square_shape(rows: int, cols: int, dx_m: float, dy_m: float) -> tuple[int, int]:
    """(columns, rows) of ``resample_square``'s grid, without building it."""
    cell = min(dx_m, dy_m)
    return (int(np.floor((cols - 1) * dx_m / cell + 1e-9)) + 1, int(np.floor((rows - 1) * dy_m / cell + 1e-9)) + 1)


def resample_square(z: np.ndarray, x0_m: float, y0_m: float, dx_m: float, dy_m: float):
    """A grid of ``dx x dy`` cells (row 0 south, centre of [0, 0] at (x0, y0)) resampled
    bilinearly onto square cells of ``min(dx, dy)`` over the same centres' extent.
    Returns (heights, x0, y0)."""
    cell = min(dx_m, dy_m)
    rows, cols = z.shape
    nx, ny = square_shape(rows, cols, dx_m, dy_m)
    fc = np.arange(nx) * cell / dx_m
    fr = np.arange(ny) * cell / dy_m
    FR, FC = np.meshgrid(fr, fc, indexing="ij")
    return bilinear(z, FR, FC), x0_m, y0_m


def _is_float(token) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def write_dem(path: str | Path, heights_m: np.ndarray, x0_m: float, y0_m: float, cellsize_m: float,
              corner: bool = True, nodata_value: float = -9999.0, fmt: str = "%.4f") -> None:
    """Write an ESRI ASCII grid (row 0 of ``heights_m`` = south; NaN = NODATA).

    ``x0_m``, ``y0_m``: centre of the south-west cell. ``corner`` selects the
    ``xllcorner`` (True) or ``xllcenter`` header convention.
    """
    z = np.asarray(heights_m, dtype=float)
    rows, cols = z.shape
    if corner:
        head = f"xllcorner {x0_m - 0.5 * cellsize_m!r}\nyllcorner {y0_m - 0.5 * cellsize_m!r}\n"
    else:
        head = f"xllcenter {x0_m!r}\nyllcenter {y0_m!r}\n"
    out = np.where(np.isnan(z), nodata_value, z)[::-1]
    with open(path, "w", encoding="ascii") as f:
        f.write(f"ncols {cols}\nnrows {rows}\n{head}cellsize {cellsize_m!r}\nNODATA_value {nodata_value:g}\n")
        np.savetxt(f, out, fmt=fmt)
