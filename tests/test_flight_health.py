"""LinkHealth's verdicts at their thresholds (issue 19: a failsafe test must fail when broken).

Frames are synthesised with wall = vehicle time + a chosen delay, so the jitter,
the loss fraction and the clock ratio of each case are known by construction;
each threshold of ``HealthConfig`` (documented defaults) is probed on both sides.
"""

from __future__ import annotations

import re

import pytest

from companion.flight.health import HealthConfig, LinkHealth

DT = 0.004   # 250 Hz sensor frames


def feed(h: LinkHealth, n: int, delay=lambda k: 0.0, t0: float = 0.0, speed: float = 1.0, keep=lambda k: True):
    """Frame k at vehicle time t0 + k DT arrives at wall (t0 + k DT) / speed + delay(k);
    frames with keep(k) false are lost. Returns [(k, verdict)] for the non-None verdicts."""
    out = []
    for k in range(n):
        if not keep(k):
            continue
        t = t0 + k * DT
        v = h.observe(t / speed + delay(k), t)
        if v is not None:
            out.append((k, v))
    return out


def test_documented_defaults():
    c = HealthConfig()
    assert (c.window_s, c.max_jitter_s, c.max_loss_fraction, c.lockstep_ratio) == (1.0, 0.012, 0.3, 1.3)


def test_clean_real_time_link_has_no_verdict_ratio_one_and_zero_jitter():
    h = LinkHealth(DT)
    assert feed(h, 1000) == []
    assert h.ratio == pytest.approx(1.0, rel=1e-9)
    assert h.jitter_p95_s == pytest.approx(0.0, abs=1e-12)
    assert h.n_lost == 0


@pytest.mark.parametrize("delay_ms,flag", [(11.0, False), (13.0, True), (20.0, True)])
def test_jitter_just_over_12_ms_is_flagged_just_under_is_not(delay_ms, flag):
    """Every 5th frame late by ``delay_ms``: 20 % of the window, so the 95th
    percentile of the extra delay is ``delay_ms`` (the rest are on time)."""
    h = LinkHealth(DT)
    verdicts = feed(h, 1000, delay=lambda k: delay_ms * 1e-3 if k % 5 == 0 else 0.0)
    assert bool(verdicts) is flag
    assert h.jitter_p95_s == pytest.approx(delay_ms * 1e-3, abs=1e-9)
    if flag:
        assert verdicts[-1][1] == f"link jitter {delay_ms:.0f} ms (95th percentile)"


def test_a_constant_base_delay_is_not_jitter():
    h = LinkHealth(DT)
    assert feed(h, 1000, delay=lambda k: 0.25) == []
    assert h.jitter_p95_s == pytest.approx(0.0, abs=1e-9)


def test_the_first_verdict_waits_for_half_a_window_and_comes_every_25_frames():
    """Verdicts only on frames 25, 50, ... and once the window spans >= 0.5 s: frame
    125 spans 124 x 4 ms = 0.496 s (too short), frame 150 spans 0.596 s."""
    h = LinkHealth(DT)
    verdicts = feed(h, 400, delay=lambda k: 0.05 if k % 2 else 0.0)
    ks = [k + 1 for k, _ in verdicts]            # frames observed so far
    assert ks[0] == 150
    assert all(n % 25 == 0 for n in ks) and ks == list(range(150, 401, 25))


@pytest.mark.parametrize("window_s,frames_in_window,flag", [(0.85, 9, False), (0.95, 10, True)])
def test_at_least_ten_frames_are_needed(window_s, frames_in_window, flag):
    """At 10 Hz a window of 0.85 s holds 9 frames (no verdict), 0.95 s holds 10."""
    h = LinkHealth(0.1, HealthConfig(window_s=window_s))
    out = []
    for k in range(25):
        t = 0.1 * k
        out.append(h.observe(t + (0.05 if k % 2 else 0.0), t))
    assert len(h._w) == frames_in_window
    assert (out[-1] is not None) is flag


def test_the_window_keeps_exactly_window_s_of_frames():
    """Frames with wall_k >= wall_now - window_s stay: 1 s at 250 Hz is 251 frames."""
    h = LinkHealth(DT)
    feed(h, 600)
    assert len(h._w) == 251


@pytest.mark.parametrize("every,flag", [(2, True), (3, True), (4, False)])
def test_loss_over_30_percent_is_flagged(every, flag):
    """One frame in ``every`` lost: 50 %, 33 %, 25 % of the frames (limit 30 %)."""
    h = LinkHealth(DT)
    verdicts = feed(h, 1000, keep=lambda k: k % every != 0)
    assert bool(verdicts) is flag
    # seen lost frames: not frame 0 (before the first) nor 999 (no frame after it)
    assert h.n_lost == len(range(every, 999, every))
    if flag:
        pct = int(re.fullmatch(r"(\d+)% of the sensor frames lost", verdicts[-1][1]).group(1))
        assert abs(pct - round(100 / every)) <= 1


