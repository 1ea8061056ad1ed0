"""A corpus of hostile input files (issue 19, docs/limits.md): each case builds
its files in an empty directory and names the ``companion`` command line that
must refuse them with one line on stderr, exit code 2, and nothing written,
in bounded time and memory.

Used by tests/test_hostile_inputs.py (in-process, plus a few as subprocesses
under time and memory limits) and benchmarks/hostile_inputs.py (every case as
a subprocess, with a table of times and peak RSS).

A case is ``Case(id, build, needle, env)``: ``build(d, base)`` writes what it
needs into ``d`` (the command's working directory) and returns the argv after
``companion``; ``base`` holds a good flat-rectangle mission (mission.yaml,
map.yaml, map.pgm, dem.asc), a good plan.json for it and a good vector-field
mission (field.yaml + field.geojson); each case breaks one thing of them
(the .tlog cases need no base). ``needle`` must be in the error line;
``env`` adds environment variables (limit overrides).
"""

from __future__ import annotations

import gzip
import json
import lzma
import os
import shutil
import struct
import subprocess
import sys
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import yaml

from companion.bundled import missions_dir

SRC = missions_dir() / "flat-rectangle"


def _dump(doc) -> str:
    return yaml.dump(doc, Dumper=getattr(yaml, "CSafeDumper", yaml.SafeDumper))
HOME = (44.8, -0.6, 30.0)
M = "mission.yaml"


@dataclass(frozen=True)
class Case:
    id: str
    build: Callable[[Path, Path], list]
    needle: str
    env: dict = field(default_factory=dict)


# --- the good base -------------------------------------------------------------------

def _lonlat(x: float, y: float) -> list:
    from mavcore.frames import enu2geodetic

    lat, lon, _ = enu2geodetic(x, y, 0.0, *HOME)
    return [lon, lat]


def field_doc(rings=None) -> dict:
    """A 20 m x 10 m field (ENU x 0..20, y 0..10) with one row along x at y = 5."""
    ring = rings or [[_lonlat(x, y) for x, y in ((0, 0), (20, 0), (20, 10), (0, 10), (0, 0))]]
    return {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"role": "boundary"}, "geometry": {"type": "Polygon", "coordinates": ring}},
        {"type": "Feature", "properties": {"role": "row"},
         "geometry": {"type": "LineString", "coordinates": [_lonlat(2, 5), _lonlat(18, 5)]}}]}


def make_base(d: Path) -> Path:
    """The good inputs every case breaks one thing of (module doc)."""
    from test_bad_input import good_plan_doc

    from mavcore.mission import load_mission

    d.mkdir(parents=True, exist_ok=True)
    for f in SRC.iterdir():
        shutil.copy(f, d / f.name)
    mission = load_mission(d / M)
    (d / "plan.json").write_text(json.dumps(good_plan_doc(mission)))
    (d / "field.geojson").write_text(json.dumps(field_doc()))
    doc = _mission_doc(d)
    doc.pop("map")
    doc["field"] = {"file": "field.geojson", "resolution_m": 0.1}
    (d / "field.yaml").write_text(_dump(doc))
    return d


def check_base(base: Path) -> None:
    """The base passes every loader the cases break (raises otherwise)."""
    from mavcore.maps.field import load_mission_maps
    from mavcore.mission import load_mission
    from companion.plan_io import load_plan

    for m in (M, "field.yaml"):
        load_mission_maps(load_mission(base / m))
    load_plan(base / "plan.json")


# --- running a case under limits -------------------------------------------------------

def tree(d: Path) -> dict:
    """Every path under ``d`` with its mode, size and mtime (links not followed)."""
    out = {}
    for p in d.rglob("*"):
        st = os.lstat(p)
        out[str(p.relative_to(d))] = (st.st_mode, st.st_size, st.st_mtime_ns)
    return out


#: Runs ``argv`` under RLIMIT_AS and a timeout, and prints its exit status, CPU time and peak
#: RSS (``os.wait4``). A small process of its own (``python -S``, about 10 MB): a forked
#: child's peak RSS starts at its parent's, so the test process must not be the parent.
_LAUNCHER = """
import json, os, resource, subprocess, sys, time
a = json.loads(sys.argv[1])
def limit():
    resource.setrlimit(resource.RLIMIT_AS, (a["as"], a["as"]))
t0 = time.perf_counter()
p = subprocess.Popen(a["argv"], cwd=a["cwd"], env=a["env"], preexec_fn=limit, stdout=subprocess.DEVNULL)
timed_out = False
while True:
    pid, status, usage = os.wait4(p.pid, os.WNOHANG)
    if pid:
        break
    if time.perf_counter() - t0 > a["timeout"]:
        timed_out = True
        p.kill()
        pid, status, usage = os.wait4(p.pid, 0)
        break
    time.sleep(0.005)
print(json.dumps({"rc": os.waitstatus_to_exitcode(status), "wall": time.perf_counter() - t0,
                  "cpu": usage.ru_utime + usage.ru_stime, "rss": usage.ru_maxrss * 1024, "timed_out": timed_out}))
"""


