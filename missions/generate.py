#!/usr/bin/env python3
"""Generate synthetic vineyard missions: map.yaml + map.pgm (P5), dem.asc, mission.yaml.

Usage::

    python missions/generate.py flat-rectangle --out missions/flat-rectangle
    python missions/generate.py tilted-hexagon --out missions/tilted-hexagon
    python missions/generate.py large --out missions/large-10ha [--hectares 10] [--resolution 0.1]
    python missions/generate.py all            # regenerate the bundled missions in place

The world (the map's local ENU frame, metres) is built from a ``FieldSpec``:

- The **field** is a convex polygon. Cells inside it are free ground; cells
  **outside it are unknown** (grey, pixel 128): not flyable (unknown is not
  free for the planner) but not a physical obstacle either, so a simulator
  that raises occupied cells into vine walls does not build a fence around
  the field.
- **Vine rows** are straight occupied strips ``vine_width_m`` wide, parallel to
  the direction ``row_angle_deg`` (ENU, from east, counter-clockwise), their
  centrelines ``row_spacing_m`` apart. A row exists where its centreline is
  at least ``headland_m`` inside the field boundary, which leaves a headland
  for turning at the row ends and one free lane along the outer rows; rows
  shorter than ``min_row_length_m`` are left out.
  By default a row passes through the field's centroid: the pointing target
  S_p of eq. (21) defaults to that centroid at flight altitude, and it must
  not lie on a flight lane (the direction to it would be undefined there);
  this way it sits on a vine row, half a spacing from the nearest lane.
- The **DEM** is a plane ``z = slope_x x + slope_y y`` plus a gentle
  undulation ``A sin(2 pi x / L + phi_x) sin(2 pi y / L + phi_y)`` whose phases
  come from a seeded ``numpy.random.Generator`` (deterministic output).

Only numpy (and the project's own map writers) are used.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

try:
    from mavcore.maps.dem import write_dem
    from mavcore.maps.field import points_in_polygon  # noqa: F401  (re-exported for the corpus)
    from mavcore.maps.ogm import write_pgm
except ModuleNotFoundError:  # running from a checkout without the package installed
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from mavcore.maps.dem import write_dem
    from mavcore.maps.field import points_in_polygon  # noqa: F401
    from mavcore.maps.ogm import write_pgm

PIX_OCCUPIED = 0
PIX_FREE = 254
PIX_UNKNOWN = 128
OCCUPIED_THRESH = 0.65
FREE_THRESH = 0.196


@dataclass(frozen=True)
class FieldSpec:
    """Everything that defines a generated vineyard (ENU metres, degrees)."""

    name: str
    description: str
    polygon_m: tuple[tuple[float, float], ...]   # convex, counter-clockwise
    row_angle_deg: float
    row_spacing_m: float = 2.5
    row_offset_m: float | None = None  # a row centreline passes through this cross-row coordinate;
                                       # None: through the field's centroid (see module docstring)
    vine_width_m: float = 0.4
    headland_m: float = 2.5
    min_row_length_m: float = 3.0
    resolution_m: float = 0.1
    border_m: float = 1.0              # unknown margin around the field in the image
    dem_cellsize_m: float = 1.0
    dem_margin_m: float = 3.0          # DEM extends this far beyond the image
    dem_corner: bool = True            # xllcorner (True) or xllcenter header
    slope_x: float = 0.0
    slope_y: float = 0.0
    undulation_m: float = 0.0
    undulation_wavelength_m: float = 15.0
    seed: int = 1
    home: tuple[float, float, float] = (44.80, -0.60, 30.0)
    height_agl_m: float = 1.5
    speed_m_s: float = 1.0
    waypoint_interval_s: float = 4.0
    safety_margin_m: float = 0.45   # from the airframe surface (companion.margins); 0.5 leaves no corridor on the 30 deg rows
    sim_yaml: str = "  obstacles: []\n  noise: {vector_variance: 5.0e-4, gyro_variance: 5.0e-4}\n  seed: 1\n"


# --- geometry (pure) -------------------------------------------------------

def chord(poly: np.ndarray, v: float, angle_deg: float, inset_m: float) -> tuple[float, float]:
    """Interval (u_lo, u_hi) of the line {u d + v n} inside the convex CCW polygon
    shrunk by ``inset_m`` (d = (cos a, sin a), n = (-sin a, cos a)); empty if u_lo >= u_hi.

    For a convex polygon the points at least ``inset_m`` from the boundary
    are the intersection of the edges' half-planes shifted inward by ``inset_m``.
    """
    a = math.radians(angle_deg)
    d = np.array([math.cos(a), math.sin(a)])
    p0 = v * np.array([-math.sin(a), math.cos(a)])
    lo, hi = -math.inf, math.inf
    for i in range(len(poly)):
        e = poly[(i + 1) % len(poly)] - poly[i]
        nin = np.array([-e[1], e[0]]) / math.hypot(e[0], e[1])   # inward normal (CCW polygon)
        num = nin @ poly[i] + inset_m - nin @ p0
        den = nin @ d
        if abs(den) < 1e-12:
            if num > 1e-9:
                return 0.0, 0.0
            continue
        if den > 0:
            lo = max(lo, num / den)
        else:
            hi = min(hi, num / den)
    return lo, hi


def is_convex_ccw(poly: np.ndarray) -> bool:
    e = np.roll(poly, -1, axis=0) - poly
    cross = e[:, 0] * np.roll(e[:, 1], -1) - e[:, 1] * np.roll(e[:, 0], -1)
    return bool(np.all(cross > 0))


def polygon_centroid(poly: np.ndarray) -> np.ndarray:
    """Area centroid (m) of a simple polygon (K, 2)."""
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = cross.sum() / 2.0
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * area)


def polygon_area(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return abs(float((x * np.roll(y, -1) - np.roll(x, -1) * y).sum()) / 2.0)


def row_offset(spec: FieldSpec) -> float:
    """Cross-row coordinate (m) of one row centreline (rows at offset + k * spacing)."""
    if spec.row_offset_m is not None:
        return spec.row_offset_m
    a = math.radians(spec.row_angle_deg)
    cx, cy = polygon_centroid(np.asarray(spec.polygon_m, dtype=float))
    return -cx * math.sin(a) + cy * math.cos(a)


@dataclass(frozen=True, eq=False)
class Raster:
    """Generated occupancy image and its map_server origin."""

    pixels: np.ndarray          # (h, w) uint8, image order (row 0 = north)
    origin_xy_m: tuple[float, float]
    resolution_m: float


def rasterize(spec: FieldSpec, chunk_rows: int = 256) -> Raster:
    """Field polygon + vine rows -> PGM pixels (row 0 north). Pure."""
    poly = np.asarray(spec.polygon_m, dtype=float)
    res = spec.resolution_m
    # Snap the image corner to whole cells so the map origin is a round number.
    x_min, y_min = np.floor((poly.min(axis=0) - spec.border_m) / res + 1e-9) * res
    x_max, y_max = poly.max(axis=0) + spec.border_m
    cols = int(math.ceil(round((x_max - x_min) / res, 6)))
    rows = int(math.ceil(round((y_max - y_min) / res, 6)))
    a = math.radians(spec.row_angle_deg)
    ca, sa = math.cos(a), math.sin(a)
    off = row_offset(spec)
    if not is_convex_ccw(poly):
        raise ValueError(f"{spec.name}: the field polygon must be convex and counter-clockwise")
    # Row k (centreline v = off + k spacing) spans the chord of the field shrunk by the headland;
    # rows shorter than min_row_length_m are left out (no stubs of vines in a corner).
    v_all = poly @ np.array([-sa, ca])
    k_min = math.floor((v_all.min() - off) / spec.row_spacing_m)
    k_max = math.ceil((v_all.max() - off) / spec.row_spacing_m)
    u_lo = np.full(k_max - k_min + 1, math.inf)
    u_hi = np.full(k_max - k_min + 1, -math.inf)
    for i, k in enumerate(range(k_min, k_max + 1)):
        lo, hi = chord(poly, off + k * spec.row_spacing_m, spec.row_angle_deg, spec.headland_m - 1e-9)
        if hi - lo >= spec.min_row_length_m:
            u_lo[i], u_hi[i] = lo, hi
    grid = np.empty((rows, cols), dtype=np.uint8)   # row 0 south while building
    xc = x_min + (np.arange(cols) + 0.5) * res
    for r0 in range(0, rows, chunk_rows):
        yc = y_min + (np.arange(r0, min(rows, r0 + chunk_rows)) + 0.5) * res
        X, Y = np.meshgrid(xc, yc)
        inside = points_in_polygon(X, Y, poly)
        u = X * ca + Y * sa
        v = -X * sa + Y * ca
        k = np.round((v - off) / spec.row_spacing_m).astype(np.int64)
        vine = inside & (np.abs(v - (off + k * spec.row_spacing_m)) <= 0.5 * spec.vine_width_m)
        kv = k[vine] - k_min
        vine[vine] = (kv >= 0) & (kv < len(u_lo))
        kv = k[vine] - k_min
        uv = u[vine]
        vine[vine] = (uv >= u_lo[kv]) & (uv <= u_hi[kv])
        block = np.full(X.shape, PIX_UNKNOWN, dtype=np.uint8)
        block[inside] = PIX_FREE
        block[vine] = PIX_OCCUPIED
        grid[r0:r0 + block.shape[0]] = block
    return Raster(pixels=grid[::-1].copy(), origin_xy_m=(round(float(x_min), 9), round(float(y_min), 9)),
                  resolution_m=res)


@dataclass(frozen=True, eq=False)
class DemGrid:
    heights_m: np.ndarray   # (rows, cols), row 0 south
    x0_m: float             # centre of the south-west cell
    y0_m: float
    cellsize_m: float


def terrain(spec: FieldSpec, raster: Raster) -> DemGrid:
    """Plane + seeded undulation on a grid covering the image plus a margin. Pure."""
    rng = np.random.default_rng(spec.seed)
    phx, phy = rng.uniform(0.0, 2.0 * math.pi, size=2)
    h, w = raster.pixels.shape
    cs = spec.dem_cellsize_m
    x_lo = raster.origin_xy_m[0] - spec.dem_margin_m
    y_lo = raster.origin_xy_m[1] - spec.dem_margin_m
    x_hi = raster.origin_xy_m[0] + w * raster.resolution_m + spec.dem_margin_m
    y_hi = raster.origin_xy_m[1] + h * raster.resolution_m + spec.dem_margin_m
    cols = int(math.ceil((x_hi - x_lo) / cs))
    rows = int(math.ceil((y_hi - y_lo) / cs))
    x0, y0 = x_lo + 0.5 * cs, y_lo + 0.5 * cs
    X, Y = np.meshgrid(x0 + np.arange(cols) * cs, y0 + np.arange(rows) * cs)
    lam = spec.undulation_wavelength_m
    z = (spec.slope_x * X + spec.slope_y * Y
         + spec.undulation_m * np.sin(2 * math.pi * X / lam + phx) * np.sin(2 * math.pi * Y / lam + phy))
    return DemGrid(heights_m=z, x0_m=x0, y0_m=y0, cellsize_m=cs)


def estimate_path_length_m(spec: FieldSpec) -> float:
    """Rough boustrophedon length: one lane per corridor (mid-way between
    centrelines, plus the two outer lanes), each the chord of the field
    shrunk by the safety margin, joined by one spacing per turn. A sizing
    aid for the bundled missions, not the planner."""
    poly = np.asarray(spec.polygon_m, dtype=float)
    a = math.radians(spec.row_angle_deg)
    v_all = poly @ np.array([-math.sin(a), math.cos(a)])
    s = spec.row_spacing_m
    off = row_offset(spec)
    k0 = math.ceil((v_all.min() - off) / s - 0.5)
    k1 = math.floor((v_all.max() - off) / s - 0.5)
    lanes = []
    for k in range(k0, k1 + 1):
        lo, hi = chord(poly, off + (k + 0.5) * s, spec.row_angle_deg, spec.safety_margin_m)
        if hi > lo:
            lanes.append(hi - lo)
    return float(sum(lanes) + s * max(0, len(lanes) - 1))


# --- files -------------------------------------------------------------------

def mission_yaml(spec: FieldSpec) -> str:
    lat, lon, alt = spec.home
    return f"""# Generated by missions/generate.py ({spec.name}); regenerate rather than edit.