def test_jitter_is_reported_before_loss():
    h = LinkHealth(DT)
    verdicts = feed(h, 1000, keep=lambda k: k % 2 == 1, delay=lambda k: 0.03 if k % 10 == 1 else 0.0)
    assert verdicts and verdicts[-1][1].startswith("link jitter")


def test_losses_leave_the_window_after_window_s():
    """Half the frames lost for 1 s, then 1.5 s clean: the loss is forgotten."""
    h = LinkHealth(DT)
    verdicts = feed(h, 625, keep=lambda k: k >= 250 or k % 2 == 0)
    assert verdicts and verdicts[0][0] < 250          # flagged while losing
    assert all(k < 250 + 250 for k, _ in verdicts)    # and silent a window after the losses end
    assert h.n_lost == 125                            # frames 1, 3, ..., 249


@pytest.mark.parametrize("gap_periods,lost", [(1.4, 0), (1.6, 1), (3.0, 2), (10.0, 9)])
def test_a_gap_of_more_than_one_and_a_half_periods_counts_lost_frames(gap_periods, lost):
    """Lost frames: round(gap / period) - 1 (module doc: gaps beyond 1.5 periods)."""
    h = LinkHealth(DT)
    h.observe(0.0, 0.0)
    h.observe(gap_periods * DT, gap_periods * DT)
    assert h.n_lost == lost and len(h._lost) == lost


def test_a_long_gap_counts_every_lost_frame_but_remembers_at_most_1000():
    h = LinkHealth(DT)
    h.observe(0.0, 0.0)
    h.observe(10.0, 10.0)                   # 2500 periods: 2499 frames lost
    assert h.n_lost == 2499
    assert len(h._lost) == 1000             # bounded memory


def test_repeated_or_older_time_stamps_are_ignored():
    """A frame whose vehicle time does not advance is no new frame: 10 % of the
    frames repeated 50 ms late would otherwise read as 50 ms of jitter."""
    h = LinkHealth(DT)
    out = []
    for k in range(1000):
        t = k * DT
        out.append(h.observe(t, t))
        if k % 10 == 0:
            out.append(h.observe(t + 0.05, t))
            out.append(h.observe(t + 0.05, t - DT))
    assert [v for v in out if v is not None] == []
    assert h.n_lost == 0 and h.jitter_p95_s == pytest.approx(0.0, abs=1e-12)


def test_faster_than_real_time_gets_no_verdict_up_to_the_ratio_limit():
    """Vehicle time at 2x wall time (ratio 2 > 1.3): no verdict even with jitter;
    at 1.25x (below 1.3) the jitter is flagged."""
    jit = lambda k: 0.05 if k % 2 else 0.0        # noqa: E731
    h = LinkHealth(DT)
    assert feed(h, 1000, speed=2.0, delay=jit) == []
    assert h.ratio == pytest.approx(2.0, rel=0.1)
    h = LinkHealth(DT)
    assert feed(h, 1000, speed=1.25, delay=jit) != []
    assert h.ratio == pytest.approx(1.25, rel=0.1)


@pytest.mark.parametrize("ratio,flag", [(1.28, True), (1.32, False)])
def test_the_lockstep_ratio_limit_is_1_3(ratio, flag):
    h = LinkHealth(DT)
    assert bool(feed(h, 1000, speed=ratio, keep=lambda k: k % 2 == 0)) is flag


def test_lockstep_trusts_the_vehicle_until_its_frames_skip():
    h = LinkHealth(DT, lockstep=True)
    assert feed(h, 1000, delay=lambda k: 0.05 if k % 2 else 0.0) == []
    h = LinkHealth(DT, lockstep=True)
    assert feed(h, 1000, delay=lambda k: 0.05 if k % 2 else 0.0, keep=lambda k: k % 7 != 3) != []


def test_before_any_verdict_the_reported_values_are_empty():
    """report.json reads jitter_p95_s and ratio: a fresh watch (or one that has not yet
    filled half a window) reports no jitter and no clock ratio, never a made-up one."""
    h = LinkHealth(DT)
    assert h.jitter_p95_s == 0.0 and h.ratio is None and h.n_lost == 0
    feed(h, 100, delay=lambda k: 0.05 if k % 2 else 0.0)    # 0.4 s: under half a window
    assert h.jitter_p95_s == 0.0 and h.ratio is None


def test_a_frame_exactly_window_s_old_stays_in_the_window():
    """With a 1/256 s period every time is exact in binary: the window (wall_k >= now - 1 s)
    holds 257 frames, the one exactly 1 s old included."""
    h = LinkHealth(1 / 256)
    for k in range(600):
        h.observe(1000.0 + k / 256, k / 256)     # wall clock 1000 s ahead: still exact
    assert len(h._w) == 257


def test_a_loss_exactly_window_s_old_still_counts():
    """Period 1/256 s (exact times), every odd frame lost: each loss is stamped with the wall
    time of the frame that revealed it (even k >= 2). At the last frame k = 598 the losses of
    k in [342, 598] are within 1 s (the one exactly 1 s old included): 129."""
    h = LinkHealth(1 / 256)
    for k in range(0, 600, 2):
        h.observe(1000.0 + k / 256, k / 256)
    assert len(h._lost) == 129