def run_limited(argv: list, cwd: Path, env: dict, timeout_s: float = 5.0, max_as_bytes: int = 1 << 30):
    """Run ``companion argv`` as a subprocess under RLIMIT_AS, killed after ``timeout_s``:
    (rc, stderr, wall s, CPU s, peak RSS bytes, timed out), all the child's own."""
    full_env = dict(os.environ, **env)
    full_env.setdefault("OPENBLAS_NUM_THREADS", "1")
    spec = {"argv": [sys.executable, "-m", "companion", *argv], "cwd": str(cwd), "env": full_env,
            "as": max_as_bytes, "timeout": timeout_s}
    out = subprocess.run([sys.executable, "-S", "-c", _LAUNCHER, json.dumps(spec)], capture_output=True,
                         timeout=timeout_s + 30)
    r = json.loads(out.stdout)
    return r["rc"], out.stderr.decode("utf-8", "replace"), r["wall"], r["cpu"], r["rss"], r["timed_out"]


# --- builders -------------------------------------------------------------------------

def _mission_doc(base: Path) -> dict:
    return yaml.safe_load((base / M).read_text())


def _copy_maps(d: Path, base: Path) -> None:
    for f in base.iterdir():
        if f.name not in (M, "plan.json", "field.yaml") and not (d / f.name).exists():
            shutil.copy(f, d / f.name)


def mission(change=None, name: str = M, field_mission: bool = False):
    """A builder: the base mission (or the field one) with ``change(doc, d)`` applied, planned."""
    def build(d: Path, base: Path) -> list:
        _copy_maps(d, base)
        doc = yaml.safe_load((base / ("field.yaml" if field_mission else M)).read_text())
        if change is not None:
            change(doc, d)
        (d / name).write_text(_dump(doc))
        return ["plan", name, "-o", "out.json"]
    return build


def raw_mission(data, name: str = M):
    """A builder: ``data`` (bytes or str) as the mission file."""
    def build(d: Path, base: Path) -> list:
        _copy_maps(d, base)
        _write(d / name, data)
        return ["plan", name, "-o", "out.json"]
    return build


def _write(p: Path, data) -> None:
    if callable(data):
        data(p)
    elif isinstance(data, bytes):
        p.write_bytes(data)
    else:
        p.write_text(data, encoding="utf-8")


def special(kind: str):
    """A writer making ``p`` a FIFO, a directory, a symlink loop, a dangling link, or a
    link to /dev/zero or /dev/urandom."""
    def make(p: Path) -> None:
        if kind == "fifo":
            os.mkfifo(p)
        elif kind == "dir":
            p.mkdir()
        elif kind == "loop":
            os.symlink(p.name + ".b", p)
            os.symlink(p.name, str(p) + ".b")
        elif kind == "dangling":
            os.symlink("nowhere-" + p.name, p)
        else:
            os.symlink(kind, p)
    return make


def sparse(size: int, head: bytes = b""):
    """A writer of a sparse file of ``size`` bytes starting with ``head``."""
    def make(p: Path) -> None:
        with open(p, "wb") as f:
            f.write(head)
            f.truncate(size)
    return make


def map_file(data, key: str = "map", mission_name: str = M, file_name: str = "m.yaml"):
    """A builder: the mission's ``map`` (or ``dem``) is a file holding ``data``."""
    def build(d: Path, base: Path) -> list:
        _copy_maps(d, base)
        _write(d / file_name, data)
        doc = _mission_doc(base)
        doc[key] = file_name
        (d / mission_name).write_text(_dump(doc))
        return ["plan", mission_name, "-o", "out.json"]
    return build


def map_yaml(change):
    """A builder: the base map YAML with ``change(doc, d)`` applied."""
    def build(d: Path, base: Path) -> list:
        doc = yaml.safe_load((base / "map.yaml").read_text())
        _copy_maps(d, base)
        change(doc, d)
        return map_file(_dump(doc))(d, base)
    return build


def image(data, file_name: str = "img.pgm"):
    """A builder: the map YAML's ``image`` is a file holding ``data``."""
    def build(d: Path, base: Path) -> list:
        _write(d / file_name, data)
        return map_yaml(lambda doc, _d: doc.update(image=file_name))(d, base)
    return build


def dem(data, file_name: str = "e.asc"):
    return map_file(data, key="dem", file_name=file_name)


def geojson(data, file_name: str = "f.geojson"):
    """A builder: the field mission's ``field.file`` holds ``data`` (a dict is dumped)."""
    def build(d: Path, base: Path) -> list:
        _write(d / file_name, json.dumps(data) if isinstance(data, dict) else data)
        return mission(lambda doc, _d: doc["field"].update(file=file_name), field_mission=True)(d, base)
    return build


def plan_json(data, file_name: str = "p.json"):
    """A builder: ``companion fly --plan`` with a plan.json holding ``data`` (a dict is dumped)."""
    def build(d: Path, base: Path) -> list:
        _write(d / file_name, json.dumps(data) if isinstance(data, dict) else data)
        return ["fly", str(base / M), "--plan", file_name, "--quiet"]
    return build


def plan_doc(change):
    """A builder: the base plan.json with ``change(doc)`` applied."""
    def build(d: Path, base: Path) -> list:
        doc = json.loads((base / "plan.json").read_text())
        change(doc)
        return plan_json(doc)(d, base)
    return build


def tlog(data, file_name: str = "f.tlog"):
    def build(d: Path, base: Path) -> list:
        _write(d / file_name, data)
        return ["replay", file_name]
    return build


# --- file contents ---------------------------------------------------------------------

