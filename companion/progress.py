"""A live one-line progress display for a flight.

On a terminal the line is rewritten in place (``\\r``) at most ten times a
wall second; otherwise (a pipe, a CI log) a plain line is printed every few
wall seconds and at every phase change. Display only: it never influences
the flight.
"""

from __future__ import annotations

import math
import sys
import time
from typing import TextIO


class Progress:
    """Phase, percent done, current position error and replanning events.

    Parameters
    ----------
    stream : text stream or None
        Where to write (default ``sys.stderr``).
    tty : bool or None
        Force terminal/plain mode; None asks ``stream.isatty()``.
    plain_interval_s : float
        Wall seconds between plain lines.
    enabled : bool
        False silences everything (tests, library use).
    """

    def __init__(self, stream: TextIO | None = None, tty: bool | None = None, plain_interval_s: float = 5.0,
                 enabled: bool = True) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(self.stream.isatty()) if tty is None else tty
        self.plain_interval_s = plain_interval_s
        self.enabled = enabled
        self._phase = ""
        self._next = 0.0
        self._width = 0

    @staticmethod
    def format(phase: str, fraction: float, error_m: float | None, events: int, sim_time_s: float,
               coverage: float | None = None, control: str | None = None) -> str:
        """The line. ``fraction``: of the trajectory's time; ``coverage``: the
        coverage flown so far (``FlightRecorder.coverage_flown``, report.json's
        ``coverage_fraction``); ``control``: who flies the inner loop now."""
        err = "  -  " if error_m is None or not math.isfinite(error_m) else f"{error_m * 1000:7.1f} mm"
        pct = max(0.0, min(1.0, fraction)) * 100.0
        line = f"[{phase:<10}] {pct:5.1f}%  t={sim_time_s:7.1f} s  error {err}  events {events}"
        if coverage is not None:
            line += f"  coverage {coverage:6.1%}"
        if control is not None:
            line += f"  ({control} control)"
        return line

    def update(self, phase: str, fraction: float, error_m: float | None = None, events: int = 0,
               sim_time_s: float = 0.0, force: bool = False, coverage: float | None = None,
               control: str | None = None) -> None:
        """Show the state if it is time to (by wall clock) or the phase changed."""
        if not self.enabled:
            return
        now = time.monotonic()
        changed = phase != self._phase
        if not (force or changed or now >= self._next):
            return
        self._phase = phase
        line = self.format(phase, fraction, error_m, events, sim_time_s, coverage, control)
        if self.tty:
            pad = max(0, self._width - len(line))
            self.stream.write("\r" + line + " " * pad)
            self._width = len(line)
            self._next = now + 0.1
        else:
            self.stream.write(line + "\n")
            self._next = now + self.plain_interval_s
        self.stream.flush()

    def close(self) -> None:
        """End the live line (a newline on a terminal)."""
        if self.enabled and self.tty and self._width:
            self.stream.write("\n")
            self.stream.flush()
            self._width = 0
