"""``companion.coverage.peaks.find_peaks`` against ``scipy.signal.find_peaks`` (the
independent reference it replaces at run time, see the module doc)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import find_peaks as scipy_find_peaks

from companion.coverage.peaks import find_peaks, local_maxima


def _profiles():
    rng = np.random.default_rng(18)
    for n in (3, 10, 200, 3000):
        yield rng.normal(size=n)                             # no ties
        yield np.round(rng.normal(size=n), 1)                # ties and plateaus
        yield np.convolve(rng.poisson(3.0, n).astype(float), np.ones(5) / 5, mode="same")
    # a row profile: periodic peaks on a pedestal, one wall crossing them
    d = np.arange(4000) * 0.05
    prof = np.maximum(0.0, np.cos(2 * np.pi * d / 2.5)) ** 4 * 100 + 30 + rng.poisson(2.0, d.size)
    prof[1800:1830] += 500
    yield np.convolve(prof, np.ones(7) / 7, mode="same")
    yield np.array([0.0, 1.0, 1.0, 1.0, 0.0, 2.0, 2.0, 0.0, 1.0, 1.0])   # plateaus, even and odd


@pytest.mark.parametrize("k", range(14))
@pytest.mark.parametrize("distance", [1, 3, 25.5])
@pytest.mark.parametrize("frac", [0.0, 0.2, 0.6])
def test_same_peaks_as_scipy(k, distance, frac):
    x = list(_profiles())[k]
    prominence = frac * float(np.max(x))
    want = scipy_find_peaks(x, prominence=prominence, distance=distance)[0]
    assert np.array_equal(find_peaks(x, prominence, distance), want)


def test_plateaus_give_their_middle_and_the_ends_are_never_peaks():
    x = np.array([5.0, 1.0, 3.0, 3.0, 3.0, 3.0, 0.0, 4.0, 4.0, 4.0, 2.0, 9.0])
    # plateau 2..5 -> (2 + 5) // 2 = 3; plateau 7..9 -> 8; index 0 and 11 are ends
    assert local_maxima(x).tolist() == [3, 8]
