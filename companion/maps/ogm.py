"""Occupancy grid loader: ROS map_server YAML + PGM (P2 or P5).

Semantics follow ROS ``map_server`` (``image_loader.cpp``):

- For a pixel value ``v`` of a PGM with maximum ``maxval``, the occupancy
  probability is ``p = (maxval - v) / maxval`` (dark is occupied), or
  ``p = v / maxval`` with ``negate: 1``. (For 8-bit images this is map_server's
  ``(255 - v) / 255``; 16-bit images are scaled by their own ``maxval``.)
- ``mode: trinary`` (default): ``p > occupied_thresh`` is occupied,
  ``p < free_thresh`` is free, anything else is unknown.
- ``mode: scale``: map_server keeps a graded cost for cells between the
  thresholds. The planner only knows occupied / free / unknown, so those cells
  are **unknown** (never free); classification is therefore identical to
  trinary.
- ``mode: raw``: the pixel value (after ``negate``) *is* the map_server
  occupancy value: 0..100 are probabilities in percent, classified with the
  same thresholds on ``v / 100``; any value above 100 (e.g. 255, map_server's
  "-1") is unknown.

Image row 0 is the north (top) row; the grid is flipped so that row 0 is the
south row (``grid.py`` convention). ``origin: [x, y, yaw]`` is the world pose
of the lower-left corner of the lower-left pixel; ``yaw`` (rad) rotates the
grid about that corner (kept in ``OccupancyGrid.origin_yaw_rad``).
A relative ``image`` path is relative to the YAML file.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import MapError
from ..textfile import parse_yaml, read_text
from .grid import OccupancyGrid

_REQUIRED = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
_OPTIONAL = ("mode",)
_MODES = ("trinary", "scale", "raw")
#: Largest map coordinate (m, +-): a local metric frame wider than the Earth is a
#: typo in ``origin`` or ``resolution``, and the planner's grid arithmetic would overflow.
MAX_COORD_M = 1.0e7


def _number(data: dict, key: str, src: str) -> float:
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise MapError(f"{src}: key '{key}'", f"expected a finite number, got {value!r}")
    return float(value)


@dataclass(frozen=True, eq=False)
class ImageData:
    """Pixels (height, width), unsigned ints in file order (row 0 = top), and the PGM maxval."""

    values: np.ndarray
    maxval: int


def read_pgm(path: str | Path) -> ImageData:
    """Read a binary (P5, 8- or 16-bit) or plain (P2) PGM file.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    ImageData
        ``values`` (height, width) int array in image order (row 0 = top) and ``maxval``.

    Raises
    ------
    MapError
        Missing file, bad magic/header, truncated or out-of-range data.
    """
    src = str(path)
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError:
        raise MapError(src, "no such file (image of the occupancy grid)") from None
    except OSError as exc:
        raise MapError(src, f"cannot read: {exc.strerror or exc}") from None
    magic = raw[:2]
    if magic not in (b"P2", b"P5"):
        raise MapError(src, f"not a PGM image (magic {magic!r}; expected P2 or P5)")

    # Header: magic, width, height, maxval separated by whitespace, '#' comments allowed.
    tokens: list[int] = []
    pos = 2
    n = len(raw)
    while len(tokens) < 3:
        while pos < n and raw[pos:pos + 1].isspace():
            pos += 1
        if pos < n and raw[pos:pos + 1] == b"#":
            while pos < n and raw[pos:pos + 1] not in (b"\n", b"\r"):
                pos += 1
            continue
        start = pos
        while pos < n and not raw[pos:pos + 1].isspace() and raw[pos:pos + 1] != b"#":
            pos += 1
        if start == pos:
            raise MapError(src, "truncated PGM header (expected width, height and maxval)")
        tok = raw[start:pos]
        if not tok.isdigit():
            raise MapError(src, f"bad PGM header: {tok[:20].decode('latin-1')!r} is not a positive integer")
        tokens.append(int(tok))
    width, height, maxval = tokens
    if width <= 0 or height <= 0:
        raise MapError(src, f"bad PGM header: size {width} x {height} must be positive")
    if not 0 < maxval < 65536:
        raise MapError(src, f"bad PGM header: maxval {maxval} not in 1..65535")
    count = width * height

    if magic == b"P5":
        if pos >= n or not raw[pos:pos + 1].isspace():
            raise MapError(src, "bad PGM header: no whitespace after maxval")
        pos += 1  # exactly one whitespace byte separates header and raster
        dtype = np.dtype(">u2") if maxval > 255 else np.dtype("u1")
        need = count * dtype.itemsize
        if n - pos < need:
            raise MapError(src, f"truncated PGM data: {n - pos} bytes for {width} x {height} pixels ({need} needed)")
        values = np.frombuffer(raw, dtype=dtype, count=count, offset=pos)
    else:
        body = re.sub(rb"#[^\r\n]*", b" ", raw[pos:])
        parts = body.split()
        if len(parts) < count:
            raise MapError(src, f"truncated PGM data: {len(parts)} values for {width} x {height} pixels")
        try:
            values = np.array([int(t) for t in parts[:count]], dtype=np.int64)
        except ValueError:
            raise MapError(src, "bad PGM data: non-integer pixel value") from None
    if values.size and values.dtype.kind == "i" and int(values.min()) < 0:
        raise MapError(src, f"bad PGM data: negative pixel value {int(values.min())}")
    if values.size and int(values.max()) > maxval:
        raise MapError(src, f"bad PGM data: pixel value {int(values.max())} above maxval {maxval}")
    values = values.astype(np.uint16 if maxval > 255 else np.uint8, copy=False)
    return ImageData(values.reshape(height, width), maxval)


def classify(values: np.ndarray, maxval: int, negate: bool, occupied_thresh: float,
             free_thresh: float, mode: str) -> tuple[np.ndarray, np.ndarray]:
    """map_server pixel classification (pure): pixels -> (occupied, free) bool masks.

    Parameters
    ----------
    values : (h, w) unsigned int array
        Pixel values in 0..maxval.
    maxval : int
    negate : bool
    occupied_thresh, free_thresh : float
        Probability thresholds in [0, 1].
    mode : {'trinary', 'scale', 'raw'}
        See the module docstring.

    Returns
    -------
    occupied, free : (h, w) bool arrays, same orientation as ``values``.
    """
    # Classify each of the maxval + 1 possible values once, then look the pixels up.
    v = np.arange(maxval + 1, dtype=float)
    if negate:
        v = maxval - v
    if mode == "raw":
        known = v <= 100
        p = v / 100.0
        occ_lut, free_lut = known & (p > occupied_thresh), known & (p < free_thresh)
    else:
        p = (maxval - v) / maxval
        occ_lut = p > occupied_thresh
        free_lut = (p < free_thresh) & ~occ_lut
    return occ_lut[values], free_lut[values]


def load_ogm(yaml_path: str | Path) -> OccupancyGrid:
    """Load a ROS map_server occupancy grid (YAML + PGM).

    Parameters
    ----------
    yaml_path : path-like
        The map YAML (``image``, ``resolution``, ``origin``, ``negate``,
        ``occupied_thresh``, ``free_thresh``, optional ``mode``).

    Returns
    -------
    OccupancyGrid
        Row 0 south, ``source`` = the YAML path.

    Raises
    ------
    MapError
        Any malformed input, naming the file (and key) and the problem.
    """
    ypath = Path(yaml_path)
    src = str(ypath)
    data = parse_yaml(read_text(ypath, MapError, "occupancy grid YAML"), src, MapError)
    if not isinstance(data, dict):
        raise MapError(src, "expected a mapping of map_server keys")
    for key in data:
        if key not in _REQUIRED + _OPTIONAL:
            raise MapError(f"{src}: key '{key}'",
                           f"unknown key (known: {', '.join(sorted(_REQUIRED + _OPTIONAL))})")
    for key in _REQUIRED:
        if key not in data:
            raise MapError(f"{src}: key '{key}'", "missing")

    image = data["image"]
    if not isinstance(image, str) or not image:
        raise MapError(f"{src}: key 'image'", f"expected a file name, got {image!r}")
    resolution = _number(data, "resolution", src)
    if resolution <= 0:
        raise MapError(f"{src}: key 'resolution'", f"must be > 0 m per cell, got {resolution}")
    origin = data["origin"]
    if (not isinstance(origin, (list, tuple)) or len(origin) != 3
            or any(isinstance(o, bool) or not isinstance(o, (int, float)) or not math.isfinite(o)
                   for o in origin)):
        raise MapError(f"{src}: key 'origin'", f"expected [x, y, yaw] numbers, got {origin!r}")
    negate = data["negate"]
    if negate not in (0, 1) or (not isinstance(negate, (bool, int))):
        raise MapError(f"{src}: key 'negate'", f"expected 0 or 1, got {negate!r}")
    occ_t = _number(data, "occupied_thresh", src)
    free_t = _number(data, "free_thresh", src)
    if not 0.0 <= free_t <= 1.0:
        raise MapError(f"{src}: key 'free_thresh'", f"must be in [0, 1], got {free_t}")
    if not 0.0 <= occ_t <= 1.0:
        raise MapError(f"{src}: key 'occupied_thresh'", f"must be in [0, 1], got {occ_t}")
    if free_t > occ_t:
        raise MapError(f"{src}: key 'free_thresh'", f"{free_t} is above occupied_thresh {occ_t}")
    mode = data.get("mode", "trinary")
    if mode not in _MODES:
        raise MapError(f"{src}: key 'mode'", f"expected one of {', '.join(_MODES)}, got {mode!r}")

    img_path = Path(image)
    if not img_path.is_absolute():
        img_path = ypath.parent / img_path
    img = read_pgm(img_path)
    h, w = img.values.shape
    reach = max(abs(float(origin[0])), abs(float(origin[1]))) + math.hypot(h, w) * resolution
    if reach > MAX_COORD_M:
        raise MapError(f"{src}: keys 'origin', 'resolution'",
                       f"the {w} x {h} grid reaches {reach:.3g} m from the frame origin "
                       f"(more than {MAX_COORD_M:g} m)")
    occupied, free = classify(img.values, img.maxval, bool(negate), occ_t, free_t, mode)
    # Image row 0 is north; grid row 0 is south.
    return OccupancyGrid(
        occupied=np.ascontiguousarray(occupied[::-1]),
        free=np.ascontiguousarray(free[::-1]),
        resolution_m=resolution,
        origin_xy_m=(float(origin[0]), float(origin[1])),
        origin_yaw_rad=float(origin[2]),
        source=src,
    )


def write_pgm(path: str | Path, values: np.ndarray, maxval: int = 255, binary: bool = True) -> None:
    """Write a PGM image (P5 binary or P2 plain); ``values`` (h, w) in image order (row 0 = top)."""
    v = np.asarray(values)
    h, w = v.shape
    if binary:
        dtype = np.dtype(">u2") if maxval > 255 else np.dtype("u1")
        with open(path, "wb") as f:
            f.write(f"P5\n{w} {h}\n{maxval}\n".encode("ascii"))
            f.write(v.astype(dtype).tobytes())
    else:
        with open(path, "w", encoding="ascii") as f:
            f.write(f"P2\n{w} {h}\n{maxval}\n")
            np.savetxt(f, v.astype(np.int64), fmt="%d")
