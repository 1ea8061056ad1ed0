"""Corridors between vine rows and the coverage measure.

A corridor is the free band between two neighbouring detected rows whose
offsets differ by the row period within 25 %; its centre line runs at the
mid offset, along the row direction, over the stretch where both rows
exist (the intersection of their spans).

Coverage fraction: the centre lines are sampled every cell; a sample is
covered when a flown main segment running along the rows (within 5 deg of
the row direction) passes within half a line spacing of it. The fraction
is covered samples over all samples (all corridors together). Without
corridors (no rows in the map) it falls back to the share of eroded free
cells within half a line spacing of a main segment.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..polyline import segment_distances
from .freespace import FreeSpace
from .rows import RowStructure

_ALONG_TOL_RAD = np.deg2rad(5.0)


@dataclass(frozen=True, eq=False)
class Corridors:
    """Corridor centre lines in G (m): offset along the row normal and t-range along the rows."""

    angle_g_rad: float
    offset_m: np.ndarray
    t0_m: np.ndarray
    t1_m: np.ndarray

    def centre_lines_g(self) -> np.ndarray:
        """(k, 2, 2) centre-line end points in G (m)."""
        u = np.array([np.cos(self.angle_g_rad), np.sin(self.angle_g_rad)])
        n = np.array([-np.sin(self.angle_g_rad), np.cos(self.angle_g_rad)])
        base = self.offset_m[:, None] * n
        return np.stack([base + self.t0_m[:, None] * u, base + self.t1_m[:, None] * u], axis=1)


def find_corridors(rows: RowStructure | None) -> Corridors | None:
    """Corridors between neighbouring rows one period apart (module doc); None if none."""
    if rows is None or len(rows.offsets_m) < 2:
        return None
    o, sp, p = rows.offsets_m, rows.spans_m, rows.spacing_m
    gap = np.diff(o)
    t0 = np.maximum(sp[:-1, 0], sp[1:, 0])
    t1 = np.minimum(sp[:-1, 1], sp[1:, 1])
    ok = (np.abs(gap - p) <= 0.25 * p) & (t1 > t0)
    if not ok.any():
        return None
    return Corridors(angle_g_rad=rows.angle_g_rad, offset_m=0.5 * (o[:-1] + o[1:])[ok],
                     t0_m=t0[ok], t1_m=t1[ok])


def corridor_coverage(corr: Corridors, main_g: np.ndarray, line_spacing_m: float,
                      step_m: float) -> np.ndarray:
    """(k,) covered fraction of each corridor's centre line (module doc)."""
    a, b = main_g[:, 0], main_g[:, 1]
    d = b - a
    ang = np.arctan2(d[:, 1], d[:, 0])
    diff = np.abs((ang - corr.angle_g_rad + np.pi / 2) % np.pi - np.pi / 2)
    a, b = a[diff <= _ALONG_TOL_RAD], b[diff <= _ALONG_TOL_RAD]
    ends = corr.centre_lines_g()
    out = np.zeros(len(corr.offset_m))
    if len(a) == 0:
        return out
    # offsets of the segment ends across the rows: a segment whose two ends
    # lie on the same side, more than half a spacing from a centre line,
    # stays that far from all of it (the offset is linear along a segment)
    nrm = np.array([-np.sin(corr.angle_g_rad), np.cos(corr.angle_g_rad)])
    da, db = a @ nrm, b @ nrm
    d_lo, d_hi = np.minimum(da, db), np.maximum(da, db)
    half = 0.5 * line_spacing_m
    for i, (p0, p1) in enumerate(ends):
        near = (d_lo <= corr.offset_m[i] + half) & (d_hi >= corr.offset_m[i] - half)
        if not near.any():
            continue
        n = max(2, int(np.ceil(np.hypot(*(p1 - p0)) / step_m)) + 1)
        s = np.linspace(0.0, 1.0, n)[:, None]
        q = (1 - s) * p0 + s * p1
        dist = segment_distances(q, a[near], b[near]).min(axis=1)
        out[i] = float(np.mean(dist <= half))
    return out


def coverage_fraction(corr: Corridors | None, free: FreeSpace, main_g: np.ndarray,
                      line_spacing_m: float) -> float:
    """Total covered fraction of the corridors' centre lines (module doc)."""
    h = free.resolution_m
    if corr is not None:
        per = corridor_coverage(corr, main_g, line_spacing_m, h)
        lengths = corr.t1_m - corr.t0_m
        return float(np.sum(per * lengths) / np.sum(lengths))
    # fallback: share of eroded cells within half a spacing of a main segment
    f = max(1, int(np.ceil(np.sqrt(free.eroded.size / 1_000_000))))
    er = free.eroded[::f, ::f]
    hit = np.zeros(er.shape, dtype=bool)
    cell = f * h
    for p0, p1 in main_g:
        n = int(np.ceil(np.hypot(*(p1 - p0)) / (cell / 2))) + 1
        s = np.linspace(0.0, 1.0, n)[:, None]
        q = (1 - s) * p0 + s * p1
        r = np.clip((q[:, 1] / cell).astype(int), 0, er.shape[0] - 1)
        c = np.clip((q[:, 0] / cell).astype(int), 0, er.shape[1] - 1)
        hit[r, c] = True
    if not er.any():
        return 0.0
    dist = ndimage.distance_transform_edt(~hit) * cell
    return float(np.mean(dist[er] <= 0.5 * line_spacing_m + cell))
