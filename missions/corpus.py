#!/usr/bin/env python3
"""Adversarial vineyards for the planner, and an independent coverage checker.

Usage::

    python missions/corpus.py --seed 7 --out /tmp/field-7     # write one field as a mission
    python missions/corpus.py --large --out /tmp/large-irregular

Each field is drawn from its seed (``numpy.random.default_rng(seed)``, so the
corpus is the same on every machine) in the map's local ENU frame:

- a **boundary** that is a random star-shaped polygon (concave in places),
  with a rectangular **notch** cut into it for some seeds;
- **rows** at a random angle (0..180 deg), spacing 2..3 m, vine width
  0.3..0.45 m, kept at least a headland (1.5..3 m) from the boundary;
- features by kind (``KINDS``; seed % len(KINDS)):

  * ``buildings``: 1..4 rotated rectangles (occupied); for half of them
    the rows run right up to the wall, so their corridors are dead ends
    reached only the long way round;
  * ``ponds``: ellipses of unknown cells (not flyable, not an obstacle);
  * ``neck``: two lobes joined by a neck only a little wider than twice
    the safety margin (a narrow passage with rounded corners after erosion);
  * ``island``: a walled enclosure with vines inside: its door is narrower
    than twice the safety margin, so the pocket is closed off (its segments
    are unreachable and must be dropped, not fail the plan);
  * ``mixed``: all of the above at once;

Cells outside the boundary are unknown (pixel 128), inside free (254),
vines and walls occupied (0), as ``missions/generate.py`` draws them.

Independent coverage checker (:func:`check_coverage`)
    It uses the drawing's truth (the vine cells as drawn, the row angle,
    spacing and offset), not the planner's corridors or statistic. Corridor
    samples are points every ``h / 2`` on the mid-lines between neighbouring
    row centre lines where both rows have a vine at the same along-row
    position. A sample is *reachable* when its clearance from every non-free
    cell (``scipy.ndimage.distance_transform_edt`` of the free mask, the
    outside padded as non-free) is at least the safety margin plus one cell
    (the planner's admissible set, by its definition) and it lies in the
    8-connected component (``scipy.ndimage.label``) of that set holding the
    path's start. It is *covered* when the flown path passes within a
    quarter spacing of it (``scipy.spatial.cKDTree`` on the path sampled
    every ``h / 4``). Coverage is covered / reachable samples.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import generate  # noqa: E402  (missions/generate.py)
from generate import PIX_FREE, PIX_OCCUPIED, PIX_UNKNOWN, points_in_polygon  # noqa: E402

KINDS = ("buildings", "ponds", "neck", "island", "mixed")


@dataclass(frozen=True, eq=False)
class Field:
    """A drawn field and its truth.

    Attributes
    ----------
    name, kind : str
    pixels : (h, w) uint8
        map_server image, row 0 north (PIX_* values of ``generate``).
    origin_xy_m : (x, y)
        World position (ENU, m) of the lower-left corner of the image.
    resolution_m : float
    row_angle_deg, row_spacing_m, row_offset_m : float
        Rows run along ``row_angle_deg`` (ENU, from east, CCW); row k's centre
        line is at cross-row coordinate ``row_offset_m + k row_spacing_m``
        (``v = -x sin a + y cos a``).
    vine : (h, w) bool
        Drawn vine cells, row 0 **south** (grid convention).
    safety_margin_m : float
    area_m2 : float
        Free area of the field (m^2).
    """

    name: str
    kind: str
    pixels: np.ndarray
    origin_xy_m: tuple[float, float]
    resolution_m: float
    row_angle_deg: float
    row_spacing_m: float
    row_offset_m: float
    vine: np.ndarray
    safety_margin_m: float
    area_m2: float


def _star_polygon(rng, radius_m: float, n: int, jitter: float) -> np.ndarray:
    """CCW star-shaped polygon about (0, 0): n vertices at sorted random angles."""
    ang = np.sort(rng.uniform(0.0, 2 * np.pi, n))
    r = radius_m * (1.0 + jitter * rng.uniform(-1.0, 1.0, n))
    return np.column_stack([r * np.cos(ang), r * np.sin(ang)])


def _rect(cx, cy, w, h, yaw_deg) -> np.ndarray:
    a = math.radians(yaw_deg)
    c, s = math.cos(a), math.sin(a)
    pts = np.array([(-w / 2, -h / 2), (w / 2, -h / 2), (w / 2, h / 2), (-w / 2, h / 2)])
    return np.column_stack([cx + c * pts[:, 0] - s * pts[:, 1], cy + s * pts[:, 0] + c * pts[:, 1]])


def draw_field(seed: int, size_m: float | None = None, resolution_m: float = 0.1,
               safety_margin_m: float = 0.5, kind: str | None = None) -> Field:
    """The adversarial field of ``seed`` (module doc). Pure: the seed fixes everything.

    ``size_m``: rough diameter of the field (default: 40..110 m from the seed).
    """
    rng = np.random.default_rng(seed)
    kind = kind or KINDS[seed % len(KINDS)]
    size = float(size_m) if size_m is not None else float(rng.uniform(40.0, 110.0))
    res = resolution_m
    h_cells = res
    spacing = float(rng.uniform(2.0, 3.0))
    vine_w = float(rng.uniform(0.3, 0.45))
    headland = float(rng.uniform(1.5, 3.0))
    angle = float(rng.uniform(0.0, 180.0))
    margin = safety_margin_m
    neck_w = 2 * (margin + h_cells) + float(rng.uniform(0.3, 1.5))

    shapes: list[np.ndarray] = []
    if kind == "neck" or (kind == "mixed" and rng.random() < 0.5):
        # two lobes side by side joined by a neck along x
        r = size / 4
        left = _star_polygon(rng, r, 9, 0.2) + (-r * 1.25, 0.0)
        right = _star_polygon(rng, r, 9, 0.2) + (r * 1.25, 0.0)
        neck = _rect(0.0, float(rng.uniform(-r / 4, r / 4)), r * 1.6, neck_w, 0.0)
        shapes = [left, right, neck]
    else:
        shapes = [_star_polygon(rng, size / 2, int(rng.integers(6, 12)), 0.25)]
    notch = None
    if kind in ("buildings", "mixed", "ponds") and rng.random() < 0.7:
        ang_n = rng.uniform(0, 2 * np.pi)
        depth = size * rng.uniform(0.15, 0.3)
        notch = _rect(0.5 * size * np.cos(ang_n), 0.5 * size * np.sin(ang_n), size * rng.uniform(0.1, 0.25),
                      2 * depth, np.degrees(ang_n) + 90.0)

    allpts = np.vstack(shapes)
    border = 2.0
    x_min, y_min = np.floor((allpts.min(axis=0) - border) / res) * res
    x_max, y_max = allpts.max(axis=0) + border
    cols = int(math.ceil((x_max - x_min) / res))
    rows = int(math.ceil((y_max - y_min) / res))
    xc = x_min + (np.arange(cols) + 0.5) * res
    yc = y_min + (np.arange(rows) + 0.5) * res
    X, Y = np.meshgrid(xc, yc)             # row 0 south
    inside = np.zeros(X.shape, dtype=bool)
    for p in shapes:
        inside |= points_in_polygon(X, Y, p)
    if notch is not None:
        inside &= ~points_in_polygon(X, Y, notch)

    walls = np.zeros_like(inside)           # occupied, rows stop a headland away
    touch = np.zeros_like(inside)           # occupied, rows run up to them
    unknown = np.zeros_like(inside)
    pocket = np.zeros_like(inside)          # inside the island's enclosure
    fx, fy = X[inside], Y[inside]
    lo, hi = np.array([fx.min(), fy.min()]), np.array([fx.max(), fy.max()])

    def random_point(frac=0.6):
        c = 0.5 * (lo + hi)
        return c + (rng.uniform(-0.5, 0.5, 2) * frac * (hi - lo))

    sc = min(1.0, size / 100.0)             # features shrink with small fields
    if kind in ("buildings", "mixed"):
        for _ in range(int(rng.integers(1, 5))):
            cx, cy = random_point()
            b = points_in_polygon(X, Y, _rect(cx, cy, sc * rng.uniform(4, 15), sc * rng.uniform(4, 12),
                                              rng.uniform(0, 180)))
            (touch if rng.random() < 0.5 else walls)[...] |= b
    if kind in ("ponds", "mixed"):
        for _ in range(int(rng.integers(1, 4))):
            cx, cy = random_point()
            ax, ay = sc * rng.uniform(2, 8, 2)
            t = math.radians(rng.uniform(0, 180))
            u = (X - cx) * math.cos(t) + (Y - cy) * math.sin(t)
            v = -(X - cx) * math.sin(t) + (Y - cy) * math.cos(t)
            unknown |= (u / ax) ** 2 + (v / ay) ** 2 <= 1.0
    if kind in ("island", "mixed"):
        cx, cy = random_point(0.3)
        w, hh = rng.uniform(8, 14), rng.uniform(8, 14)
        yaw = rng.uniform(0, 180)
        outer = points_in_polygon(X, Y, _rect(cx, cy, w, hh, yaw))
        inner = points_in_polygon(X, Y, _rect(cx, cy, w - 1.0, hh - 1.0, yaw))
        ring = outer & ~inner
        # a door narrower than twice the margin: free, yet closed by the erosion
        door = points_in_polygon(X, Y, _rect(cx + (w / 2 - 0.25) * math.cos(math.radians(yaw)),
                                             cy + (w / 2 - 0.25) * math.sin(math.radians(yaw)),
                                             1.0, 2 * margin - 0.3, yaw))
        walls |= ring & ~door
        pocket |= inner

    field = inside & ~unknown
    a = math.radians(angle)
    U = X * math.cos(a) + Y * math.sin(a)
    V = -X * math.sin(a) + Y * math.cos(a)
    off = float(rng.uniform(0.0, spacing))
    k = np.round((V - off) / spacing)
    band = np.abs(V - (off + k * spacing)) <= 0.5 * vine_w
    d_edge = ndimage.distance_transform_edt(np.pad(field & ~walls, 1))[1:-1, 1:-1] * res
    vine = band & field & (d_edge >= headland) & ~touch
    # inside the enclosure the rows run up to its wall (a headland of one margin)
    vine |= band & pocket & (ndimage.distance_transform_edt(pocket) * res >= 1.0)
    vine &= ~walls & ~touch
    occupied = (vine | walls | touch) & inside
    pix = np.full(X.shape, PIX_UNKNOWN, dtype=np.uint8)
    pix[field] = PIX_FREE
    pix[occupied] = PIX_OCCUPIED
    free_area = float(np.count_nonzero(pix == PIX_FREE)) * res * res
    return Field(name=f"corpus-{seed}", kind=kind, pixels=np.ascontiguousarray(pix[::-1]),
                 origin_xy_m=(float(x_min), float(y_min)), resolution_m=res, row_angle_deg=angle,
                 row_spacing_m=spacing, row_offset_m=off, vine=vine & (pix == PIX_OCCUPIED),
                 safety_margin_m=margin, area_m2=free_area)


def large_irregular(hectares: float = 10.0, seed: int = 1010) -> Field:
    """A ~``hectares`` field of kind ``mixed`` (buildings, ponds, an enclosure, a notch)."""
    size = math.sqrt(hectares * 1e4 / (math.pi / 4 * 0.55))   # calibrated: star jitter, notch and features
    return draw_field(seed, size_m=size, kind="mixed")


def grid_of(f: Field):
    """The field as a ``companion`` OccupancyGrid (trinary map_server classification)."""
    from mavcore.maps.grid import OccupancyGrid

    pix = f.pixels[::-1]
    return OccupancyGrid(occupied=pix == PIX_OCCUPIED, free=pix == PIX_FREE, resolution_m=f.resolution_m,
                         origin_xy_m=f.origin_xy_m, source=f"{f.name}/map.yaml")


# --- independent coverage checker --------------------------------------------

@dataclass(frozen=True)
class CoverageCheck:
    """Result of :func:`check_coverage` (counts of corridor samples)."""

    corridor_samples: int
    reachable_samples: int
    covered_samples: int

    @property
    def fraction(self) -> float:
        return self.covered_samples / self.reachable_samples if self.reachable_samples else 1.0


def check_coverage(f: Field, path_xy_m: np.ndarray) -> CoverageCheck:
    """Share of the reachable corridor samples the path flies over (module doc)."""
    pix = f.pixels[::-1]
    res = f.resolution_m
    free = pix == PIX_FREE
    rows, cols = free.shape
    clearance = ndimage.distance_transform_edt(np.pad(free, 1))[1:-1, 1:-1] * res
    admissible = clearance >= f.safety_margin_m + res - 1e-9
    labels, _ = ndimage.label(admissible, structure=np.ones((3, 3), dtype=bool))
    path = np.asarray(path_xy_m, float)

    def cell(xy):
        c = np.floor((xy[..., 0] - f.origin_xy_m[0]) / res).astype(np.int64)
        r = np.floor((xy[..., 1] - f.origin_xy_m[1]) / res).astype(np.int64)
        ok = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
        return np.clip(r, 0, rows - 1), np.clip(c, 0, cols - 1), ok

    r0, c0, ok0 = cell(path[0])
    start_label = labels[r0, c0] if ok0 else 0

    a = math.radians(f.row_angle_deg)
    u_dir = np.array([math.cos(a), math.sin(a)])
    n_dir = np.array([-math.sin(a), math.cos(a)])
    corners = np.array([[f.origin_xy_m[0], f.origin_xy_m[1]],
                        [f.origin_xy_m[0] + cols * res, f.origin_xy_m[1]],
                        [f.origin_xy_m[0], f.origin_xy_m[1] + rows * res],
                        [f.origin_xy_m[0] + cols * res, f.origin_xy_m[1] + rows * res]])
    U, V = corners @ u_dir, corners @ n_dir
    s = f.row_spacing_m
    ks = np.arange(math.floor((V.min() - f.row_offset_m) / s) - 1, math.ceil((V.max() - f.row_offset_m) / s) + 1)
    u = np.arange(U.min(), U.max(), res / 2)
    vm = f.row_offset_m + (ks + 0.5) * s
    P = u[None, :, None] * u_dir + vm[:, None, None] * n_dir           # (k, n, 2) mid-line samples

    def vine_at(pts):
        r, c, ok = cell(pts)
        return ok & f.vine[r, c]

    # a row has a vine at along-row position u if any drawn vine cell lies within
    # half a cell of its centre line there (the band is vine_w wide: probe +-w/4)
    def row_here(v_line):
        out = np.zeros(P.shape[:2], dtype=bool)
        for dv in (-0.1, 0.0, 0.1):
            out |= vine_at(u[None, :, None] * u_dir + (v_line + dv)[:, None, None] * n_dir)
        return out

    corridor = row_here(vm - s / 2) & row_here(vm + s / 2)
    pts = P[corridor]
    r, c, ok = cell(pts)
    reach = ok & admissible[r, c] & (labels[r, c] == start_label) & (start_label > 0)
    dense = [path[:1]]
    for p, q in zip(path[:-1], path[1:]):
        n = max(2, int(np.ceil(np.hypot(*(q - p)) / (res / 4))) + 1)
        t = np.linspace(0.0, 1.0, n)[1:, None]
        dense.append((1 - t) * p + t * q)
    tree = cKDTree(np.vstack(dense))
    d, _ = tree.query(pts[reach]) if reach.any() else (np.zeros(0), None)
    return CoverageCheck(corridor_samples=int(len(pts)), reachable_samples=int(reach.sum()),
                         covered_samples=int(np.count_nonzero(d <= s / 4)))


def path_clearance_m(grid, path_xy_m: np.ndarray, step_m: float) -> float:
    """Smallest distance (m) from the path (sampled every ``step_m``) to the centre of a
    non-free cell, the map's outside included (a KD-tree of the non-free cells that touch
    free ones: the nearest non-free cell to a free point is one of those)."""
    nf = np.pad(~grid.free, 1, constant_values=True)
    border = nf & ndimage.binary_dilation(~nf, structure=np.ones((3, 3), bool))
    r, c = np.nonzero(border)
    x, y = grid.cell_to_world(r - 1, c - 1)
    tree = cKDTree(np.column_stack([x, y]))
    path = np.asarray(path_xy_m, float)
    pts = [path[:1]]
    for p, q in zip(path[:-1], path[1:]):
        n = max(2, int(np.ceil(np.hypot(*(q - p)) / step_m)) + 1)
        t = np.linspace(0.0, 1.0, n)[1:, None]
        pts.append((1 - t) * p + t * q)
    return float(tree.query(np.vstack(pts))[0].min())


# --- files ---------------------------------------------------------------------

def write_field(f: Field, out: str | Path) -> Path:
    """Write map.yaml, map.pgm, a gently sloped dem.asc and mission.yaml; return the mission path.

    ``f.safety_margin_m`` is the clearance from the vehicle's **centre** the
    field is drawn around (its necks and doors) and checked against. The
    mission's ``coverage.safety_margin_m`` is measured from the airframe's
    surface (``companion.margins``), so the file holds that clearance less the
    default airframe radius (0.442 m; at least 0): the planner then erodes by
    exactly ``f.safety_margin_m``, and ``companion plan`` warns that the margin
    is below the radius. A field 2 m between rows cannot give the 0.884 m
    vehicle 0.5 m from its surface: the corpus stresses the planner's geometry.
    """
    from companion.margins import airframe_radius_m
    from mavcore.vehicle import VehicleConfig

    surface_margin = max(0.0, round(f.safety_margin_m - airframe_radius_m(VehicleConfig().arm_m), 9))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    generate.write_pgm(out / "map.pgm", f.pixels, maxval=255, binary=True)
    raster = generate.Raster(pixels=f.pixels, origin_xy_m=f.origin_xy_m, resolution_m=f.resolution_m)
    (out / "map.yaml").write_text(generate.map_yaml(raster), encoding="utf-8")
    h, w = f.pixels.shape
    cs, margin = 2.0, 4.0
    x0 = f.origin_xy_m[0] - margin + cs / 2
    y0 = f.origin_xy_m[1] - margin + cs / 2
    nx = int(math.ceil((w * f.resolution_m + 2 * margin) / cs))
    ny = int(math.ceil((h * f.resolution_m + 2 * margin) / cs))
    X, Y = np.meshgrid(x0 + cs * np.arange(nx), y0 + cs * np.arange(ny))
    generate.write_dem(out / "dem.asc", 0.02 * X - 0.01 * Y, x0, y0, cs)
    (out / "mission.yaml").write_text(
        f"# Generated by missions/corpus.py ({f.name}, kind {f.kind}); regenerate rather than edit.\n"
        f"name: {f.name}\nmap: map.yaml\ndem: dem.asc\nhome: {{lat: 44.8, lon: -0.6, alt_m: 30.0}}\n"
        f"flight: {{height_agl_m: 1.5, speed_m_s: 1.0, waypoint_interval_s: 4.0}}\n"
        f"coverage: {{line_spacing_m: {f.row_spacing_m!r}, safety_margin_m: {surface_margin!r}}}\n"
        f"pointing: {{target: centroid}}\n", encoding="utf-8")
    return out / "mission.yaml"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--large", action="store_true", help="the ~10 ha irregular benchmark field")
    ap.add_argument("--hectares", type=float, default=10.0)
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    f = large_irregular(args.hectares) if args.large else draw_field(args.seed)
    path = write_field(f, args.out)
    print(f"{f.name} ({f.kind}): {f.pixels.shape[1]} x {f.pixels.shape[0]} px, {f.area_m2 / 1e4:.2f} ha free, "
          f"rows {f.row_angle_deg:.1f} deg / {f.row_spacing_m:.2f} m -> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
