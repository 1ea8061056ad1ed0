"""Occupancy grid loader: a map YAML + image, read the way Nav2's map_server reads it.

Semantics follow Nav2's ``map_io.cpp`` (``loadMapYaml``/``loadMapFromFile``;
ROS 1 ``map_server`` is the same for PGM):

- **Image formats**: PGM (P2 or P5, 8 or 16 bit) is read here; every other
  format Nav2's image library reads (PNG, BMP, TIFF, JPEG, PPM, ...) through
  Pillow. Each pixel's **shade** in [0, 1] is the mean of its red, green and
  blue channels (a grey image: its grey value) over the channel maximum; in
  ``trinary`` mode an image with an alpha channel averages the alpha
  (opacity, 1 = opaque) in as a fourth channel, as Nav2 does "to preserve
  existing behaviour".
- ``occ = 1 - shade`` (dark is occupied), or ``occ = shade`` with ``negate``.
- ``mode: trinary`` (default): ``occ > occupied_thresh`` is occupied,
  ``occ < free_thresh`` is free, anything else is unknown.
- ``mode: scale``: a pixel that is not fully opaque is unknown; otherwise
  as trinary, except that Nav2 keeps a graded cost for cells between the
  thresholds. The planner only knows occupied / free / unknown, so those
  cells are **unknown** (never free).
- ``mode: raw``: the cell value is ``round(255 shade)`` (``negate`` does
  not apply, as in Nav2): 0..100 are occupancy percentages, classified with
  the same thresholds on ``value / 100``; anything above 100 is unknown.
- Keys: ``image``, ``resolution``, ``origin``, ``negate`` (0/1 or a
  boolean), ``occupied_thresh``, ``free_thresh`` are required, ``mode`` is
  optional; any other key (``map_type``, ...) is ignored as Nav2 ignores
  it, with a warning in ``OccupancyGrid.warnings`` (a misspelt optional key
  should not pass unnoticed).

Image row 0 is the north (top) row; the grid is flipped so that row 0 is the
south row (``grid.py`` convention). ``origin: [x, y, yaw]`` is the world pose
of the lower-left corner of the lower-left pixel; ``yaw`` (rad) rotates the
grid about that corner (kept in ``OccupancyGrid.origin_yaw_rad``).
A relative ``image`` path is relative to the YAML file.

Every classification goes through a lookup table over the possible channel
sums (at most 4 x 65535 + 1 entries), so the thresholds are applied in
double precision and a 10 ha map costs one table lookup per pixel.
"""

from __future__ import annotations

import math
import re
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import MapError
from ..inputs import brief, check, clip, count_tokens, limits, name, open_regular, read_bytes, read_text
from .grid import OccupancyGrid

_REQUIRED = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
_OPTIONAL = ("mode",)
_MODES = ("trinary", "scale", "raw")
#: Largest map coordinate (m, +-): a local metric frame wider than the Earth is a
#: typo in ``origin`` or ``resolution``, and the planner's grid arithmetic would overflow.
MAX_COORD_M = 1.0e7
#: ``classify`` looks its tables up this many cells at a time (bounded temporaries)
_LOOKUP_CELLS = 1 << 20


def _number(data: dict, key: str, src: str) -> float:
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise MapError(f"{src}: key '{key}'", f"expected a finite number, got {brief(value)}")
    return float(value)


@dataclass(frozen=True, eq=False)
class ImageData:
    """Pixels (height, width), unsigned ints in file order (row 0 = top), and the PGM maxval."""

    values: np.ndarray
    maxval: int


