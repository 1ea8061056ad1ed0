"""Position/velocity receiver (sitl/gnss.py): schedule, latency, hold, noise."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from sitl.gnss import GnssReceiver

FRAME_US = 4000          # 250 Hz sensor frames


def _truth(t_us):
    """A moving truth: p = (t, 2t, 0) m, v = (1, 2, 0) m/s with t in s."""
    t = t_us * 1e-6
    return (t, 2.0 * t, 0.0), (1.0, 2.0, 0.0)


def _run(rx, seconds):
    rx.reset(*_truth(0))
    out = []
    for k in range(1, int(seconds * 1e6) // FRAME_US + 1):
        t = k * FRAME_US
        s = rx.step(t, *_truth(t))
        out.append((t, s, rx.fresh))
    return out


def test_ten_hz_with_80_ms_latency_hand_worked():
    """Measured at 0 (the primed sample, delivered at reset), 100, 200 ms, ...;
    each delivered at t_m + 80 ms and held, stamped with its measurement time,
    carrying the truth *at* t_m."""
    rx = GnssReceiver(100_000, 80_000, 0.0, 0.0, 0.0, np.random.default_rng(0))
    out = _run(rx, 1.0)
    for t, s, fresh in out:
        t_m = ((t - 80_000) // 100_000) * 100_000 if t >= 80_000 else 0
        assert s.time_us == t_m
        assert s.pos_enu_m == _truth(t_m)[0]                  # exact: noise off
        assert fresh == (t >= 180_000 and (t - 80_000) % 100_000 == 0)
    fresh_times = [t for t, _, f in out if f]
    assert fresh_times[:3] == [180_000, 280_000, 380_000]
    assert np.all(np.diff(fresh_times) == 100_000)            # the configured rate


def test_latency_not_a_multiple_of_the_frame_rounds_up_to_the_next_frame():
    rx = GnssReceiver(100_000, 70_000, 0.0, 0.0, 0.0, np.random.default_rng(0))
    out = _run(rx, 0.5)
    fresh = [(t, s.time_us) for t, s, f in out if f]
    assert fresh[:2] == [(172_000, 100_000), (272_000, 200_000)]   # first frame at or after t_m + 70 ms


def test_default_every_frame_without_latency_is_the_frame_itself():
    rx = GnssReceiver(FRAME_US, 0, 0.0, 0.0, 0.0, np.random.default_rng(0))
    for t, s, fresh in _run(rx, 0.1):
        assert fresh and s.time_us == t and s.vel_enu_m_s == (1.0, 2.0, 0.0)


def test_noise_std_per_axis_and_memory_bound():
    rx = GnssReceiver(FRAME_US, 40_000, 0.01, 0.02, 0.03, np.random.default_rng(4))
    rx.reset(*_truth(0))
    errs = []
    longest = 0
    for k in range(1, 6001):
        t = k * FRAME_US
        s = rx.step(t, *_truth(t))
        longest = max(longest, len(rx._pending))
        if rx.fresh:
            p, v = _truth(s.time_us)
            errs.append([s.pos_enu_m[i] - p[i] for i in range(3)] + [s.vel_enu_m_s[i] - v[i] for i in range(3)])
    e = np.array(errs)
    n = len(e)
    lo, hi = chi2.ppf(5e-7, n - 1) / (n - 1), chi2.ppf(1 - 5e-7, n - 1) / (n - 1)
    ratio = e.var(axis=0, ddof=1) / np.array([0.01, 0.01, 0.02, 0.03, 0.03, 0.03]) ** 2
    assert np.all((lo < ratio) & (ratio < hi))
    assert longest <= 40_000 // FRAME_US + 1                  # bounded by latency / period + 1


def test_bad_schedule_is_refused():
    with pytest.raises(ValueError):
        GnssReceiver(0, 0, 0.0, 0.0, 0.0, np.random.default_rng(0))
    with pytest.raises(ValueError):
        GnssReceiver(100_000, -1, 0.0, 0.0, 0.0, np.random.default_rng(0))
    assert math.isfinite(GnssReceiver(1, 0, 0.0, 0.0, 0.0, np.random.default_rng(0)).period_us)