name: {spec.name}
description: "{spec.description}"
map: map.yaml
dem: dem.asc
home: {{lat: {lat}, lon: {lon}, alt_m: {alt}}}   # geodetic pose of the map frame's origin (z = 0)
flight: {{height_agl_m: {spec.height_agl_m}, speed_m_s: {spec.speed_m_s}, waypoint_interval_s: {spec.waypoint_interval_s}}}
coverage: {{line_spacing_m: {spec.row_spacing_m}, safety_margin_m: {spec.safety_margin_m}}}
pointing: {{target: centroid}}
sim:
{spec.sim_yaml}"""


def map_yaml(raster: Raster) -> str:
    ox, oy = raster.origin_xy_m
    return (f"image: map.pgm\nresolution: {raster.resolution_m!r}\norigin: [{ox!r}, {oy!r}, 0.0]\n"
            f"negate: 0\noccupied_thresh: {OCCUPIED_THRESH}\nfree_thresh: {FREE_THRESH}\nmode: trinary\n")


def write_mission(spec: FieldSpec, out: str | Path) -> dict:
    """Write map.yaml, map.pgm, dem.asc and mission.yaml into ``out``; return a summary."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    raster = rasterize(spec)
    dem = terrain(spec, raster)
    write_pgm(out / "map.pgm", raster.pixels, maxval=255, binary=True)
    (out / "map.yaml").write_text(map_yaml(raster), encoding="utf-8")
    write_dem(out / "dem.asc", dem.heights_m, dem.x0_m, dem.y0_m, dem.cellsize_m, corner=spec.dem_corner)
    (out / "mission.yaml").write_text(mission_yaml(spec), encoding="utf-8")
    poly = np.asarray(spec.polygon_m, dtype=float)
    length = estimate_path_length_m(spec)
    return {"dir": str(out), "image_px": raster.pixels.shape[::-1], "area_ha": polygon_area(poly) / 1e4,
            "est_path_m": length, "est_duration_s": length / spec.speed_m_s}


