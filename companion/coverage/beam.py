"""The beam of parallel main lines: cutting, ISOA orientation sweep, phase.

Geometry in the grid frame G (see :mod:`freespace`): a beam with direction
``alpha`` has unit direction ``u = (cos a, sin a)`` and normal
``n = (-sin a, cos a)``; line ``m`` is ``{o_m n + t u}`` with offsets
``o_m = phase + m s`` (``s`` the line spacing).

ISOA score (Horvath, Pozna & Precup 2018: the beam orientation that gives
the fewest and longest main segments). For one orientation and phase the
main segments have lengths ``l_i`` (runs of eroded free space along the
lines, at least ``min_segment_m`` long) and the score is

    S = sum(l_i^2) / sum(l_i)

the length-weighted mean segment length: the expected length of the
segment that covers a random point of the beam. For a fixed covered length
it is the covered length divided by the number of segments when they are
equal, so maximising it asks for fewer and longer segments at once; a
phase or angle that misses the free space (lines lying on the rows) does
not win because its few segments are short. Each orientation is scored at
``K = 4`` phases a quarter spacing apart (at least one falls in any
corridor wider than s/4) and keeps the best.

Sweep: all orientations 0..180 deg at the configured step (<= 1 deg) on a
block-averaged mask (cells of at most s/4, at most ~250 000 of them), then
+-1 step at 1/10 of it on a finer mask, then +-0.1 step at 1/50 of it at
full resolution; at most 48 lines per phase are scored (an evenly spread
subset: S is a statistic of the segments). At each level the orientation
kept is the middle of the run of near-best scores (within 0.5 %) around
the best one, the symmetric choice on a plateau. All masks are cropped to
the bounding box of the eroded cells and padded by one blocked cell, so a
sample is one float32 multiply-add per axis, a clip and a flat ``take``.
Which of the sweep's result and the rows' direction is flown is decided in
:mod:`plan` (rows win when the line spacing is the row spacing).

Phase: the beam is shifted so the lines follow the middle of the corridors.
With known corridors (rows found, beam along them) the phase is the
circular mean of the corridor centre offsets modulo the spacing
(:func:`corridor_phase`). Otherwise (:func:`beam_phase`) the clearance of
every free cell (capped at s/2, from a distance transform of the map
subsampled to at most ~2e6 cells) is folded modulo the spacing along the
normal, and the phase maximising that folded profile is where lines have
the most room on both sides.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .freespace import FreeSpace, Raster

_PHASES = 4
_MAX_LINES = 48
_MAX_COARSE_CELLS = 250_000


@dataclass(frozen=True, eq=False)
class Segments:
    """Main segments of a beam, in beam coordinates.

    Attributes
    ----------
    line : (k,) int
        Index of the beam line (ascending offset order).
    offset_m : (k,) float
        Offset of the segment's line along the normal (m).
    t0_m, t1_m : (k,) float
        Start and end along the line direction (m), ``t0 < t1``.
    """

    line: np.ndarray
    offset_m: np.ndarray
    t0_m: np.ndarray
    t1_m: np.ndarray

    @property
    def length_m(self) -> np.ndarray:
        return self.t1_m - self.t0_m

    def endpoints_g(self, alpha: float) -> tuple[np.ndarray, np.ndarray]:
        """(k, 2) start and end points in G (m)."""
        u = np.array([np.cos(alpha), np.sin(alpha)])
        n = np.array([-np.sin(alpha), np.cos(alpha)])
        base = self.offset_m[:, None] * n
        return base + self.t0_m[:, None] * u, base + self.t1_m[:, None] * u


def bbox_corners_g(free: FreeSpace) -> np.ndarray:
    """(4, 2) G corners (m) of the bounding box of the eroded cells."""
    r0, r1, c0, c1 = free.bbox_cells
    h = free.resolution_m
    x0, x1, y0, y1 = c0 * h, c1 * h, r0 * h, r1 * h
    return np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]])


def _ranges(corners: np.ndarray, alpha: float) -> tuple[float, float, float, float]:
    u = np.array([np.cos(alpha), np.sin(alpha)])
    n = np.array([-np.sin(alpha), np.cos(alpha)])
    t, o = corners @ u, corners @ n
    return float(o.min()), float(o.max()), float(t.min()), float(t.max())


def cut_lines(raster: Raster, alpha: float, offsets: np.ndarray, t_lo: float, t_hi: float,
              step_m: float, min_segment_m: float, dtype=np.float32) -> Segments:
    """Cut beam lines into main segments: runs of True cells of ``raster``.

    The lines are sampled every ``step_m`` (sub-cell at full resolution) by
    nearest-cell lookup; a segment runs from its first to its last free
    sample, so its end points are inside the mask. Segments shorter than
    ``min_segment_m`` are dropped.
    """
    t = t_lo + step_m * np.arange(int(np.floor((t_hi - t_lo) / step_m)) + 1)
    offsets = np.asarray(offsets, dtype=float)
    free = raster.sample_lines(alpha, offsets, t, dtype)
    # one False column before each line: the flat changes of the padded rows
    # alternate run start, run end (the end one past the last free sample)
    # because each line starts and ends outside a run
    n_t = len(t)
    padded = np.zeros((len(offsets), n_t + 2), dtype=bool)
    padded[:, 1:-1] = free
    change = np.flatnonzero(padded[:, 1:] != padded[:, :-1])
    si, ei = change[0::2], change[1::2]
    sl = si // (n_t + 1)
    si, ei = si - sl * (n_t + 1), ei - sl * (n_t + 1)
    t0, t1 = t[si], t[ei - 1]
    keep = (t1 - t0) >= min_segment_m
    return Segments(line=sl[keep], offset_m=offsets[sl[keep]], t0_m=t0[keep], t1_m=t1[keep])


def _score(raster: Raster, corners: np.ndarray, alphas: np.ndarray,
           spacing_m: float, min_segment_m: float) -> np.ndarray:
    """ISOA score S (module doc) of each orientation, best over K phases."""
    out = np.zeros(len(alphas))
    for i, a in enumerate(alphas):
        o_lo, o_hi, t_lo, t_hi = _ranges(corners, a)
        m = np.arange(int(np.floor((o_hi - o_lo) / spacing_m)) + 1)
        if len(m) > _MAX_LINES:
            m = m[np.linspace(0, len(m) - 1, _MAX_LINES).round().astype(int)]
        k = np.arange(_PHASES)
        offs = (o_lo + spacing_m * (m[None, :] + k[:, None] / _PHASES)).ravel()
        seg = cut_lines(raster, a, offs, t_lo, t_hi, raster.cell_m, min_segment_m)
        if len(seg.line) == 0:
            continue
        phase = seg.line // len(m)
        ln = seg.length_m
        num = np.bincount(phase, ln * ln, _PHASES)
        den = np.bincount(phase, ln, _PHASES)
        out[i] = np.max(np.where(den > 0, num / np.maximum(den, 1e-12), 0.0))
    return out


def _plateau_centre(score: np.ndarray, wrap: bool, rel_tol: float = 0.005) -> int:
    """Index in the middle of the run of near-best scores around the best one.

    Scores within ``rel_tol`` of the maximum count as ties; on such a plateau
    (a beam that can tilt without being cut more often) the middle is the
    symmetric choice. ``wrap``: the candidates cover a full half-turn.
    """
    n = len(score)
    good = score >= (1.0 - rel_tol) * score.max()
    i = int(np.argmax(score))
    lo = hi = i
    while (hi - lo + 1) < n and good[(lo - 1) % n if wrap else max(lo - 1, 0)] and (wrap or lo > 0):
        lo -= 1
    while (hi - lo + 1) < n and good[(hi + 1) % n if wrap else min(hi + 1, n - 1)] and (wrap or hi < n - 1):
        hi += 1
    return ((lo + hi) // 2) % n


@dataclass(frozen=True)
class Sweep:
    """Result of the ISOA orientation sweep.

    Attributes
    ----------
    alpha_rad : float
        Best beam direction in G (rad, [0, pi)).
    score_m : float
        Its ISOA score S (m, module doc) at full resolution.
    """

    alpha_rad: float
    score_m: float


def full_scores(free: FreeSpace, alphas, spacing_m: float, min_segment_m: float) -> np.ndarray:
    """ISOA scores S (m) of the beam directions ``alphas`` (G, rad) at full resolution."""
    return _score(free.raster(), bbox_corners_g(free), np.atleast_1d(np.asarray(alphas, float)),
                  spacing_m, min_segment_m)


def isoa_sweep(free: FreeSpace, spacing_m: float, min_segment_m: float,
               step_deg: float = 1.0) -> Sweep:
    """Beam direction by the coarse-to-fine ISOA sweep (module doc)."""
    h = free.resolution_m
    corners = bbox_corners_g(free)
    extent = corners.max(axis=0) - corners.min(axis=0)
    coarse_cell = min(spacing_m / 4, np.sqrt(extent[0] * extent[1] / _MAX_COARSE_CELLS))
    f1 = max(1, int(coarse_cell / h))
    f2 = max(1, f1 // 3)
    levels = ((f1, step_deg, 90.0), (f2, step_deg / 10, step_deg), (1, step_deg / 50, step_deg / 10))
    best, best_score = 0.0, 0.0
    for f, step, half in levels:
        if half >= 90.0:
            cand = np.deg2rad(np.arange(0.0, 180.0, step))
        else:
            cand = best + np.deg2rad(np.arange(-half, half + step / 2, step))
        score = _score(free.raster(f), corners, cand, spacing_m, min_segment_m)
        i = _plateau_centre(score, wrap=half >= 90.0)
        best, best_score = float(cand[i]), float(score[i])
    return Sweep(alpha_rad=best % np.pi, score_m=best_score)


def corridor_phase(corridor_offsets_m: np.ndarray, spacing_m: float) -> float:
    """Offset (m, modulo the spacing) of the beam through the corridor centres (module doc).

    ``corridor_offsets_m``: corridor centre offsets along the beam normal (m).
    The circular mean keeps corridors on both sides of the wrap-around together.
    """
    ang = 2 * np.pi * np.asarray(corridor_offsets_m, float) / spacing_m
    mean = np.arctan2(np.sin(ang).mean(), np.cos(ang).mean())
    return float((mean / (2 * np.pi) * spacing_m) % spacing_m)


def beam_phase(free: FreeSpace, alpha: float, spacing_m: float, max_cells: int = 2_000_000) -> float:
    """Offset (m, modulo the spacing) that puts the lines mid-corridor (module doc)."""
    h = free.resolution_m
    f = max(1, int(np.ceil(np.sqrt(free.free.size / max_cells))))
    clr = free.clearance_coarse(f)
    r, c = np.nonzero(clr > 0)
    w = np.minimum(clr[r, c], spacing_m / 2).astype(float)
    gx, gy = (c * f + 0.5) * h, (r * f + 0.5) * h
    d = -gx * np.sin(alpha) + gy * np.cos(alpha)
    nb = max(8, int(round(spacing_m / (h / 2))))
    x = np.mod(d, spacing_m) / spacing_m * nb
    i0 = np.floor(x).astype(np.int64)
    w1 = x - i0
    prof = np.bincount(i0 % nb, w * (1 - w1), nb) + np.bincount((i0 + 1) % nb, w * w1, nb)
    prof = prof + 0.5 * (np.roll(prof, 1) + np.roll(prof, -1))
    return float((int(np.argmax(prof)) / nb) * spacing_m)


def main_segments(free: FreeSpace, alpha: float, spacing_m: float, phase_m: float,
                  min_segment_m: float) -> Segments:
    """All main segments of the beam at full resolution (samples every half cell)."""
    h = free.resolution_m
    corners = bbox_corners_g(free)
    o_lo, o_hi, t_lo, t_hi = _ranges(corners, alpha)
    m0 = int(np.ceil((o_lo - phase_m) / spacing_m))
    m1 = int(np.floor((o_hi - phase_m) / spacing_m))
    offsets = phase_m + spacing_m * np.arange(m0, m1 + 1)
    return cut_lines(free.raster(), alpha, offsets, t_lo, t_hi, h / 2, min_segment_m, np.float64)
