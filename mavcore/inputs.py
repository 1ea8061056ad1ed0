"""The one loading layer of every input file (docs/limits.md).

Missions, map YAMLs, plan.json, GeoJSON/KML fields, DEMs (ASCII grids and
rasters), map images and .tlogs are all opened here, and every read is
bounded before it starts:

- only a regular file is read: a directory, a FIFO, a socket or a device
  (``/dev/zero``, ``/dev/urandom``) is refused from ``os.stat`` before it
  is opened, and it is opened with ``O_NONBLOCK`` (a file swapped for a
  FIFO after the check cannot block either) and checked again by ``fstat``;
- its size is checked against the cap of its kind before a byte is read,
  and at most cap + 1 bytes are read (a file that grows is caught too);
- YAML is composed by a loader that counts alias events, the size of the
  document with every alias expanded, and the nesting depth, and stops at
  the first one over its cap; JSON's nesting is capped the same way;
- the map and DEM loaders check pixel and cell counts from headers before
  decoding or allocating (``check``).

Every cap is a :class:`Limits` field with a default, overridable by the
environment variable ``COMPANION_MAX_<FIELD>`` (e.g.
``COMPANION_MAX_IMAGE_PIXELS=60000000``). A value over a cap is one line:
``<file>: <what> is <value>, above the limit <cap> (COMPANION_MAX_<FIELD>)``.
Error messages show user values only through :func:`brief` (bounded).
"""

from __future__ import annotations

import dataclasses
import errno
import json
import os
import reprlib
import stat
from dataclasses import dataclass, fields

from .errors import InputError

ENV_PREFIX = "COMPANION_MAX_"


@dataclass(frozen=True)
class Limits:
    """Caps on input files (docs/limits.md). Sizes in bytes, counts in items.

    Attributes
    ----------
    text_bytes : int
        A mission YAML, map YAML or GeoJSON/KML field.
    plan_bytes : int
        A plan.json (format 2.x stores the trajectory's pieces: a 10 ha field is about 9 MB; the
        optional dense samples add about 245 bytes each).
    dem_bytes : int
        An elevation model file (ASCII grid or raster).
    image_bytes : int
        A map image.
    image_pixels : int
        Pixels of a map image (from its header, before decoding).
    dem_cells : int
        Cells of an elevation model: in the file, and after any resampling
        (rectangular cells, rotation by ``home.heading_deg``, reprojection).
    field_cells : int
        Cells of a rasterised GeoJSON/KML field.
    polygon_vertices : int
        Vertices of all polygons and lines of a field together.
    raster_crossings : int
        Row crossings of a field's polygon edges when rasterised (the work
        of the even-odd scanline fill).
    yaml_aliases : int
        Alias (``*name``) events in one YAML document.
    yaml_nodes : int
        Nodes of one YAML document with every alias expanded.
    nesting_depth : int
        Nesting of lists and mappings in YAML and JSON.
    tlog_bytes : int
        A .tlog replayed (after decompression).
    tlog_garbage_bytes : int
        Consecutive bytes of a .tlog without one valid record.
    """

    text_bytes: int = 16 << 20
    plan_bytes: int = 32 << 20
    dem_bytes: int = 64 << 20
    image_bytes: int = 128 << 20
    image_pixels: int = 25_000_000
    dem_cells: int = 4_000_000
    field_cells: int = 25_000_000
    polygon_vertices: int = 200_000
    raster_crossings: int = 20_000_000
    yaml_aliases: int = 100
    yaml_nodes: int = 100_000
    nesting_depth: int = 64
    tlog_bytes: int = 2 << 30
    tlog_garbage_bytes: int = 2 << 20

    @staticmethod
    def env_name(name: str) -> str:
        return ENV_PREFIX + name.upper()


_DEFAULTS = Limits()