def alias_bomb(levels: int = 9, width: int = 9, key: str = "origin") -> str:
    """The billion laughs: ``levels`` anchors each ``width`` aliases of the one before."""
    lines = ["l0: &l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    for i in range(1, levels + 1):
        lines.append(f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * width)}]")
    lines.append(f"{key}: *l{levels}")
    return "\n".join(lines) + "\n"


def map_yaml_text(prefix: str = "", drop: tuple = ()) -> str:
    """The base map YAML's keys (less ``drop``) after ``prefix``."""
    doc = {"image": "map.pgm", "resolution": 0.1, "origin": [-1.0, -1.0, 0.0], "negate": 0,
           "occupied_thresh": 0.65, "free_thresh": 0.196}
    for k in drop:
        doc.pop(k)
    return prefix + _dump(doc)


def png(width: int, height: int, color_type: int = 0, bit_depth: int = 8, idat: bytes | None = None,
        crc_ok: bool = True) -> bytes:
    """A PNG whose IHDR claims ``width`` x ``height`` (the data need not fill it)."""
    def chunk(kind: bytes, body: bytes, ok: bool = True) -> bytes:
        crc = zlib.crc32(kind + body) ^ (0 if ok else 1)
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)
    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, color_type, 0, 0, 0)
    data = zlib.compress(b"\0" * 64) if idat is None else idat
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr, crc_ok) + chunk(b"IDAT", data) + chunk(b"IEND", b"")


def small_png(w: int = 32, h: int = 32) -> bytes:
    raw = b"".join(b"\0" + b"\xff" * w for _ in range(h))
    return png(w, h, idat=zlib.compress(raw))


def bmp(width: int, height: int) -> bytes:
    info = struct.pack("<IiiHHIIiiII", 40, width, height, 1, 24, 0, 0, 2835, 2835, 0, 0)
    return b"BM" + struct.pack("<IHHI", 54 + 64, 0, 0, 54) + info + b"\0" * 64


def gif(width: int, height: int) -> bytes:
    return b"GIF89a" + struct.pack("<HHBBB", width, height, 0, 0, 0) + b"," + struct.pack(
        "<HHHHB", 0, 0, width, height, 0) + b"\x02\x02\x44\x01\x00;"


def dem_text(ncols="16", nrows="9", cell="cellsize 2.0", values=None, extra="") -> str:
    n = int(float(ncols)) * int(float(nrows)) if values is None else 0
    body = " ".join(["0.0"] * n) if values is None else values
    return f"ncols {ncols}\nnrows {nrows}\nxllcorner -4.0\nyllcorner -4.0\n{cell}\n{extra}{body}\n"


def deep_json(depth: int) -> str:
    return "[" * depth + "]" * depth


def geo_polygon(n: int) -> str:
    """A GeoJSON polygon of ``n`` vertices (a thin comb about home), written compactly."""
    lon0, lat0 = _lonlat(0, 0)
    pts = ",".join(f"[{lon0 + 1e-6 * (i % 1000):.7f},{lat0 + 1e-7 * (i // 1000):.7f}]" for i in range(n))
    return '{"type":"Polygon","coordinates":[[' + pts + "]]}"


def zigzag(n: int) -> dict:
    """A boundary of ``n`` vertices whose edges cross every raster row (0..20 m x 0..100 m)."""
    pts = [_lonlat(20.0 * i / n, 100.0 * (i % 2)) for i in range(n)] + [_lonlat(20, -1), _lonlat(0, -1)]
    pts.append(pts[0])
    return field_doc([pts])


def ring_of(n: int, w: float = 20.0, h: float = 10.0) -> list:
    """A closed ring of ``n`` vertices on the border of the w x h m rectangle at home."""
    import numpy as np

    from mavcore.maps.gis import enu_to_lonlat

    t = np.linspace(0.0, 2 * (w + h), n, endpoint=False)
    x = np.where(t < w, t, np.where(t < w + h, w, np.where(t < 2 * w + h, 2 * w + h - t, 0.0)))
    y = np.where(t < w, 0.0, np.where(t < w + h, t - w, np.where(t < 2 * w + h, h, 2 * (w + h) - t)))
    lon, lat = enu_to_lonlat(x, y, HOME)
    pts = np.column_stack([lon, lat]).tolist()
    return pts + [pts[0]]


def field_at(doc: dict, resolution_m: float):
    """A builder: the field mission with the field ``doc`` at ``resolution_m``."""
    def build(d: Path, base: Path) -> list:
        (d / "f.geojson").write_text(json.dumps(doc))
        return mission(lambda m, _d: m["field"].update(file="f.geojson", resolution_m=resolution_m),
                       field_mission=True)(d, base)
    return build


def rotated_dem(d: Path, base: Path) -> list:
    """A 1500 x 1500 DEM (under the cell cap) that, rotated 45 degrees by home.heading_deg, is over it."""
    (d / "big.asc").write_text(dem_text(ncols="1500", nrows="1500", cell="cellsize 0.1"))
    return mission(lambda m, _d: (m.update(dem="big.asc"), m["home"].update(heading_deg=45.0)))(d, base)


def kml(coords: str, extra: str = "", prolog: str = "") -> str:
    return (f'<?xml version="1.0"?>{prolog}<kml><Document>{extra}<Placemark><name>boundary</name><Polygon>'
            f"<outerBoundaryIs><LinearRing><coordinates>{coords}</coordinates></LinearRing></outerBoundaryIs>"
            "</Polygon></Placemark></Document></kml>")


