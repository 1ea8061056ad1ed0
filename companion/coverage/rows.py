"""Vine-row detection: dominant orientation, spacing and positions of the rows.

The rows are found from the occupied cells alone, so this works on drawn
rows as well as on sparse laser hits on posts and trunks (a SLAM map such
as the LCAS vineyard map: 0.05 m cells, rows ~3 m apart with gaps).

Orientation
    For a candidate row direction ``alpha`` the occupied points are projected
    on the row normal ``n = (-sin a, cos a)``; rows parallel to ``alpha``
    pile up in few bins. The score is the *sharpness* of that projected
    histogram, ``sum(h_k^2) / N^2`` (bin ``b = max(2 h, 0.1 m)``), computed per tile of length ``T`` along the row direction
    and summed over tiles. Tiling makes the score tolerant to the angular
    step: a row tilted by the step smears over ``T tan(step)`` within a
    tile, so ``T = b / tan(step)`` keeps it within one bin. Sweep 0..180 deg
    at 1 deg, then +-1 deg at 0.1 deg, then +-0.1 deg at 0.01 deg; finally
    the direction is corrected by the pooled least-squares slope of the
    points of each found row (d against t), which removes the binning bias
    (and aliasing) of the histogram score.
Spacing
    Autocorrelation (FFT) of the projected occupancy profile at the best
    orientation (bins of one cell, square-rooted so that dense walls do
    not outweigh sparse rows). The period is the first autocorrelation
    peak after the central lobe that reaches half of the highest peak (the
    pitch-detector rule: the fundamental, never a harmonic), refined by a
    parabola through the peak and then by a least-squares fit
    ``offset_k = a + p n_k`` to the rows found below.
Rows
    Peaks of the profile (smoothed over 0.3 m) at least half a period apart
    whose prominence is at least 20 % of the profile's maximum; each row is
    located at the median offset of the points within a quarter period of
    its peak and spans those points along the row direction (the points
    are split at gaps longer than a period and clusters shorter than a
    period, such as a wall crossing the row, are left out). Walls and
    headland edges can be peaks too; :mod:`corridors` keeps only pairs of
    neighbouring rows about one period apart.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from mavcore.errors import PlanError
from mavcore.maps.grid import OccupancyGrid
from .freespace import bbox_cells, dilate_runs
from .peaks import find_peaks

_MAX_SWEEP_POINTS = 30_000
#: directions this close below 180 deg are reported as 0 deg (the same line;
#: 1e-4 deg is 2 mm over 1 km), so east-west rows do not print as "180.000"
WRAP_TOL_DEG = 1e-4
_MAX_SLOPE_POINTS = 300_000
#: points of the final pass (offsets and spans of the rows): thousands per row on a
#: 10 ha field even so; more only costs time
_MAX_ROW_POINTS = 600_000


class RowSpacing(NamedTuple):
    """Detected row spacing (m) and row orientation (deg, ENU from east, CCW, in [0, 180))."""

    spacing_m: float
    orientation_deg: float


@dataclass(frozen=True, eq=False)
class RowStructure:
    """Rows found in an occupancy grid, in the grid's metric frame G (see freespace).

    Attributes
    ----------
    spacing_m : float
        Row period (m).
    angle_g_rad : float
        Row direction in G (rad, in [0, pi)).
    orientation_deg : float
        Row direction in the world (ENU deg from east, in [0, 180)).
    offsets_m : (k,) float
        Row centre lines: offsets along the normal ``n = (-sin a, cos a)`` (m), ascending.
    spans_m : (k, 2) float
        Extent of each row along ``u = (cos a, sin a)`` (m).
    """

    spacing_m: float
    angle_g_rad: float
    orientation_deg: float
    offsets_m: np.ndarray
    spans_m: np.ndarray


class BorderCells(NamedTuple):
    """The occupied cells that border free space (:func:`border_cells`), as flat
    indices into a box of the grid, turned into points only when asked."""

    flat: np.ndarray        # (N,) int64, ascending: np.nonzero order of the box
    width: int              # columns of the box
    r0: int                 # the box's first row and column in the grid
    c0: int
    resolution_m: float

    def points(self, n_max: int | None = None) -> np.ndarray:
        """(n, 2) G-frame centres (m) of every ``ceil(N / n_max)``-th cell (all of them
        when ``N <= n_max`` or without ``n_max``): a deterministic stride subsample (no
        randomness needed for a statistic), the other points never built."""
        f = self.flat if n_max is None or len(self.flat) <= n_max else \
            self.flat[:: int(np.ceil(len(self.flat) / n_max))]
        r, c = np.divmod(f, self.width)
        h = self.resolution_m
        return np.column_stack([(c + self.c0 + 0.5) * h, (r + self.r0 + 0.5) * h])


def border_cells(grid: OccupancyGrid) -> BorderCells:
    """The occupied cells that border free space (:func:`occupied_points_g`)."""
    h = grid.resolution_m
    k = max(2, int(np.ceil(0.3 / h)))
    r0, r1, c0, c1 = bbox_cells(grid.free)
    if r1 <= r0:
        return BorderCells(np.zeros(0, dtype=np.int64), 1, 0, 0, h)
    r0, r1 = max(0, r0 - k), min(grid.shape[0], r1 + k)
    c0, c1 = max(0, c0 - k), min(grid.shape[1], c1 + k)
    diamond = k - np.abs(np.arange(-k, k + 1))
    near_free = dilate_runs(grid.free[r0:r1, c0:c1], diamond, outside=False)
    near_free &= grid.occupied[r0:r1, c0:c1]
    return BorderCells(np.flatnonzero(near_free), c1 - c0, r0, c0, h)


def occupied_points_g(grid: OccupancyGrid) -> np.ndarray:
    """(N, 2) G-frame centres (m) of the occupied cells that border free space.

    Only cells within ``k = max(2, ceil(0.3 m / h))`` 4-connected steps of a
    free cell count (the dilation by ``k`` crosses, a diamond): rows, posts
    and the edges of large occupied areas, not their interiors (a field
    surrounded by occupied land would otherwise swamp the rows). Only the
    free cells' bounding box grown by ``k`` can hold such cells. In
    ``np.nonzero`` order.
    """
    return border_cells(grid).points()


def _project(pts: np.ndarray, alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """Along-row ``t`` and normal ``d`` coordinates (m) of G points for direction alpha."""
    ca, sa = np.cos(alpha), np.sin(alpha)
    return pts[:, 0] * ca + pts[:, 1] * sa, -pts[:, 0] * sa + pts[:, 1] * ca


def _sharpness(pts: np.ndarray, alphas: np.ndarray, bin_m: float, tile_m: float) -> np.ndarray:
    """Tiled projected-histogram sharpness for each candidate angle (see module doc)."""
    n = len(pts)
    radius = float(np.hypot(*(pts.max(axis=0) - pts.min(axis=0)))) + 2 * bin_m
    centre = 0.5 * (pts.max(axis=0) + pts.min(axis=0))
    q = pts - centre
    out = np.empty(len(alphas))
    qx, qy = np.ascontiguousarray(q[:, 0]), np.ascontiguousarray(q[:, 1])
    for i, a in enumerate(alphas):
        ca, sa = np.cos(a), np.sin(a)
        ti = ((qx * ca + qy * sa + radius) / tile_m).astype(np.int64)
        di = ((-qx * sa + qy * ca + radius) / bin_m).astype(np.int64)
        # sum of squared bin counts: any one-to-one numbering of the occupied
        # (tile, bin) pairs gives the same integer, so number them within the
        # points' own range instead of all ntiles * nbins bins
        d_lo = di.min()
        key = (ti - ti.min()) * (di.max() - d_lo + 1) + (di - d_lo)
        h = np.bincount(key)
        out[i] = float(np.dot(h, h)) / (n * n)
    return out


def _best_angle(pts: np.ndarray, bin_m: float) -> float:
    """Coarse-to-fine sharpness sweep; returns the row direction in G (rad, [0, pi))."""
    best = 0.0
    for step_deg, half_deg in ((1.0, 90.0), (0.1, 1.0), (0.01, 0.1)):
        if half_deg >= 90.0:
            cand = np.deg2rad(np.arange(0.0, 180.0, step_deg))
        else:
            cand = best + np.deg2rad(np.arange(-half_deg, half_deg + step_deg / 2, step_deg))
        tile = bin_m / np.tan(np.deg2rad(step_deg))
        score = _sharpness(pts, cand, bin_m, tile)
        best = float(cand[int(np.argmax(score))])
    return best % np.pi


def _profile(d: np.ndarray, cell_m: float) -> tuple[np.ndarray, float]:
    """Square-rooted occupancy profile along the normal (bins of ``cell_m``) and its origin (m).

    The square root compresses the dynamic range so a dense wall or headland
    edge does not outweigh many sparse rows of laser hits.
    """
    lo = float(d.min())
    return np.sqrt(np.bincount(((d - lo) / cell_m).astype(np.int64)).astype(float)), lo


def _period(prof: np.ndarray, cell_m: float, min_m: float) -> float | None:
    """Row period (m) from the autocorrelation of the profile, or None."""
    m = len(prof)
    if m < 8:
        return None
    x = prof - prof.mean()
    spec = np.fft.rfft(x, 2 * m)
    acf = np.fft.irfft(spec * np.conj(spec))[: m // 2]
    if acf[0] <= 0:
        return None
    # skip the central lobe: start after its first local minimum (and min_m)
    start = max(int(np.ceil(min_m / cell_m)), 1)
    dif = np.diff(acf)
    mins = np.flatnonzero((dif[:-1] < 0) & (dif[1:] >= 0)) + 1
    mins = mins[mins >= start]
    if len(mins) == 0:
        return None
    k0 = int(mins[0])
    if k0 >= len(acf) - 2:
        return None
    # fundamental = the first local maximum reaching half the highest one
    # (as pitch detectors do), so a harmonic never wins by chance
    top = float(acf[k0:].max())
    if top < 0.05 * acf[0]:
        return None
    peaks = np.flatnonzero((dif[:-1] > 0) & (dif[1:] <= 0)) + 1
    peaks = peaks[(peaks > k0) & (acf[peaks] >= 0.5 * top)]
    if len(peaks) == 0 or peaks[0] >= len(acf) - 1:
        return None
    k = int(peaks[0])
    y0, y1, y2 = acf[k - 1], acf[k], acf[k + 1]
    den = y0 - 2.0 * y1 + y2
    return float((k + (0.5 * (y0 - y2) / den if den < 0 else 0.0)) * cell_m)


def _refine_period(offsets: np.ndarray, period: float) -> float:
    """Least-squares period from the row offsets (m): offset_k = a + p n_k.

    ``n_k`` counts periods from the first row; only rows within a tenth of a
    period of a whole multiple take part. Falls back to ``period``.
    """
    if len(offsets) < 2:
        return period
    n = np.round((offsets - offsets[0]) / period)
    ok = np.abs(offsets - offsets[0] - n * period) <= period / 10
    if np.unique(n[ok]).size < 2:
        return period
    return float(np.polyfit(n[ok], offsets[ok], 1)[0])


def _span(t_sorted: np.ndarray, gap_m: float) -> tuple[float, float]:
    """Extent of a row along its direction from its points' sorted ``t`` (m).

    The points are split at gaps longer than ``gap_m``; clusters shorter than
    ``gap_m`` (a wall crossing the row, a stray post) are dropped unless
    nothing else is left.
    """
    cut = np.flatnonzero(np.diff(t_sorted) > gap_m) + 1
    lo = np.concatenate([[0], cut])
    hi = np.concatenate([cut, [len(t_sorted)]]) - 1
    long = (t_sorted[hi] - t_sorted[lo]) >= gap_m
    if not long.any():
        return float(t_sorted[0]), float(t_sorted[-1])
    return float(t_sorted[lo[long]].min()), float(t_sorted[hi[long]].max())


def _rows_at(pts: np.ndarray, alpha: float, h: float, min_spacing_m: float):
    """Period, row offsets, row spans and pooled in-row slope at direction alpha, or None."""
    t, d = _project(pts, alpha)
    prof, lo = _profile(d, h)
    period = _period(prof, h, min_spacing_m)
    if period is None:
        return None
    # rows = peaks of the (smoothed) profile at least half a period apart
    # whose prominence is at least 20 % of the highest value (prominence,
    # not height, so the pedestal of a wall crossing every row is ignored)
    width = max(3, int(round(0.3 / h)) | 1)
    smooth = np.convolve(prof, np.ones(width) / width, mode="same")
    # scipy.signal.find_peaks's rule without its 0.85 s import (companion/coverage/peaks.py)
    peaks = find_peaks(smooth, prominence=0.2 * smooth.max(), distance=max(1, int(0.5 * period / h)))
    offsets, spans = [], []
    num = den = 0.0
    order = np.argsort(d, kind="stable")
    d_sorted, t_by_d = d[order], t[order]
    for pk in peaks:
        centre = lo + (pk + 0.5) * h
        i0, i1 = np.searchsorted(d_sorted, [centre - period / 4, centre + period / 4], side="left")
        dd, tt = d_sorted[i0:i1], t_by_d[i0:i1]
        offsets.append(float(np.median(dd)))
        t0, t1 = _span(np.sort(tt), period)
        spans.append((t0, t1))
        inside = (tt >= t0) & (tt <= t1)
        tc = tt[inside] - tt[inside].mean()
        num += float(np.dot(tc, dd[inside] - dd[inside].mean()))
        den += float(np.dot(tc, tc))
    period = _refine_period(np.asarray(offsets), period)
    slope = num / den if den > 0 else 0.0
    return period, np.asarray(offsets), np.asarray(spans).reshape(-1, 2), slope


def detect_rows(grid: OccupancyGrid, min_spacing_m: float = 1.0) -> RowStructure | None:
    """Find the vine rows of ``grid`` (see module doc); None if no periodic rows.

    Parameters
    ----------
    grid : OccupancyGrid
    min_spacing_m : float
        Shortest row period considered (m).
    """
    cells = border_cells(grid)      # millions of cells at 10 ha: points only for the subsamples
    if len(cells.flat) < 10:
        return None
    h = grid.resolution_m
    bin_m = max(2 * h, 0.1)
    alpha = _best_angle(cells.points(_MAX_SWEEP_POINTS), bin_m)
    # the first pass only yields the in-row slope: a statistic, so a stride
    # subsample of the points is enough (the final pass uses up to _MAX_ROW_POINTS)
    found = _rows_at(cells.points(_MAX_SLOPE_POINTS), alpha, h, min_spacing_m)
    if found is None:
        return None
    # refine the direction by the pooled least-squares slope of the rows'
    # points (d against t within each row), then find the rows again
    alpha = (alpha + np.arctan(found[3])) % np.pi
    found = _rows_at(cells.points(_MAX_ROW_POINTS), alpha, h, min_spacing_m)
    if found is None:
        return None
    period, offsets, spans, _ = found
    world_deg = float(np.rad2deg(alpha + grid.origin_yaw_rad) % 180.0)
    if world_deg >= 180.0 - WRAP_TOL_DEG:
        world_deg = 0.0
    return RowStructure(spacing_m=period, angle_g_rad=alpha, orientation_deg=world_deg,
                        offsets_m=offsets, spans_m=spans)


def detect_row_spacing(grid: OccupancyGrid) -> RowSpacing:
    """Row spacing (m) and orientation (deg, ENU from east, in [0, 180)) of ``grid``.

    Raises
    ------
    PlanError
        Naming the map, if the occupied cells show no periodic rows.
    """
    rows = detect_rows(grid)
    if rows is None or len(rows.offsets_m) < 2:
        raise PlanError(grid.source, "cannot detect vine rows to derive the line spacing; "
                                     "set coverage.line_spacing_m")
    return RowSpacing(rows.spacing_m, rows.orientation_deg)
