"""Peaks of a 1-D profile by prominence and distance: ``scipy.signal.find_peaks``'s rule.

``scipy.signal`` imports ``scipy.stats`` and costs about 0.85 s of CPU to
import, a sixth of the time ``companion plan`` may take on a 10 ha field
(issue 18), for the one call of ``companion.coverage.rows``. This is the
same computation for the two options used there, following scipy's
``_local_maxima_1d``, ``_select_by_peak_distance`` and ``_peak_prominences``
step by step; ``tests/test_peaks.py`` checks it against scipy on seeded
profiles with ties and plateaus.
"""

from __future__ import annotations

import math

import numpy as np


def local_maxima(x: np.ndarray) -> np.ndarray:
    """Indices of the local maxima of ``x`` (a plateau gives its middle, rounded down;
    the two ends are never maxima), increasing."""
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    if n < 3:
        return np.zeros(0, dtype=np.intp)
    # runs of equal values: a run is a maximum when both neighbours are lower
    change = np.flatnonzero(np.diff(x) != 0.0) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [n]]) - 1                  # inclusive
    inner = (starts > 0) & (ends < n - 1)
    s, e = starts[inner], ends[inner]
    peak = (x[s - 1] < x[s]) & (x[e + 1] < x[e])
    return ((s[peak] + e[peak]) // 2).astype(np.intp)


def _select_by_distance(peaks: np.ndarray, priority: np.ndarray, distance: float) -> np.ndarray:
    """Keep mask: from the highest peak down, drop the others closer than ``distance`` samples."""
    distance = math.ceil(distance)
    keep = np.ones(peaks.shape[0], dtype=bool)
    order = np.argsort(priority)                              # as scipy (same sort, same ties)
    for j in order[::-1]:
        if not keep[j]:
            continue
        k = j - 1
        while k >= 0 and peaks[j] - peaks[k] < distance:
            keep[k] = False
            k -= 1
        k = j + 1
        while k < peaks.shape[0] and peaks[k] - peaks[j] < distance:
            keep[k] = False
            k += 1
    return keep


def prominences(x: np.ndarray, peaks: np.ndarray) -> np.ndarray:
    """Topographic prominence of each peak: its height above the higher of the two
    minima between it and the nearest higher sample on either side (or the end)."""
    x = np.asarray(x, dtype=float)
    out = np.empty(peaks.shape[0])
    for n, p in enumerate(peaks):
        higher_left = np.flatnonzero(x[:p] > x[p])
        i0 = higher_left[-1] + 1 if higher_left.size else 0
        higher_right = np.flatnonzero(x[p + 1:] > x[p])
        i1 = p + 1 + higher_right[0] if higher_right.size else x.shape[0]
        out[n] = x[p] - max(x[i0:p + 1].min(), x[p:i1].min())
    return out


def find_peaks(x: np.ndarray, prominence: float, distance: float = 1.0) -> np.ndarray:
    """Peaks of ``x`` at least ``distance`` samples apart (the higher kept) whose
    prominence is at least ``prominence``; as ``scipy.signal.find_peaks(x,
    prominence=prominence, distance=distance)[0]``.

    Parameters
    ----------
    x : (n,) array
    prominence : float
        Smallest prominence kept (same unit as ``x``).
    distance : float
        Smallest index distance between two kept peaks, >= 1.

    Returns
    -------
    (k,) int array
        Peak indices, increasing.
    """
    if not distance >= 1:
        raise ValueError(f"distance must be >= 1, got {distance}")
    x = np.asarray(x, dtype=float)
    peaks = local_maxima(x)
    if distance > 1 and peaks.size > 1:
        peaks = peaks[_select_by_distance(peaks, x[peaks], distance)]
    return peaks[prominences(x, peaks) >= prominence]