def limits(environ=None) -> Limits:
    """The caps in force: the defaults, overridden by ``COMPANION_MAX_*`` variables.

    Raises
    ------
    InputError
        A variable that is not a positive integer, or names no cap.
    """
    env = os.environ if environ is None else environ
    known = {Limits.env_name(f.name): f.name for f in fields(Limits)}
    over = {}
    for var, value in env.items():
        if not var.startswith(ENV_PREFIX):
            continue
        if var not in known:
            raise InputError(f"environment variable {var}",
                             f"names no limit (known: {', '.join(sorted(known))})")
        try:
            n = int(value.strip().replace("_", ""))
        except ValueError:
            n = -1
        if n <= 0:
            raise InputError(f"environment variable {var}", f"expected a positive integer, got {brief(value)}")
        over[known[var]] = n
    return dataclasses.replace(_DEFAULTS, **over) if over else _DEFAULTS


def check(source: str, what: str, value, name: str, error: type[Exception] = InputError, lim=None) -> None:
    """``error`` naming ``source``, ``what`` and the cap when ``value`` exceeds cap ``name``."""
    cap = getattr(lim or limits(), name)
    if value > cap:
        raise error(source, f"{what} is {value:,}, above the limit {cap:,} ({Limits.env_name(name)})")


_REPR = reprlib.Repr()
_REPR.maxlevel = 2
_REPR.maxstring = 40
_REPR.maxother = 40
_REPR.maxlong = 40
_REPR.maxlist = _REPR.maxtuple = _REPR.maxdict = _REPR.maxset = 4


def brief(value, width: int = 60) -> str:
    """A bounded repr of a user value for error messages (never the whole of it)."""
    try:
        text = _REPR.repr(value)
    except Exception:  # noqa: BLE001 - a repr that fails must not hide the error being reported
        text = f"<{type(value).__name__}>"
    return text if len(text) <= width else text[:width - 3] + "..."


def name(path) -> str:
    """A file name for messages: as given, its middle elided beyond 200 characters."""
    text = str(path)
    return text if len(text) <= 200 else f"{text[:120]}...{text[-60:]}"


def count_tokens(data: bytes, chunk: int = 1 << 22) -> int:
    """Whitespace-separated tokens in ``data``, counted a chunk at a time (no list of them)."""
    import numpy as np

    space_chars = np.frombuffer(b" \t\n\r\v\f", dtype=np.uint8)
    n = 0
    prev_space = True
    view = np.frombuffer(data, dtype=np.uint8)
    for i in range(0, view.size, chunk):
        space = np.isin(view[i:i + chunk], space_chars)
        starts = ~space
        starts[1:] &= space[:-1]
        starts[0] &= prev_space
        n += int(np.count_nonzero(starts))
        prev_space = bool(space[-1])
    return n


def clip(text: str, width: int = 120) -> str:
    """``text`` cut to ``width`` characters (one line) for an error message."""
    text = " ".join(str(text).split())
    return text if len(text) <= width else text[:width - 3] + "..."


# --- files ---------------------------------------------------------------------------

_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def _kind(mode: int) -> str:
    for test, name in _KINDS:
        if test(mode):
            return name
    return "not a regular file"


def _os_problem(exc: OSError, what: str) -> str:
    if exc.errno == errno.ENOENT:
        return f"no such file ({what})" if what else "no such file"
    if exc.errno == errno.ELOOP:
        return "too many levels of symbolic links"
    if exc.errno == errno.ENAMETOOLONG:
        return "file name too long"
    return f"cannot read: {exc.strerror or type(exc).__name__}"


def open_regular(path, error: type[Exception], what: str = "", cap: str = "text_bytes", lim=None):
    """An open binary file object of a regular file within the size cap ``cap``.

    Raises
    ------
    error
        Missing, not a regular file, unreadable, or larger than the cap.
    """
    src = name(path)
    lim = lim or limits()
    try:
        st = os.stat(path)
    except (OSError, ValueError) as exc:
        raise error(src, _os_problem(exc, what) if isinstance(exc, OSError) else "bad file name") from None
    if not stat.S_ISREG(st.st_mode):
        raise error(src, f"is {_kind(st.st_mode)}, not a regular file")
    check(src, "the file size", st.st_size, cap, error, lim)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise error(src, _os_problem(exc, what)) from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise error(src, f"is {_kind(st.st_mode)}, not a regular file")
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_bytes(path, error: type[Exception], what: str = "", cap: str = "text_bytes", lim=None) -> bytes:
    """The bytes of a regular file within the size cap ``cap`` (``open_regular``)."""
    lim = lim or limits()
    with open_regular(path, error, what, cap, lim) as fh:
        try:
            data = fh.read(getattr(lim, cap) + 1)
        except OSError as exc:
            raise error(name(path), _os_problem(exc, what)) from None
    check(name(path), "the file size", len(data), cap, error, lim)   # it grew since the stat
    return data