def test_half_a_window_is_measured_from_the_oldest_frame_inclusive():
    """Exact binary times (period 1/256 s, wall = 1000 s + t, late frames 1/32 s late) and a
    window of 2 x 149/256 s: after 150 frames the window spans exactly 149/256 s, half the
    window, which is enough for the first verdict (not before: frame 125 spans 124/256 s)."""
    h = LinkHealth(1 / 256, HealthConfig(window_s=2 * 149 / 256))
    first = None
    for k in range(200):
        t = k / 256
        v = h.observe(1000.0 + t + (1 / 32 if k % 2 == 0 and k > 0 else 0.0), t)
        if v is not None and first is None:
            first = k + 1
    assert first == 150


@pytest.mark.parametrize("limit,flag", [(1.25, True), (1.2, False)])
def test_a_clock_ratio_equal_to_the_limit_is_still_judged(limit, flag):
    """Vehicle time at exactly 1.25x wall time (binary-exact times), every other frame lost:
    the ratio 1.25 is not above a 1.25 limit, so the link is judged (and found bad); above
    a 1.2 limit it is trusted."""
    h = LinkHealth(5 / 1024, HealthConfig(lockstep_ratio=limit))
    out = [h.observe(k / 256, 5 * k / 1024) for k in range(0, 600, 2)]
    assert h.ratio == 1.25
    assert any(v is not None for v in out) is flag


def test_jitter_is_measured_from_the_fastest_frame():
    """All frames 250 ms late but one that is 240 ms late: the 95th percentile is 10 ms
    above the fastest one (a constant delay cancels, the one early frame does not)."""
    h = LinkHealth(DT)
    feed(h, 600, delay=lambda k: 0.24 if k == 500 else 0.25)
    assert h.jitter_p95_s == pytest.approx(0.010, abs=1e-9)


def _exact(n=600, delay=lambda k: 0.0, keep=lambda k: True, **cfg):
    """Period 1/256 s, wall = 1000 s + t + delay: every time exact in binary. Verdicts."""
    h = LinkHealth(1 / 256, HealthConfig(**cfg))
    out = [h.observe(1000.0 + k / 256 + delay(k), k / 256) for k in range(n) if keep(k)]
    return h, [v for v in out if v is not None]


@pytest.mark.parametrize("late,p95", [(13, 0.0), (14, 1 / 64)])
def test_the_95th_percentile_is_the_sorted_offset_at_int_0_95_n_minus_1(late, p95):
    """257 frames in the window: index int(0.95 x 256) = 243 of the sorted offsets. With 14
    frames 1/64 s late, index 243 is the first late one; with 13 it is on time."""
    h, _ = _exact(delay=lambda k: 1 / 64 if 400 <= k < 400 + late else 0.0)
    assert len(h._w) == 257 and h.jitter_p95_s == p95


def test_jitter_equal_to_the_limit_is_not_flagged():
    late = lambda k: 1 / 64 if k % 5 == 0 else 0.0          # noqa: E731
    h, verdicts = _exact(delay=late, max_jitter_s=1 / 64)
    assert h.jitter_p95_s == 1 / 64 and verdicts == []
    assert _exact(delay=late, max_jitter_s=1 / 64 - 1e-9)[1] != []


def test_loss_equal_to_the_limit_is_not_flagged():
    """Every odd frame lost: 129 losses in the 256 periods of the window, 129/256 exactly."""
    odd_lost = lambda k: k % 2 == 0                           # noqa: E731
    assert _exact(keep=odd_lost, max_loss_fraction=129 / 256)[1] == []
    assert _exact(keep=odd_lost, max_loss_fraction=129 / 256 - 1e-9)[1] != []


def test_loss_with_a_few_frames_per_window_uses_the_true_expected_count():
    """10 Hz frames, every other one lost, a 2.5 s window: 12 losses (13 with the one at the
    window's edge) against 24 expected frames is 50-54 % (flagged); the expected count is
    floored at 1 frame only, not at some larger number."""
    h = LinkHealth(0.1, HealthConfig(window_s=2.5))
    out = [h.observe(0.1 * k, 0.1 * k) for k in range(0, 100, 2)]
    verdicts = [v for v in out if v is not None]
    pct = int(re.fullmatch(r"(\d+)% of the sensor frames lost", verdicts[-1]).group(1))
    assert 50 <= pct <= 55


def test_the_expected_frame_count_is_floored_at_one():
    """One vehicle second per frame but 20 ms of wall clock (ratio limit lifted), a 0.5 s
    window: it spans half a period, 0.5 frames expected; one lost frame is then 1 of at
    least 1 expected, 100 % (not 200 %)."""
    h = LinkHealth(1.0, HealthConfig(window_s=0.5, lockstep_ratio=1e9, max_jitter_s=1e9))
    out = [h.observe(0.02 * k, float(k)) for k in range(120) if k != 90]
    assert [v for v in out if v is not None][-1] == "100% of the sensor frames lost"