@dataclass(frozen=True, eq=False)
class Shades:
    """An image reduced to what map_server reads from it (module doc).

    Attributes
    ----------
    channel_sum : (h, w) int array
        Sum of the colour channels of each pixel (R + G + B, or the grey value
        counted once for a grey image), image order (row 0 = top).
    n_channels : int
        How many channels ``channel_sum`` adds (1 for grey, 3 for colour).
    maxval : int
        Largest value of one channel (255, 65535 or a PGM's maxval).
    alpha : (h, w) int array or None
        Opacity (``maxval`` = opaque) where the image has an alpha channel.
    """

    channel_sum: np.ndarray
    n_channels: int
    maxval: int
    alpha: np.ndarray | None = None


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
    src = name(path)
    lim = limits()
    raw = read_bytes(path, MapError, "image of the occupancy grid", cap="image_bytes", lim=lim)
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
        if len(tok) > 9 and tok.isdigit():
            raise MapError(src, f"bad PGM header: a number of {len(tok)} digits (at most 9)")
        if not tok.isdigit():
            raise MapError(src, f"bad PGM header: {tok[:20].decode('latin-1')!r} is not a positive integer")
        tokens.append(int(tok))
    width, height, maxval = tokens
    if width <= 0 or height <= 0:
        raise MapError(src, f"bad PGM header: size {width} x {height} must be positive")
    if not 0 < maxval < 65536:
        raise MapError(src, f"bad PGM header: maxval {maxval} not in 1..65535")
    count = width * height
    check(src, f"the image's pixel count ({width} x {height})", count, "image_pixels", MapError, lim)

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
        values = _plain_values(body, count, src, f"{width} x {height} pixels")
    if values.size and values.dtype.kind == "i" and int(values.min()) < 0:
        raise MapError(src, f"bad PGM data: negative pixel value {int(values.min())}")
    if values.size and int(values.max()) > maxval:
        raise MapError(src, f"bad PGM data: pixel value {int(values.max())} above maxval {maxval}")
    values = values.astype(np.uint16 if maxval > 255 else np.uint8, copy=False)
    return ImageData(values.reshape(height, width), maxval)


_NOT_DIGIT_OR_SPACE = re.compile(rb"[^\s0-9]")
_LONG_NUMBER = re.compile(rb"[0-9]{10}")


def _plain_values(body: bytes, count: int, src: str, what: str) -> np.ndarray:
    """The first ``count`` whitespace-separated decimal integers of a P2 raster.

    Parsed by numpy (int32, no Python object per pixel); what follows the
    ``count``-th value is ignored, as before, unless it comes first."""
    bad = _NOT_DIGIT_OR_SPACE.search(body)
    if bad is not None:
        start = body.rfind(b" ", 0, bad.start()) + 1   # the token holding the bad byte starts after a space
        start = max(start, max(body.rfind(c, 0, bad.start()) for c in (b"\n", b"\r", b"\t", b"\v", b"\f")) + 1)
        if count_tokens(body[:start]) < count:
            raise MapError(src, "bad PGM data: non-integer pixel value")
        body = body[:start]
    if _LONG_NUMBER.search(body) is not None:
        raise MapError(src, "bad PGM data: a pixel value of 10 or more digits")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            values = np.fromstring(body, dtype=np.int32, sep=" ") if body.strip() else np.zeros(0, np.int32)
        except (ValueError, DeprecationWarning):   # pragma: no cover - only digits and spaces are left
            raise MapError(src, "bad PGM data: non-integer pixel value") from None
    if values.size < count:
        raise MapError(src, f"truncated PGM data: {values.size} values for {what}")
    return values[:count]


def classify(img: Shades, negate: bool, occupied_thresh: float, free_thresh: float,
             mode: str) -> tuple[np.ndarray, np.ndarray]:
    """Nav2 pixel classification (pure, module doc): image -> (occupied, free) bool masks.

    Parameters
    ----------
    img : Shades
    negate : bool
    occupied_thresh, free_thresh : float
        Probability thresholds in [0, 1].
    mode : {'trinary', 'scale', 'raw'}

    Returns
    -------
    occupied, free : (h, w) bool arrays, same orientation as the image.
    """
    m = img.maxval
    key = img.channel_sum
    n = img.n_channels
    with_alpha = img.alpha is not None and mode == "trinary"
    if with_alpha:
        # trinary averages the opacity in as one more channel
        key = key.astype(np.int32) + img.alpha
        n += 1
    # one entry per possible channel sum: thresholds in double precision
    shade = np.arange(n * m + 1, dtype=float) / (n * m)
    if mode == "raw":
        v = np.rint(shade * 255.0)
        known = v <= 100
        occ_lut, free_lut = known & (v / 100.0 > occupied_thresh), known & (v / 100.0 < free_thresh)
    else:
        occ = shade if negate else 1.0 - shade
        occ_lut = occ > occupied_thresh
        free_lut = (occ < free_thresh) & ~occ_lut
    occupied, free = _lookup(occ_lut, key), _lookup(free_lut, key)
    if mode == "scale" and img.alpha is not None:
        opaque = img.alpha == m
        occupied &= opaque
        free &= opaque
    return occupied, free


