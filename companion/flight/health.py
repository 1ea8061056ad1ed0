"""Can the companion still close the inner loop over this link? (pure)

The geometric controller answers every sensor frame; its command acts on the
vehicle only once the answer arrives. In lockstep the vehicle waits for it, so
link delay costs wall time, never stability. Free-running (a real vehicle, or
the SITL in real time) the delay adds dead time to the attitude loop: 30 ms of
jitter is enough to make it bounce the vehicle along the ground. This watch
estimates, from the arrival (wall) times of the sensor frames and their vehicle
time stamps, the extra delay of each frame and the frames lost, and says when
the inner loop should be handed back to the vehicle's own controller.

- A vehicle that says it runs in lockstep (the bundled SITL's parameter
  SIM_LOCKSTEP = 1) waits for every answer: no verdict, as long as its clock
  shows no lost frames (a lockstep SITL falls back to free running when
  answers stop coming; then its frames skip and the checks below apply).
- Otherwise the clock ratio (vehicle seconds per wall second over the last
  window) tells faster-than-real-time running (> ``lockstep_ratio``): no verdict.
- Jitter: ``(wall_k - t_k) - min_window(wall - t)``, the delay of frame k
  beyond the fastest frame of the window (a constant base delay cancels).
- Lost frames: gaps in the vehicle time stamps beyond 1.5 periods.

``observe`` returns a reason string when, over the last window, the 95th
percentile of the jitter exceeds ``max_jitter_s`` or more than
``max_loss_fraction`` of the frames were lost. Everything is passed in: no clock.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True)
class HealthConfig:
    window_s: float = 1.0
    max_jitter_s: float = 0.012
    max_loss_fraction: float = 0.3
    lockstep_ratio: float = 1.3


class LinkHealth:
    """Sliding-window jitter and loss of the sensor frames (see the module docstring)."""

    def __init__(self, period_s: float, cfg: HealthConfig = HealthConfig(), lockstep: bool = False) -> None:
        self.period_s = float(period_s)
        self.lockstep = lockstep
        self.cfg = cfg
        self._w: deque = deque()          # (wall_s, t_s)
        self.n_lost = 0
        self._lost: deque = deque()       # wall times of lost frames
        self._t_prev: float | None = None
        self.jitter_p95_s = 0.0
        self.ratio = None
        self._n = 0

    def observe(self, wall_s: float, t_s: float) -> str | None:
        cfg = self.cfg
        if self._t_prev is not None:
            gap = t_s - self._t_prev
            if gap <= 0.0:
                return None
            missed = int(round(gap / self.period_s)) - 1
            for _ in range(min(missed, 1000)):
                self._lost.append(wall_s)
            self.n_lost += max(0, missed)
        self._t_prev = t_s
        w = self._w
        w.append((wall_s, t_s))
        while w and wall_s - w[0][0] > cfg.window_s:
            w.popleft()
        while self._lost and wall_s - self._lost[0] > cfg.window_s:
            self._lost.popleft()
        self._n += 1
        if self._n % 25 or len(w) < 10 or wall_s - w[0][0] < 0.5 * cfg.window_s:
            return None   # a verdict every 25 frames is enough (0.1 s at 250 Hz)
        dwall = wall_s - w[0][0]
        self.ratio = (t_s - w[0][1]) / dwall
        if self.ratio > cfg.lockstep_ratio or (self.lockstep and not self._lost):
            return None
        offs = sorted(a - b for a, b in w)
        base = offs[0]
        self.jitter_p95_s = offs[int(0.95 * (len(offs) - 1))] - base
        expected = dwall / self.period_s
        loss = len(self._lost) / max(expected, 1.0)
        if self.jitter_p95_s > cfg.max_jitter_s:
            return f"link jitter {self.jitter_p95_s * 1e3:.0f} ms (95th percentile)"
        if loss > cfg.max_loss_fraction:
            return f"{loss:.0%} of the sensor frames lost"
        return None
