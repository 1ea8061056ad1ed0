"""A whole replay over a .tlog's bytes (pure: byte chunks in, a named result out).

``find_setup(chunks)`` reads the recorded setup (first pass, stops once it is
complete); ``replay_chunks(chunks, core=...)`` frames, decodes, computes the
metrics and, given a core, re-runs and compares it (second pass). The caller
reads the file in chunks (``companion.commands.replay``), so memory does not
grow with the file.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from ..flight.log import FlightLog
from ..flight.reporting import flight_report
from ..link.connection import COMPANION_COMPONENT_ID, COMPANION_SYSTEM_ID
from ..link.tlog_scan import ScanSummary, TlogScanner, decode_record, new_decoder
from .metrics import FlightMetrics, MetricsAccumulator
from .rebuild import SetupCollector
from .session import Comparison, ReplaySession

_STATUSTEXT = mavlink.MAVLINK_MSG_ID_STATUSTEXT


@dataclass(frozen=True)
class ReplayResult:
    """Everything one replay found.

    Attributes
    ----------
    scan : ScanSummary
        Records read, bytes and packets skipped (damage), stamp jumps.
    metrics : FlightMetrics
        From the recording alone.
    comparison : Comparison or None
        The re-run's outputs against the recorded ones (None without a core).
    flight : companion.report.FlightReport or None
        The re-run core's own report (``wall_time_s`` is 0: not a flight).
    log : FlightLog or None
        The re-run core's per-frame log, or the metrics' (``with_log``).
    setup : dict or None
        The recorded setup record (None: none, or incomplete).
    """

    scan: ScanSummary
    metrics: FlightMetrics
    comparison: Comparison | None
    flight: object
    log: FlightLog | None
    setup: dict | None = None


def find_setup(chunks, max_garbage_bytes: int | None = None) -> dict | None:
    """The setup record of a companion .tlog (None when it has none).

    Raises
    ------
    ValueError
        Setup chunks were found but the record is incomplete or malformed.
    """
    scanner = TlogScanner(max_garbage_bytes)
    dec = new_decoder()
    col = SetupCollector()

    def look(records):
        for rec in records:
            if rec.msgid == _STATUSTEXT and rec.compid == COMPANION_COMPONENT_ID \
                    and rec.sysid == COMPANION_SYSTEM_ID:
                msg = decode_record(rec, dec)
                if msg is not None and col.feed(msg) is not None:
                    return True
        return False

    for chunk in chunks:
        if look(scanner.feed(chunk)):
            return col.setup
    if look(scanner.close()):
        return col.setup
    return col.finish()


def replay_chunks(chunks, core=None, tolerance: float = 0.0, withhold=(), settle_s: float = 5.0,
                  with_log: bool = False, environment=None, max_garbage_bytes: int | None = None) -> ReplayResult:
    """Replay a .tlog given as byte chunks (see ``ReplaySession``).

    Parameters
    ----------
    chunks : iterable of bytes
        The file's bytes, in order, in chunks of any size.
    core : FlightCore or None
        A fresh core built like the recorded flight's; None: metrics only.
    tolerance : float
        0: see ``environment``; > 0: absolute tolerance on float fields.
    withhold : iterable of int
        Vehicle message ids not fed to the core.
    settle_s : float
        The metrics' tracking window starts this long after lift-off.
    with_log : bool
        Metrics only: build a ``FlightLog`` from the recording (for figures).
    environment : sequence of str or None
        How the replaying environment differs from the recording's
        (``companion.flight.environment.differences``: ``["unknown"]`` for a
        recording without a fingerprint): empty compares bit for bit, anything
        else in drift mode (``companion.replay.compare``); None: bit for bit
        (the caller decided). A ``tolerance`` > 0 overrides both.
    max_garbage_bytes : int or None
        ``TlogScanner``'s cap: ``TlogGarbage`` (a ValueError) once more bytes
        than this frame no valid record.
    """
    log = FlightLog() if (with_log and core is None) else None
    metrics = MetricsAccumulator(settle_s, log)
    session = ReplaySession(metrics, core, tolerance, withhold, drift=bool(environment), environment=environment)
    scanner = TlogScanner(max_garbage_bytes)
    for chunk in chunks:
        session.feed(scanner.feed(chunk))
    session.feed(scanner.close())
    comparison = session.finish()
    flight = flight_report(core, 0.0, None) if core is not None else None
    col = session.setup_collector
    return ReplayResult(scanner.summary, metrics.result(), comparison, flight,
                        core.recorder.log if core is not None else log, col.setup if col.complete else None)