def _lookup(lut: np.ndarray, key: np.ndarray) -> np.ndarray:
    """``lut[key]`` as a new C-contiguous array, ``_LOOKUP_CELLS`` cells at a time.

    The same values as the fancy index, which converts the whole (h, w) key
    to a machine-integer index first (8 bytes a cell: 180 MB for a 10 ha map
    at 5 cm); ``key`` may be a view in any order (the flipped image).
    """
    out = np.empty(key.shape, dtype=lut.dtype)
    if key.ndim != 2 or key.size == 0:
        out[...] = lut[key]
        return out
    step = max(1, _LOOKUP_CELLS // max(1, key.shape[1]))
    true = np.flatnonzero(lut) if lut.dtype == bool else None
    if true is not None and len(true) and true[-1] - true[0] + 1 == len(true):
        # a bool table True on one run of keys a..b (what thresholds give): two
        # comparisons per cell, the same values as the lookup, about twice as fast
        a, b = (np.asarray(x, dtype=key.dtype) for x in (true[0], true[-1]))
        # keys index ``lut`` (0 <= key < len(lut), as the fancy index needs): a run from
        # the first key or to the last one is a single comparison (the dark or bright shades)
        lo, hi = bool(true[0] > 0), bool(true[-1] < len(lut) - 1)
        for r0 in range(0, key.shape[0], step):
            k = key[r0:r0 + step]
            o = out[r0:r0 + step]
            if lo:
                np.greater_equal(k, a, out=o)
                if hi:
                    o &= k <= b
            elif hi:
                np.less_equal(k, b, out=o)
            else:
                o[...] = True
        return out
    for r0 in range(0, key.shape[0], step):
        np.take(lut, key[r0:r0 + step], out=out[r0:r0 + step])
    return out


def read_image(path: str | Path) -> Shades:
    """Read a map image: PGM here, anything else through Pillow (module doc).

    Raises
    ------
    MapError
        Missing, unreadable, corrupt or truncated file, or a format Pillow does not know.
    """
    p = Path(path)
    lim = limits()
    with open_regular(p, MapError, "image of the occupancy grid", cap="image_bytes", lim=lim) as fh:
        magic = fh.read(2)
        if magic not in (b"P2", b"P5"):
            fh.seek(0)
            return _read_with_pillow(p, fh, lim)
    pgm = read_pgm(p)
    return Shades(pgm.values, 1, pgm.maxval)


def _read_with_pillow(p: Path, fh, lim) -> Shades:
    src = str(p)
    try:
        from PIL import Image, UnidentifiedImageError
    except ImportError:   # pragma: no cover - Pillow is a dependency
        raise MapError(src, "not a PGM image, and Pillow (needed for other formats) is not installed") from None
    bomb_cap = Image.MAX_IMAGE_PIXELS
    try:
        Image.MAX_IMAGE_PIXELS = None    # our own cap below, without Pillow's warning on stderr
        try:
            opened = Image.open(fh)
        finally:
            Image.MAX_IMAGE_PIXELS = bomb_cap
        with opened as im:
            w, h = im.size      # from the header: nothing is decoded yet
            check(src, f"the image's pixel count ({w} x {h})", w * h, "image_pixels", MapError, lim)
            if w * h == 0:
                raise MapError(src, f"the image has no pixels ({w} x {h})")
            im.load()
            mode = im.mode
            if mode == "P":
                im = im.convert("RGBA" if "transparency" in im.info else "RGB")
            elif mode == "1":
                im = im.convert("L")
            elif mode == "PA":
                im = im.convert("RGBA")
            elif mode not in ("L", "LA", "RGB", "RGBA", "I", "I;16", "I;16B", "I;16L"):
                im = im.convert("RGB")
            mode = im.mode
            arr = np.asarray(im)
    except MapError:
        raise
    except UnidentifiedImageError:
        raise MapError(src, "not an image Pillow can read (expected PGM, PNG, BMP, TIFF, ...)") from None
    except Image.DecompressionBombError as exc:
        raise MapError(src, f"image too large: {clip(exc)}") from None
    except (OSError, ValueError, SyntaxError, EOFError, struct.error, MemoryError) as exc:
        raise MapError(src, f"corrupt or truncated image: {clip(exc)}") from None
    if arr.ndim == 2:
        if mode.startswith("I"):
            vmax = int(arr.max()) if arr.size else 0
            if arr.size and int(arr.min()) < 0:
                raise MapError(src, "negative pixel values in a 32-bit image")
            maxval = 65535 if vmax <= 65535 else None
            if maxval is None:
                raise MapError(src, f"pixel value {vmax} above 65535 (32-bit images are not maps)")
            return Shades(arr.astype(np.int32), 1, maxval)
        return Shades(arr, 1, 255)
    if arr.shape[2] == 2:                   # LA
        return Shades(arr[..., 0], 1, 255, arr[..., 1].astype(np.int32))
    rgb = arr[..., :3].sum(axis=2, dtype=np.int32)
    alpha = arr[..., 3].astype(np.int32) if arr.shape[2] == 4 else None
    return Shades(rgb, 3, 255, alpha)


def load_ogm(yaml_path: str | Path) -> OccupancyGrid:
    """Load a Nav2 / ROS map_server occupancy grid (YAML + image).

    Parameters
    ----------
    yaml_path : path-like
        The map YAML (``image``, ``resolution``, ``origin``, ``negate``,
        ``occupied_thresh``, ``free_thresh``, optional ``mode``).

    Returns
    -------
    OccupancyGrid
        Row 0 south, ``source`` = the YAML path, ``warnings`` naming ignored keys.

    Raises
    ------
    MapError
        Any malformed input, naming the file (and key) and the problem.
    """
    from ..inputs_yaml import parse_yaml   # PyYAML on first use

    ypath = Path(yaml_path)
    src = str(ypath)
    data = parse_yaml(read_text(ypath, MapError, "occupancy grid YAML"), src, MapError)
    if not isinstance(data, dict):
        raise MapError(src, "expected a mapping of map_server keys")
    warnings = tuple(f"{src}: key '{key}' ignored (Nav2's map_server reads only "
                     f"{', '.join(_REQUIRED + _OPTIONAL)})"
                     for key in data if key not in _REQUIRED + _OPTIONAL)
    for key in _REQUIRED:
        if key not in data:
            raise MapError(f"{src}: key '{key}'", "missing")

    image = data["image"]
    if not isinstance(image, str) or not image:
        raise MapError(f"{src}: key 'image'", f"expected a file name, got {brief(image)}")
    resolution = _number(data, "resolution", src)
    if resolution <= 0:
        raise MapError(f"{src}: key 'resolution'", f"must be > 0 m per cell, got {resolution}")
    origin = data["origin"]
    if (not isinstance(origin, (list, tuple)) or len(origin) != 3
            or any(isinstance(o, bool) or not isinstance(o, (int, float)) or not math.isfinite(o)
                   for o in origin)):
        raise MapError(f"{src}: key 'origin'", f"expected [x, y, yaw] numbers, got {brief(origin)}")
    negate = data["negate"]
    if negate not in (0, 1) or (not isinstance(negate, (bool, int))):
        raise MapError(f"{src}: key 'negate'", f"expected 0 or 1, got {brief(negate)}")
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
        raise MapError(f"{src}: key 'mode'", f"expected one of {', '.join(_MODES)}, got {brief(mode)}")

    img_path = Path(image)
    if not img_path.is_absolute():
        img_path = ypath.parent / img_path
    img = read_image(img_path)
    h, w = img.channel_sum.shape
    reach = max(abs(float(origin[0])), abs(float(origin[1]))) + math.hypot(h, w) * resolution
    if reach > MAX_COORD_M:
        raise MapError(f"{src}: keys 'origin', 'resolution'",
                       f"the {w} x {h} grid reaches {reach:.3g} m from the frame origin "
                       f"(more than {MAX_COORD_M:g} m)")
    # Image row 0 is north; grid row 0 is south: classified in flipped order, so the
    # masks come out in grid order without a flipped copy of each.
    img = Shades(img.channel_sum[::-1], img.n_channels, img.maxval,
                 None if img.alpha is None else img.alpha[::-1])
    occupied, free = classify(img, bool(negate), occ_t, free_t, mode)
    return OccupancyGrid(
        occupied=np.ascontiguousarray(occupied),
        free=np.ascontiguousarray(free),
        resolution_m=resolution,
        origin_xy_m=(float(origin[0]), float(origin[1])),
        origin_yaw_rad=float(origin[2]),
        source=src,
        warnings=warnings,
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
