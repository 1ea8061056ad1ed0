"""Elevation model loader: ESRI ASCII grid (``.asc``).

Header keys (case-insensitive, one ``key value`` pair per line, any order):
``ncols``, ``nrows``, ``xllcorner`` or ``xllcenter``, ``yllcorner`` or
``yllcenter``, ``cellsize``, optional ``NODATA_value``. ``*llcorner`` is the
outer lower-left corner of the grid, ``*llcenter`` the centre of the
lower-left cell (half a cell further in). Then ``nrows`` rows of ``ncols``
numbers, the first row being the northernmost; the model is flipped so that
row 0 is the south row (``grid.py`` convention). NODATA cells become NaN.
Coordinates are the map's local metric ENU frame.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import MapError
from ..textfile import read_text
from .grid import ElevationModel

#: Largest coordinate (m, +-) and height (m, +-) accepted: beyond them the grid is a
#: typo (a local metric frame wider than the Earth, heights beyond any terrain).
MAX_COORD_M = 1.0e7
MAX_HEIGHT_M = 1.0e5

_KEYS = ("ncols", "nrows", "xllcorner", "xllcenter", "yllcorner", "yllcenter", "cellsize", "nodata_value")


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
    src = str(p)
    text = read_text(p, MapError, "elevation model", encoding="ascii", unreadable="cannot read as an ASCII grid")

    lines = text.splitlines()
    header: dict[str, float] = {}
    i = 0
    while i < len(lines):
        parts = lines[i].split()
        if not parts:
            i += 1
            continue
        key = parts[0].lower()
        if key[0].isdigit() or key[0] in "+-.":
            break  # first data row
        if key not in _KEYS:
            raise MapError(f"{src}: line {i + 1}", f"unknown header key {parts[0]!r} "
                           "(expected ncols, nrows, xllcorner|xllcenter, yllcorner|yllcenter, cellsize, NODATA_value)")
        if len(parts) != 2:
            raise MapError(f"{src}: line {i + 1}", f"expected '{parts[0]} <number>'")
        if key in header:
            raise MapError(f"{src}: line {i + 1}", f"duplicate header key {parts[0]!r}")
        try:
            header[key] = float(parts[1])
        except ValueError:
            raise MapError(f"{src}: line {i + 1}", f"{parts[0]} value {parts[1]!r} is not a number") from None
        if not math.isfinite(header[key]):
            raise MapError(f"{src}: line {i + 1}", f"{parts[0]} value must be finite")
        i += 1

    for key in ("ncols", "nrows", "cellsize"):
        if key not in header:
            raise MapError(src, f"header key {key!r} missing")
    for axis in ("x", "y"):
        have = [k for k in (f"{axis}llcorner", f"{axis}llcenter") if k in header]
        if len(have) != 1:
            raise MapError(src, f"header needs exactly one of {axis}llcorner / {axis}llcenter")
    ncols, nrows = header["ncols"], header["nrows"]
    for key, v in (("ncols", ncols), ("nrows", nrows)):
        if v != int(v) or v < 1:
            raise MapError(src, f"header {key} must be a positive integer, got {v:g}")
    ncols, nrows = int(ncols), int(nrows)
    cell = header["cellsize"]
    if cell <= 0:
        raise MapError(src, f"header cellsize must be > 0, got {cell:g}")
    half = 0.5 * cell
    x0 = header["xllcenter"] if "xllcenter" in header else header["xllcorner"] + half
    y0 = header["yllcenter"] if "yllcenter" in header else header["yllcorner"] + half

    reach = max(abs(x0), abs(y0)) + math.hypot(nrows, ncols) * cell
    if reach > MAX_COORD_M:
        raise MapError(src, f"the grid reaches {reach:.3g} m from the frame origin (more than {MAX_COORD_M:g} m; "
                       "check xll*/yll*, cellsize)")

    tokens = " ".join(lines[i:]).split()
    if len(tokens) != nrows * ncols:
        raise MapError(src, f"expected {nrows} x {ncols} = {nrows * ncols} values after the header, "
                       f"found {len(tokens)}")
    try:
        z = np.array(tokens, dtype=float).reshape(nrows, ncols)
    except ValueError:
        bad = next(t for t in tokens if not _is_float(t))
        raise MapError(src, f"non-numeric height value {bad[:20]!r}") from None
    if not np.all(np.isfinite(z)):
        raise MapError(src, "height values must be finite (use NODATA_value for holes)")
    if "nodata_value" in header:
        z[z == header["nodata_value"]] = np.nan
    known = z[~np.isnan(z)]
    if known.size and np.abs(known).max() > MAX_HEIGHT_M:
        raise MapError(src, f"height value {known[np.argmax(np.abs(known))]:g} m beyond +-{MAX_HEIGHT_M:g} m")
    return ElevationModel(heights_m=np.ascontiguousarray(z[::-1]), x0_m=float(x0), y0_m=float(y0),
                          cellsize_m=float(cell), source=src)


def _is_float(token: str) -> bool:
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