def kml_bomb() -> str:
    ents = '<!ENTITY a0 "lol">' + "".join(f'<!ENTITY a{i} "{f"&a{i - 1};" * 10}">' for i in range(1, 10))
    return kml("0,0 1,0 1,1 0,0", extra="<name>&a9;</name>", prolog=f"<!DOCTYPE kml [{ents}]>")


def xz_zeros(n: int) -> bytes:
    return lzma.compress(b"\0" * n, preset=0)


def gz_zeros(n: int) -> bytes:
    return gzip.compress(b"\0" * n, compresslevel=1)


def _set(path: str, value):
    def change(doc, d):
        node = doc
        keys = path.split(".")
        for k in keys[:-1]:
            node = node.setdefault(k, {})
        node[keys[-1]] = value
    return change


def _frame_big(doc):
    doc["frame"] = "E" * 1_000_000


# --- the corpus --------------------------------------------------------------------------

GIB = 1 << 30
PX = "COMPANION_MAX_IMAGE_PIXELS"
CELLS = "COMPANION_MAX_DEM_CELLS"

CASES = [
    # --- the mission YAML
    Case("mission-alias-bomb", raw_mission(alias_bomb(key="name")), "COMPANION_MAX_YAML_NODES"),
    Case("mission-alias-count", raw_mission("a: &a 1\nb: [" + ", ".join(["*a"] * 150) + "]\n"),
         "COMPANION_MAX_YAML_ALIASES"),
    Case("mission-alias-recursive", raw_mission("name: &a [x, *a]\n"), "recursive"),
    Case("mission-alias-undefined", raw_mission("name: *nowhere\n"), "not valid YAML"),
    Case("mission-deep-flow-100k", raw_mission("name: " + "[" * 100_000 + "]" * 100_000 + "\n"), M),
    Case("mission-deep-flow-65", raw_mission("name: " + "[" * 65 + "]" * 65 + "\n"), "COMPANION_MAX_NESTING_DEPTH"),
    Case("mission-deep-block-100",
         raw_mission("".join("  " * i + f"k{i}:\n" for i in range(100)) + "  " * 100 + "v: 1\n"),
         "COMPANION_MAX_NESTING_DEPTH"),
    Case("mission-deep-flow-mapping", raw_mission("name: " + "{a: " * 5000 + "1" + "}" * 5000 + "\n"), M),
    Case("mission-5000-digit-int", raw_mission("name: x\nflight: {speed_m_s: " + "9" * 5000 + "}\n"), M),
    Case("mission-5000-digit-float", mission(_set("flight.speed_m_s", "9" * 5000 + ".0")), "flight.speed_m_s"),
    Case("mission-binary-garbage", raw_mission(bytes(range(256)) * 64), M),
    Case("mission-urandom-bytes", raw_mission(lambda p: p.write_bytes(os.urandom(1 << 16))), M),
    Case("mission-nul-bytes", raw_mission(b"name: x\0\0\0\n"), M),
    Case("mission-utf16", raw_mission("name: x\n".encode("utf-16")), M),
    Case("mission-empty", raw_mission(""), M),
    Case("mission-top-list", raw_mission("- 1\n- 2\n"), M),
    Case("mission-top-scalar", raw_mission("just a string\n"), M),
    Case("mission-two-documents", raw_mission("name: a\n---\nname: b\n"), M),
    Case("mission-python-tag", raw_mission("name: !!python/object/apply:os.system ['true']\n"), M),
    Case("mission-unhashable-key", raw_mission("? [a, b]\n: 1\n"), M),
    Case("mission-tab-indent", raw_mission("flight:\n\tspeed_m_s: 1\n"), M),
    Case("mission-truncated", raw_mission(SRC.joinpath(M).read_text().split("speed_m_s")[0]), M),
    Case("mission-huge-key", raw_mission("k" * 1000 + ": 1\n"), "unknown key"),
    Case("mission-2mb-key", raw_mission("k" * 2_000_000 + ": 1\n"), M),
    Case("mission-huge-string-value", mission(_set("flight.speed_m_s", "x" * 1_000_000)), "flight.speed_m_s"),
    Case("mission-huge-list-value", mission(_set("flight.speed_m_s", list(range(20_000)))), "flight.speed_m_s"),
    Case("mission-nan-speed", mission(_set("flight.speed_m_s", float("nan"))), "flight.speed_m_s"),
    Case("mission-inf-height", mission(_set("flight.height_agl_m", float("inf"))), "flight.height_agl_m"),
    Case("mission-negative-spacing", mission(_set("coverage.line_spacing_m", -2.5)), "coverage.line_spacing_m"),
    Case("mission-home-is-list", mission(_set("home", [1, 2, 3])), "home"),
    Case("mission-home-lat-string", mission(_set("home.lat", "north")), "home.lat"),
    Case("mission-fifo", raw_mission(special("fifo")), "FIFO"),
    Case("mission-dev-zero", raw_mission(special("/dev/zero")), "character device"),
    Case("mission-dev-urandom", raw_mission(special("/dev/urandom")), "character device"),
    Case("mission-directory", raw_mission(special("dir")), "directory"),
    Case("mission-symlink-loop", raw_mission(special("loop")), "symbolic links"),
    Case("mission-dangling-link", raw_mission(special("dangling")), "no such file"),
    Case("mission-sparse-1gib", raw_mission(sparse(GIB, b"name: x\n")), "COMPANION_MAX_TEXT_BYTES"),
    Case("mission-name-too-long", lambda d, b: ["plan", "m" * 300 + ".yaml", "-o", "out.json"], "file name too long"),
    Case("mission-limit-override", raw_mission(SRC.joinpath(M).read_text()), "COMPANION_MAX_TEXT_BYTES",
         {"COMPANION_MAX_TEXT_BYTES": "100"}),
    Case("env-limit-not-a-number", raw_mission(SRC.joinpath(M).read_text()), "COMPANION_MAX_IMAGE_PIXELS",
         {PX: "lots"}),
    Case("env-limit-negative", raw_mission(SRC.joinpath(M).read_text()), "COMPANION_MAX_DEM_CELLS", {CELLS: "-5"}),
    Case("env-limit-unknown", raw_mission(SRC.joinpath(M).read_text()), "COMPANION_MAX_WINGS",
         {"COMPANION_MAX_WINGS": "2"}),
    # --- the map YAML
    Case("map-alias-bomb-origin", map_file(map_yaml_text(alias_bomb(key="origin"), drop=("origin",))),
         "COMPANION_MAX_YAML_NODES"),
    Case("map-alias-bomb-small", map_file(map_yaml_text(alias_bomb(levels=3, key="origin"), drop=("origin",))),
         "origin"),
    Case("map-deep-nesting", map_file("image: " + "[" * 200 + "]" * 200 + "\n"), "COMPANION_MAX_NESTING_DEPTH"),
    Case("map-fifo", map_file(special("fifo")), "FIFO"),
    Case("map-dev-zero", map_file(special("/dev/zero")), "character device"),
    Case("map-dev-urandom", map_file(special("/dev/urandom")), "character device"),
    Case("map-directory", map_file(special("dir")), "directory"),
    Case("map-symlink-loop", map_file(special("loop")), "symbolic links"),
    Case("map-sparse-1gib", map_file(sparse(GIB)), "COMPANION_MAX_TEXT_BYTES"),
    Case("map-binary-garbage", map_file(bytes(range(128, 256)) * 32), "m.yaml"),
    Case("map-origin-huge-list", map_yaml(lambda doc, d: doc.update(origin=list(range(20_000)))), "origin"),
    Case("mission-95k-nodes-under-cap", raw_mission(SRC.joinpath(M).read_text() + "pad: [" + ",".join(["0"] * 95_000)
                                                     + "]\n"), "unknown key"),
    Case("map-origin-inf", map_yaml(lambda doc, d: doc.update(origin=[float("inf"), 0.0, 0.0])), "origin"),
    Case("map-origin-nan", map_yaml(lambda doc, d: doc.update(origin=[0.0, float("nan"), 0.0])), "origin"),
    Case("map-resolution-negative", map_yaml(lambda doc, d: doc.update(resolution=-0.1)), "resolution"),
    Case("map-resolution-zero", map_yaml(lambda doc, d: doc.update(resolution=0)), "resolution"),
    Case("map-resolution-nan", map_yaml(lambda doc, d: doc.update(resolution=float("nan"))), "resolution"),
    Case("map-resolution-1e300", map_yaml(lambda doc, d: doc.update(resolution=1e300)), "resolution"),
    Case("map-image-name-100k", map_yaml(lambda doc, d: doc.update(image="i" * 100_000)), "file name too long"),
    Case("map-image-not-string", map_yaml(lambda doc, d: doc.update(image=list(range(10_000)))), "image"),
    Case("map-mode-huge", map_yaml(lambda doc, d: doc.update(mode="m" * 1_000_000)), "mode"),
    Case("map-negate-2", map_yaml(lambda doc, d: doc.update(negate=2)), "negate"),
    Case("map-thresholds-swapped", map_yaml(lambda doc, d: doc.update(free_thresh=0.9, occupied_thresh=0.1)),
         "free_thresh"),
    Case("map-missing-image-key", map_yaml(lambda doc, d: doc.pop("image")), "image"),
    # --- map images
    Case("image-fifo", image(special("fifo")), "FIFO"),
    Case("image-dev-zero", image(special("/dev/zero")), "character device"),
    Case("image-dev-urandom", image(special("/dev/urandom")), "character device"),
    Case("image-directory", image(special("dir")), "directory"),
    Case("image-symlink-loop", image(special("loop")), "symbolic links"),
    Case("image-missing", image(special("dangling")), "no such file"),
    Case("image-sparse-1gib", image(sparse(GIB, b"P5 100 100 255\n")), "COMPANION_MAX_IMAGE_BYTES"),
    Case("pgm-5000-digit-width", image(b"P5 " + b"9" * 5000 + b" 10 255\n"), "digits"),
    Case("pgm-5000-digit-maxval", image(b"P5 10 10 " + b"9" * 5000 + b"\n"), "digits"),
    Case("pgm-5000-digit-comment-then-ok", image(b"P5 #" + b"9" * 5000 + b"\n60000 60000 255\n"), PX),
    Case("pgm-p5-huge-dims", image(b"P5 60000 60000 255\n" + b"\0" * 100), PX),
    Case("pgm-p2-huge-dims", image(b"P2 100000 100000 255\n0 0 0\n"), PX),
    Case("pgm-p5-just-over-cap", image(b"P5 5000 5001 255\n"), PX),
    Case("pgm-p5-truncated", image(b"P5 100 100 255\n" + b"\0" * 5000), "truncated"),
    Case("pgm-p5-16bit-truncated", image(b"P5 10 10 65535\n" + b"\0" * 199), "truncated"),
    Case("pgm-p2-truncated-big", image(b"P2 4000 4000 255\n0\n"), "truncated"),
    Case("pgm-p2-non-integer", image(b"P2 2 2 255\n0 1 x 3\n"), "non-integer"),
    Case("pgm-p2-negative", image(b"P2 2 2 255\n0 -1 2 3\n"), "non-integer"),
    Case("pgm-p2-float", image(b"P2 2 2 255\n0 1.5 2 3\n"), "non-integer"),
    Case("pgm-p2-above-maxval", image(b"P2 2 2 255\n0 1 2 300\n"), "above maxval"),
    Case("pgm-p2-10-digit-value", image(b"P2 2 2 255\n0 1 2 4294967297\n"), "10 or more digits"),
    Case("pgm-magic-only", image(b"P5"), "truncated PGM header"),
    Case("pgm-zero-width", image(b"P5 0 10 255\n"), "positive"),
    Case("pgm-maxval-0", image(b"P5 2 2 0\n\0\0\0\0"), "maxval"),
    Case("pgm-maxval-70000", image(b"P5 2 2 70000\n" + b"\0" * 8), "maxval"),
    Case("pgm-negative-header", image(b"P5 -2 2 255\n"), "not a positive integer"),
    Case("png-13000-square", image(png(13000, 13000), "big.png"), PX),
    Case("png-13000-square-rgba-16bit", image(png(13000, 13000, color_type=6, bit_depth=16), "big.png"), PX),
    Case("png-1e5-by-1e5", image(png(100_000, 100_000), "big.png"), PX),
    Case("png-just-over-cap", image(png(5000, 5001), "big.png"), PX),
    Case("png-pixel-cap-override", image(small_png(), "small.png"), PX, {PX: "100"}),
    Case("png-truncated-header", image(small_png()[:20], "t.png"), "t.png"),
    Case("png-bad-idat", image(png(64, 64, idat=b"not zlib data"), "b.png"), "b.png"),
    Case("png-bad-crc", image(png(64, 64, crc_ok=False), "c.png"), "c.png"),
    Case("png-zero-size", image(png(0, 0), "z.png"), "z.png"),
    Case("bmp-huge-dims", image(bmp(100_000, 100_000), "big.bmp"), PX),
    Case("gif-huge-dims", image(gif(65535, 65535), "big.gif"), "big.gif"),
    Case("image-garbage", image(bytes(range(256)) * 16, "g.png"), "not an image"),
    Case("jpeg-garbage-after-soi", image(b"\xff\xd8\xff\xe0" + bytes(200), "j.jpg"), "j.jpg"),
    Case("tiff-garbage", image(b"II*\x00" + bytes(200), "t.tif"), "t.tif"),
    # --- elevation models
    Case("dem-cell-1-by-0.0001", dem(dem_text(ncols="200", nrows="200", cell="dx 1\ndy 0.0001")), CELLS),
    Case("dem-cell-0.0001-by-1", dem(dem_text(ncols="200", nrows="200", cell="dx 0.0001\ndy 1")), CELLS),
    Case("dem-1e9-by-1e9", dem(dem_text(ncols="1000000000", nrows="1000000000", values="0")), CELLS),
    Case("dem-5000-digit-ncols", dem(dem_text(ncols="9" * 5000, values="0")), "e.asc"),
    Case("dem-ncols-fraction", dem(dem_text(ncols="2.5", values="0 0")), "ncols"),
    Case("dem-nrows-negative", dem(dem_text(nrows="-9", values="0")), "nrows"),
    Case("dem-cellsize-nan", dem(dem_text(cell="cellsize nan")), "cellsize"),
    Case("dem-cellsize-negative", dem(dem_text(cell="cellsize -2")), "cellsize"),
    Case("dem-cellsize-zero", dem(dem_text(cell="cellsize 0")), "cellsize"),
    Case("dem-cellsize-inf", dem(dem_text(cell="cellsize inf")), "cellsize"),
    Case("dem-nodata-inf", dem(dem_text(extra="NODATA_value inf\n")), "NODATA_value"),
    Case("dem-height-nan", dem(dem_text(values=" ".join(["0"] * 143 + ["nan"]))), "finite"),
    Case("dem-height-inf", dem(dem_text(values=" ".join(["0"] + ["inf"] + ["0"] * 142))), "finite"),
    Case("dem-data-starts-with-inf", dem(dem_text(values=" ".join(["inf"] + ["0"] * 143))), "e.asc"),
    Case("dem-height-1e400", dem(dem_text(values=" ".join(["0"] * 100 + ["1e400"] + ["0"] * 43))), "finite"),
    Case("dem-height-1e9", dem(dem_text(values=" ".join(["0"] * 100 + ["1e9"] + ["0"] * 43))), "beyond"),
    Case("dem-non-numeric", dem(dem_text(values=" ".join(["0"] * 100 + ["zero"] + ["0"] * 43))), "non-numeric"),
    Case("dem-too-few-values", dem(dem_text(values="0 0 0")), "expected 9 x 16"),
    Case("dem-too-many-values", dem(dem_text(values=" ".join(["0"] * 1000))), "expected 9 x 16"),
    Case("dem-header-only", dem("ncols 16\nnrows 9\n"), "e.asc"),
    Case("dem-header-line-huge", dem("ncols " + "1" * 100_000 + "\n"), "header line"),
    Case("dem-xll-1e300", dem(dem_text().replace("xllcorner -4.0", "xllcorner 1e300")), "frame origin"),
    Case("dem-binary-garbage", dem(bytes(range(256)) * 64), "ASCII"),
    Case("dem-fifo", dem(special("fifo")), "FIFO"),
    Case("dem-dev-zero", dem(special("/dev/zero")), "character device"),
    Case("dem-dev-urandom", dem(special("/dev/urandom")), "character device"),
    Case("dem-directory", dem(special("dir")), "directory"),
    Case("dem-symlink-loop", dem(special("loop")), "symbolic links"),
    Case("dem-sparse-1gib", dem(sparse(GIB, b"ncols 10\n")), "COMPANION_MAX_DEM_BYTES"),
    Case("dem-geotiff-garbage", dem(b"II*\x00" + bytes(500), "e.tif"), "e.tif"),
    Case("dem-cells-override", dem(dem_text()), CELLS, {CELLS: "100"}),
    Case("dem-rotated-over-cap", rotated_dem, CELLS),
    # --- vector fields (GeoJSON / KML)
    Case("geojson-1e6-vertices", geojson('{"type":"Polygon","coordinates":[[' + ",".join(["[1,2]"] * 1_000_000)
                                         + "]]}"), "COMPANION_MAX_POLYGON_VERTICES"),
    Case("geojson-1e6-vertices-25mb", geojson(geo_polygon(1_000_000)), "COMPANION_MAX_TEXT_BYTES"),
    Case("geojson-vertex-override", geojson(field_doc()), "COMPANION_MAX_POLYGON_VERTICES",
         {"COMPANION_MAX_POLYGON_VERTICES": "4"}),
    Case("geojson-zigzag-crossings", geojson(zigzag(150_000)), "COMPANION_MAX_RASTER_CROSSINGS"),
    Case("geojson-deep-100k", geojson(deep_json(100_000)), "COMPANION_MAX_NESTING_DEPTH"),
    Case("geojson-deep-65", geojson(deep_json(65)), "COMPANION_MAX_NESTING_DEPTH"),
    Case("geojson-nan-coordinates",
         geojson('{"type": "Polygon", "coordinates": [[[NaN, 0], [1, 0], [1, 1], [NaN, 0]]]}'),
         "f.geojson"),
    Case("geojson-infinity", geojson('{"type": "Polygon", "coordinates": [[[Infinity, 0], [1, 0], [1, 1], [0, 0]]]}'),
         "WGS-84"),
    Case("geojson-1e400", geojson('{"type": "Polygon", "coordinates": [[[1e400, 0], [1, 0], [1, 1], [0, 0]]]}'),
         "WGS-84"),
    Case("geojson-1e300-area-overflow", geojson('{"type": "Polygon", "coordinates": [[[1e300, 0], [0, 1e300], '
                                                '[-1e300, 0], [1e300, 0]]]}'), "WGS-84"),
    Case("geojson-string-coordinates", geojson({"type": "Polygon", "coordinates": [[["a", "b"], ["c", "d"]]]}),
         "malformed"),
    Case("geojson-ragged-coordinates", geojson({"type": "Polygon", "coordinates": [[[0, 0], [1], [1, 1, 1, 1]]]}),
         "malformed"),
    Case("geojson-coordinates-too-deep", geojson({"type": "Polygon", "coordinates": [[[[[0, 0]]]]]}), "malformed"),
    Case("geojson-5000-digit-number", geojson('{"type": "Polygon", "coordinates": [[[' + "9" * 5000 + ', 0]]]}'),
         "f.geojson"),
    Case("geojson-not-json", geojson("{nope"), "not valid JSON"),
    Case("geojson-empty-collection", geojson({"type": "FeatureCollection", "features": []}), "no polygon"),
    Case("geojson-lines-off-earth", geojson(field_doc() | {"features": field_doc()["features"] + [
        {"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[1e30, 0], [0, 1e30]]}}]}),
        "WGS-84"),
    Case("geojson-fifo", geojson(special("fifo")), "FIFO"),
    Case("geojson-dev-zero", geojson(special("/dev/zero")), "character device"),
    Case("geojson-sparse-1gib", geojson(sparse(GIB)), "COMPANION_MAX_TEXT_BYTES"),
    Case("field-resolution-cells", field_at(field_doc([ring_of(4, 60.0, 60.0)]), 0.01), "COMPANION_MAX_FIELD_CELLS"),
    Case("kml-billion-laughs", geojson(kml_bomb(), "f.kml"), "f.kml"),
    Case("kml-deep-elements", geojson("<kml>" + "<a>" * 100_000 + "</a>" * 100_000 + "</kml>", "f.kml"), "no polygon"),
    Case("kml-bad-coordinate", geojson(kml("0,0 x,y 1,1"), "f.kml"), "bad KML coordinate"),
    Case("kml-1e6-vertices", geojson(kml("0,0 " * 1_000_000), "f.kml"), "COMPANION_MAX_POLYGON_VERTICES"),
    Case("kml-not-xml", geojson("<kml><unclosed>", "f.kml"), "not valid KML"),
    # --- plan.json (companion fly --plan)
    Case("planjson-deep-100k", plan_json(deep_json(100_000)), "COMPANION_MAX_NESTING_DEPTH"),
    Case("planjson-deep-65", plan_json(deep_json(65)), "COMPANION_MAX_NESTING_DEPTH"),
    Case("planjson-fifo", plan_json(special("fifo")), "FIFO"),
    Case("planjson-dev-zero", plan_json(special("/dev/zero")), "character device"),
    Case("planjson-dev-urandom", plan_json(special("/dev/urandom")), "character device"),
    Case("planjson-directory", plan_json(special("dir")), "directory"),
    Case("planjson-symlink-loop", plan_json(special("loop")), "symbolic links"),
    Case("planjson-sparse-1gib", plan_json(sparse(GIB, b"{")), "COMPANION_MAX_PLAN_BYTES"),
    Case("planjson-5000-digit-int", plan_json('{"format_version": "1.0", "x": ' + "9" * 5000 + "}"), "p.json"),
    Case("planjson-huge-frame", plan_doc(_frame_big), "frame"),
    Case("planjson-huge-version", plan_doc(lambda doc: doc.update(format_version="9" * 1_000_000)), "format_version"),
    Case("planjson-top-list", plan_json("[1, 2, 3]"), "JSON object"),
    Case("planjson-binary-garbage", plan_json(bytes(range(256)) * 64), "p.json"),
    Case("planjson-truncated", lambda d, b: plan_json((b / "plan.json").read_text()[:500])(d, b), "not valid JSON"),
    Case("planjson-bom", lambda d, b: plan_json("\ufeff" + (b / "plan.json").read_text())(d, b), "not valid JSON"),
    Case("planjson-nan-trajectory", plan_doc(lambda doc: doc["trajectory"]["p"][0].__setitem__(0, float("nan"))),
         "trajectory"),
    Case("planjson-waypoints-dict", plan_doc(lambda doc: doc.update(waypoints={"a": 1})), "waypoints"),
    Case("fly-mission-fifo", lambda d, b: (os.mkfifo(d / "m.yaml"), ["fly", "m.yaml", "--plan", str(b / "plan.json"),
                                                                    "--quiet"])[1], "FIFO"),
    Case("fly-signing-key-fifo", lambda d, b: (os.mkfifo(d / "k"), ["fly", str(b / M), "--signing-key", "k",
                                                                  "--quiet"])[1], "FIFO"),
    Case("fly-signing-key-dev-zero", lambda d, b: ["fly", str(b / M), "--signing-key", "/dev/zero", "--quiet"],
         "character device"),
    # --- .tlog (companion replay)
    Case("tlog-sparse-3gib", tlog(sparse(3 * GIB)), "COMPANION_MAX_TLOG_BYTES"),
    Case("tlog-zeros-64mib", tlog(sparse(64 << 20)), "COMPANION_MAX_TLOG_GARBAGE_BYTES"),
    Case("tlog-urandom-8mib", tlog(lambda p: p.write_bytes(os.urandom(8 << 20))), "COMPANION_MAX_TLOG_GARBAGE_BYTES"),
    Case("tlog-dense-false-starts", tlog((bytes(8) + b"\xfd" + bytes(7)) * (1 << 18)),
         "COMPANION_MAX_TLOG_GARBAGE_BYTES"),
    Case("tlog-all-magic", tlog(b"\xfd" * (8 << 20)), "COMPANION_MAX_TLOG_GARBAGE_BYTES"),
    Case("tlog-xz-zeros", tlog(xz_zeros(64 << 20), "f.tlog.xz"), "COMPANION_MAX_TLOG_GARBAGE_BYTES"),
    Case("tlog-gz-zeros", tlog(gz_zeros(64 << 20), "f.tlog.gz"), "COMPANION_MAX_TLOG_GARBAGE_BYTES"),
    Case("tlog-gz-decompressed-cap", tlog(gz_zeros(4 << 20), "f.tlog.gz"), "COMPANION_MAX_TLOG_BYTES",
         {"COMPANION_MAX_TLOG_BYTES": "1000000"}),
    Case("tlog-xz-corrupt", tlog(xz_zeros(1 << 16)[:40] + b"junk" * 100, "f.tlog.xz"), "f.tlog.xz"),
    Case("tlog-gz-truncated", tlog(gz_zeros(1 << 20)[:100], "f.tlog.gz"), "f.tlog.gz"),
    Case("tlog-empty", tlog(b""), "no MAVLink records"),
    Case("tlog-short-garbage", tlog(b"hello, not a tlog\n" * 10), "no MAVLink records"),
    Case("tlog-fifo", tlog(special("fifo")), "FIFO"),
    Case("tlog-dev-zero", tlog(special("/dev/zero")), "character device"),
    Case("tlog-dev-urandom", tlog(special("/dev/urandom")), "character device"),
    Case("tlog-directory", tlog(special("dir")), "directory"),
    Case("tlog-symlink-loop", tlog(special("loop")), "symbolic links"),
    Case("tlog-missing", tlog(special("dangling")), "no such file"),
    Case("tlog-garbage-override", tlog(bytes(1 << 16)), "COMPANION_MAX_TLOG_GARBAGE_BYTES",
         {"COMPANION_MAX_TLOG_GARBAGE_BYTES": "1000"}),
]

#: The cases tests/test_hostile_inputs.py also runs as subprocesses under the limits.
SUBPROCESS_IDS = ("map-alias-bomb-origin", "mission-fifo", "dem-dev-zero", "png-13000-square",
                  "geojson-1e6-vertices", "tlog-zeros-64mib")
