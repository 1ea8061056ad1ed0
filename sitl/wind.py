"""Wind: a constant mean plus first-order Gauss-Markov gusts (ENU, m/s).

Each axis of the gust g follows ``g' = -g / tau + sqrt(2 sigma^2 / tau) xi``
(xi white), the simplest Dryden-like model with stationary std ``sigma`` and
correlation time ``tau``. It is sampled exactly at the frame period ``dt``:
``g <- a g + sigma sqrt(1 - a^2) n``, ``a = exp(-dt / tau)``, n ~ N(0, I).
"""

from __future__ import annotations

import math

import numpy as np

from mavcore.mission.sim import WindConfig


class WindModel:
    """Seeded wind process; ``step(dt)`` returns the air velocity (3-tuple)."""

    def __init__(self, config: WindConfig, rng: np.random.Generator) -> None:
        self.config = config
        self.rng = rng
        self.mean = tuple(float(x) for x in config.mean_enu_m_s)
        self.sigma = float(config.gust_std_m_s)
        self.tau = float(config.gust_time_constant_s)
        # Start in the stationary distribution so the statistics do not ramp.
        self.gust = tuple(float(x) for x in self.sigma * rng.standard_normal(3)) if self.sigma > 0 else (0.0, 0.0, 0.0)
        self._dt = None
        self._a = self._b = 0.0

    @property
    def velocity_enu_m_s(self) -> tuple[float, float, float]:
        return (self.mean[0] + self.gust[0], self.mean[1] + self.gust[1], self.mean[2] + self.gust[2])

    def step(self, dt: float) -> tuple[float, float, float]:
        """Advance the gusts by dt (s) and return the wind velocity (ENU, m/s)."""
        if self.sigma > 0.0:
            if dt != self._dt:
                self._dt = dt
                self._a = math.exp(-dt / self.tau)
                self._b = self.sigma * math.sqrt(1.0 - self._a * self._a)
            n = self.rng.standard_normal(3)
            a, b = self._a, self._b
            g = self.gust
            self.gust = (a * g[0] + b * float(n[0]), a * g[1] + b * float(n[1]), a * g[2] + b * float(n[2]))
        return self.velocity_enu_m_s