# --- the bundled fields --------------------------------------------------------

def _rotate(points, deg, about=(0.0, 0.0)):
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return tuple((about[0] + c * (x - about[0]) - s * (y - about[1]),
                  about[1] + s * (x - about[0]) + c * (y - about[1])) for x, y in points)


def flat_rectangle() -> FieldSpec:
    # 23 m x 10 m: three 18 m rows along x at y = 2.5, 5 (through the centroid), 7.5; four lanes
    # ~22 m long (field minus the 0.5 m margin at each end): 4 x 22 + 3 x 2.5 = 95.5 m of path,
    # about 120 s with the speed ramps at the 7 rest-to-rest runs (coverage/waypoints.py timing).
    return FieldSpec(
        name="flat-rectangle",
        description="Flat rectangle (paper Fig. 8a): three vine rows along x, 2.5 m apart, flat terrain",
        polygon_m=((0.0, 0.0), (23.0, 0.0), (23.0, 10.0), (0.0, 10.0)),
        row_angle_deg=0.0, dem_cellsize_m=2.0, dem_corner=True,
        home=(44.80, -0.60, 30.0), seed=1,
    )


def tilted_hexagon() -> FieldSpec:
    # An irregular convex hexagon, rows at 30 deg, on a ~8 %/4 % slope with +-0.15 m undulation.
    # Drawn in the row frame (u along the rows, v across) and rotated by 30 deg; sized for a
    # flight of about 120 s (~85 m of path plus the speed ramps at the corners).
    hexagon_uv = ((0.0, 0.0), (14.7, -1.32), (20.68, 4.31), (18.13, 10.82), (5.19, 12.06), (-2.99, 6.07))
    poly = _rotate(hexagon_uv, 30.0)
    return FieldSpec(
        name="tilted-hexagon",
        description="Tilted irregular hexagon (paper Fig. 8b): rows at 30 deg, 2.5 m apart, sloped DEM",
        polygon_m=poly, row_angle_deg=30.0, dem_cellsize_m=1.0, dem_corner=False,
        slope_x=0.08, slope_y=0.04, undulation_m=0.15, undulation_wavelength_m=15.0,
        home=(44.85, -0.55, 45.0), seed=2,
        sim_yaml=("  obstacles: []\n  noise: {vector_variance: 5.0e-4, gyro_variance: 5.0e-4}\n  seed: 2\n"),
    )