def read_text(path, error: type[Exception], what: str = "", *, encoding: str = "utf-8",
              unreadable: str = "cannot read", cap: str = "text_bytes", lim=None) -> str:
    """The text of a regular file within the size cap ``cap``, strictly decoded."""
    return decode_text(read_bytes(path, error, what, cap, lim), path, error, encoding=encoding, unreadable=unreadable)


def decode_text(data: bytes, path, error: type[Exception], *, encoding: str = "utf-8",
                unreadable: str = "cannot read") -> str:
    """``data`` (the bytes of the file ``path``) strictly decoded, as ``read_text`` does."""
    try:
        return data.decode(encoding, errors="strict")
    except UnicodeDecodeError as exc:
        raise error(name(path), f"{unreadable}: not {encoding} text (byte 0x{data[exc.start]:02x} at offset "
                               f"{exc.start})") from None


# --- JSON ------------------------------------------------------------------------------

def json_depth(text: str | bytes, chunk: int = 1 << 20) -> int:
    """Deepest nesting of ``[``/``{`` in JSON text, outside strings (a string's
    quote counts unless an odd run of backslashes precedes it). Vectorised, a
    chunk at a time, before the text is parsed: a deep document never reaches
    the recursive parser. Only quotes and brackets change the depth or the
    string state, so a chunk without backslashes is scanned at those bytes
    alone (an eighth of a plan.json's); one with backslashes byte by byte."""
    import numpy as np

    data = text.encode("utf-8", "surrogatepass") if isinstance(text, str) else text
    view = np.frombuffer(data, dtype=np.uint8)
    structural = np.zeros(256, dtype=bool)
    structural[[34, 91, 93, 123, 125]] = True
    deepest = depth = 0
    in_string = 0
    run = 0                                    # backslashes just before the chunk
    for s0 in range(0, view.size, chunk):
        a = view[s0:s0 + chunk]
        n = a.size
        if np.any(a == 92):
            pos = np.arange(n, dtype=np.int64)
            last_plain = np.maximum.accumulate(np.where(a != 92, pos, -1 - run))
            before = np.concatenate(([-1 - run], last_plain[:-1]))
            quote = (a == 34) & (((pos - 1 - before) & 1) == 0)
            run = int(n - 1 - last_plain[-1])
        else:                                  # the common case: only a carried run can escape
            at = np.flatnonzero(structural.take(a))
            escaped_first = bool(run & 1) and at.size > 0 and at[0] == 0
            a = a[at]
            quote = a == 34
            if escaped_first:
                quote[0] = False
            run = 0
            if a.size == 0:
                continue
        parity = (np.cumsum(quote, dtype=np.uint8) + np.uint8(in_string)) & 1
        outside = parity == 0
        step = ((a == 91) | (a == 123)).astype(np.int8) - ((a == 93) | (a == 125))
        step *= outside
        level = np.cumsum(step, dtype=np.int32) + depth
        deepest = max(deepest, int(level.max()))
        depth, in_string = int(level[-1]), int(parity[-1])
    return deepest


def parse_json(text: str, source: str, error: type[Exception], lim=None):
    """A JSON document with its nesting capped, or ``error("<source>[: line N]", problem)``."""
    lim = lim or limits()
    cap = lim.nesting_depth
    if json_depth(text) > cap:
        raise error(source, f"the JSON nesting depth is above the limit {cap:,} ({Limits.env_name('nesting_depth')})")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{source}: line {exc.lineno}", f"not valid JSON: {exc.msg}") from None
    except RecursionError:
        raise error(source, f"the JSON nesting depth is above the limit {cap:,} ({Limits.env_name('nesting_depth')})"
                    ) from None
    except (ValueError, OverflowError) as exc:
        raise error(source, f"not valid JSON: {clip(exc)}") from None
    return doc
