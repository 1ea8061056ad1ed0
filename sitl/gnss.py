"""The SITL's position/velocity receiver (GNSS/RTK-like, or mocap-like by
default): measurement schedule, white noise and delivery latency, on the
vehicle clock. World ENU, SI units.

Timing. Measurements are taken at the sensor frames whose time reaches the
next multiple of ``period_us`` (0, P, 2P, ...; with P a multiple of the
sensor period, exactly at those times), each of the true state at that
frame plus white noise. A measurement taken at ``t_m`` is delivered at the
first frame at or after ``t_m + latency_us``; until the next delivery the
latest delivered sample is held, with its measurement time, so a consumer
sees both the latency (``now - time_us``) and when a sample is new.

The receiver is primed at ``reset`` with a measurement of the start state
at time 0, delivered at once (a receiver that was on before the vehicle
booted), so there is always a sample to report.

Noise: position ``N(0, std_xy^2)`` on x and y, ``N(0, std_z^2)`` on z;
velocity ``N(0, vel_std^2)`` per axis; no draw when a std is 0. Every draw
comes from the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True)
class GnssSample:
    """One position/velocity measurement.

    Attributes
    ----------
    time_us : int
        Measurement time (vehicle clock, us).
    pos_enu_m, vel_enu_m_s : 3-tuple of float
        Measured position (m) and velocity (m/s), world ENU.
    """

    time_us: int
    pos_enu_m: tuple
    vel_enu_m_s: tuple


class GnssReceiver:
    """Schedule, noise and latency of the position/velocity measurements.

    Parameters
    ----------
    period_us : int
        Time between measurements (us, > 0).
    latency_us : int
        Measurement-to-delivery delay (us, >= 0).
    pos_std_xy_m, pos_std_z_m, vel_std_m_s : float
        White noise standard deviations.
    rng : numpy.random.Generator

    Memory is bounded: at most ``latency_us / period_us + 1`` samples wait
    for delivery.
    """

    def __init__(self, period_us: int, latency_us: int, pos_std_xy_m: float, pos_std_z_m: float,
                 vel_std_m_s: float, rng: np.random.Generator) -> None:
        if period_us <= 0 or latency_us < 0:
            raise ValueError("GNSS period must be > 0 and latency >= 0")
        self.period_us = int(period_us)
        self.latency_us = int(latency_us)
        self.pos_std_xy_m = float(pos_std_xy_m)
        self.pos_std_z_m = float(pos_std_z_m)
        self.vel_std_m_s = float(vel_std_m_s)
        self.rng = rng
        self._pending: collections.deque = collections.deque()
        self.latest: GnssSample | None = None
        self._next_us = 0
        #: True when ``latest`` was delivered by the last ``step``.
        self.fresh = False

    def reset(self, p, v) -> None:
        """Forget everything; measure (p, v) at time 0 and deliver it at once."""
        self._pending.clear()
        self.latest = self.measure(0, p, v)
        self._next_us = self.period_us
        self.fresh = True

    def measure(self, time_us: int, p, v) -> GnssSample:
        """A noisy sample of the true (p, v) (3-tuples) taken at ``time_us``."""
        kxy, kz, kv = self.pos_std_xy_m, self.pos_std_z_m, self.vel_std_m_s
        if kxy > 0 or kz > 0:
            n0, n1, n2 = self.rng.standard_normal(3).tolist()
            p = (p[0] + kxy * n0, p[1] + kxy * n1, p[2] + kz * n2)
        if kv > 0:
            n0, n1, n2 = self.rng.standard_normal(3).tolist()
            v = (v[0] + kv * n0, v[1] + kv * n1, v[2] + kv * n2)
        return GnssSample(int(time_us), p, v)

    def step(self, time_us: int, p, v) -> GnssSample:
        """Advance to the sensor frame at ``time_us`` (true p, v as 3-tuples):
        measure if due, deliver what is due; returns the latest delivered sample."""
        self.fresh = False
        if time_us >= self._next_us:
            sample = self.measure(time_us, p, v)
            nxt = self._next_us + self.period_us
            self._next_us = nxt if nxt > time_us else time_us - time_us % self.period_us + self.period_us
            if self.latency_us == 0:
                self.latest = sample
                self.fresh = True
                return sample
            self._pending.append(sample)
        pend = self._pending
        while pend and pend[0].time_us + self.latency_us <= time_us:
            self.latest = pend.popleft()
            self.fresh = True
        return self.latest