def large_field(hectares: float = 10.0, resolution_m: float = 0.1) -> FieldSpec:
    # Irregular convex pentagon scaled to the requested area; rows at 20 deg.
    base = np.array([(0.0, 0.0), (1.0, -0.05), (1.15, 0.55), (0.75, 0.8), (0.05, 0.7)])
    scale = math.sqrt(hectares * 1e4 / polygon_area(base))
    return FieldSpec(
        name=f"large-{hectares:g}ha",
        description=f"Synthetic {hectares:g} ha vineyard for benchmarks: rows at 20 deg, 2.5 m apart, gentle slope",
        polygon_m=tuple(map(tuple, base * scale)), row_angle_deg=20.0, resolution_m=resolution_m,
        border_m=2.0, dem_cellsize_m=5.0, dem_margin_m=10.0, slope_x=0.03, slope_y=0.02,
        undulation_m=0.5, undulation_wavelength_m=60.0, home=(44.9, -0.5, 40.0), seed=3,
        # from the airframe's surface: at 0.45 m the 20 deg rows leave corridors one or two
        # cells wide, too thin for the sorties' pooled transit search (a corner 210 m from the
        # launch point then needs a whole battery); 0.3 m leaves five (companion plan warns
        # that it is below the 0.442 m airframe radius)
        safety_margin_m=0.3,
    )


BUNDLED = {"flat-rectangle": flat_rectangle, "tilted-hexagon": tilted_hexagon}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("field", choices=[*BUNDLED, "large", "all"])
    parser.add_argument("--out", help="output directory (default: missions/<name> next to this script)")
    parser.add_argument("--hectares", type=float, default=10.0, help="area of the large field (default 10)")
    parser.add_argument("--resolution", type=float, default=0.1, help="large field cell size in m (default 0.1)")
    args = parser.parse_args(argv)
    here = Path(__file__).resolve().parent
    if args.field == "all":
        jobs = [(f(), here / name) for name, f in BUNDLED.items()]
    elif args.field == "large":
        spec = large_field(args.hectares, args.resolution)
        jobs = [(spec, Path(args.out) if args.out else here / spec.name)]
    else:
        jobs = [(BUNDLED[args.field](), Path(args.out) if args.out else here / args.field)]
    for spec, out in jobs:
        s = write_mission(spec, out)
        print(f"{spec.name}: {s['dir']}  image {s['image_px'][0]} x {s['image_px'][1]} px, "
              f"{s['area_ha']:.3f} ha, estimated path {s['est_path_m']:.0f} m "
              f"(~{s['est_duration_s']:.0f} s at {spec.speed_m_s} m/s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
