"""What a flight keeps in memory: a bounded per-frame log and running error statistics.

Memory must grow with what the program holds, not with the flight's length:
``FlightLog`` keeps at most ``max_rows`` rows (for the figures) by halving its
sampling rate whenever it fills up, and ``ErrorStats`` keeps the tracking
statistics as running sums. The complete record of a flight is the .tlog,
which streams to disk.
"""

from __future__ import annotations

import math
from array import array
from dataclasses import dataclass, field

import numpy as np


@dataclass
class FlightLog:
    """Per-frame record of a flight (vehicle time), decimated to stay bounded.

    ``COLUMNS``: time, phase code, reference position, true (or estimated)
    position, measured position, attitude ``R_enu_flu`` rows flattened (9:
    the SITL's truth when it sends ODOMETRY, else the vehicle's estimate),
    desired attitude columns b1d, b2d, b3d (9), collective thrust f,
    pointing direction s (3).

    Rows are offered every frame (``append``); the log keeps every
    ``stride``-th one. When ``max_rows`` would be exceeded it drops every
    other kept row and doubles the stride, so a flight of any length holds
    between ``max_rows / 2`` and ``max_rows`` rows, evenly spaced in time.
    """

    COLUMNS = (["t", "phase"] + [f"ref_{c}" for c in "xyz"] + [f"true_{c}" for c in "xyz"]
               + [f"est_{c}" for c in "xyz"] + [f"R{i}{j}" for i in range(3) for j in range(3)]
               + [f"{b}_{c}" for b in ("b1d", "b2d", "b3d") for c in "xyz"] + ["f"]
               + [f"s_{c}" for c in "xyz"])
    max_rows: int = 20000
    #: The kept rows back to back (C doubles).
    data: array = field(default_factory=lambda: array("d"))
    stride: int = 1
    n_offered: int = 0

    def __post_init__(self) -> None:
        if self.max_rows < 2:
            raise ValueError("FlightLog.max_rows must be >= 2")

    def wants(self) -> bool:
        """Whether the next offered row will be kept (callers skip building it otherwise)."""
        return self.n_offered % self.stride == 0

    def append(self, *parts) -> None:
        """Offer one row, given as float sequences that concatenate to ``COLUMNS``."""
        keep = self.n_offered % self.stride == 0
        self.n_offered += 1
        if not keep:
            return
        ext = self.data.extend
        for p in parts:
            ext(p)
        n = len(self.COLUMNS)
        if len(self.data) > self.max_rows * n:
            a = np.frombuffer(self.data, dtype=float).reshape(-1, n)
            kept = a[::2].copy()
            self.data = array("d", kept.tobytes())
            self.stride *= 2

    @property
    def rows(self) -> list[tuple]:
        """The kept rows as tuples (a copy)."""
        return [tuple(r) for r in self.array().tolist()]

    def array(self) -> np.ndarray:
        """(N, len(COLUMNS)) float array (NaN where a value was unknown)."""
        n = len(self.COLUMNS)
        if len(self.data) % n:
            raise ValueError("FlightLog: partial row")
        return np.frombuffer(self.data, dtype=float).reshape(-1, n).copy()

    def column(self, name: str) -> np.ndarray:
        return self.array()[:, self.COLUMNS.index(name)]


class ErrorStats:
    """Running max and RMS of the position error after ``t_start_s + settle_s``.

    Parameters
    ----------
    settle_s : float
        Samples in the first ``settle_s`` seconds after the start are ignored.

    ``start(t)`` sets the start (vehicle time, s); ``add(t, err)`` offers a
    sample. Holds four numbers whatever the flight's length.
    """

    def __init__(self, settle_s: float) -> None:
        self.settle_s = float(settle_s)
        self.t_start_s: float | None = None
        self.max_m: float | None = None
        self.t_max_s: float | None = None
        self._sumsq = 0.0
        self.n = 0

    def start(self, t_s: float) -> None:
        self.t_start_s = float(t_s)

    def add(self, t_s: float, err_m: float) -> None:
        if self.t_start_s is None or t_s < self.t_start_s + self.settle_s or not math.isfinite(err_m):
            return
        self.n += 1
        self._sumsq += err_m * err_m
        if self.max_m is None or err_m > self.max_m:
            self.max_m = err_m
            self.t_max_s = t_s

    @property
    def rms_m(self) -> float | None:
        return math.sqrt(self._sumsq / self.n) if self.n else None
