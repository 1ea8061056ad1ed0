"""Replay one .tlog: feed its vehicle messages to a ``FlightCore`` and compare
what the core queues with what the companion recorded (pure).

The .tlog holds both directions in the order the runner saw them: each batch
of vehicle messages is written before the answers to it
(``companion.link.connection``). So replaying is a single pass over the
records: a vehicle message goes to ``core.handle`` (and the metrics) and its
outputs join a queue; a companion message (system 1, component 191) takes
the next output from the queue and is compared with it
(``companion.replay.compare``). Outputs that do not come from ``handle``:

- HEARTBEATs the runner sends by wall clock before the vehicle clock runs:
  companion HEARTBEATs recorded before the first HIGHRES_IMU are skipped;
- events from outside the core, each announced by the core on the wire: a
  recorded companion STATUSTEXT starting with ``INTERRUPT_PREFIX`` or
  ``DEGRADE_PREFIX`` met while the queue is empty is re-injected
  (``core.interrupt`` / ``core.degrade`` at that point of the stream), then
  compared like any output;
- ``link_lost`` (no output): called at the end when the recording ends with
  the core still flying.

Without a core (no mission given) only the metrics are computed.
``withhold`` names vehicle message ids the core is not fed (the metrics still
see them): replaying with the truth (ODOMETRY) withheld must give the same
outputs, or the companion read the truth.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from ..flight.core import DEGRADE_PREFIX, INTERRUPT_PREFIX
from mavcore import codec
from ..link.connection import COMPANION_COMPONENT_ID, COMPANION_SYSTEM_ID
from ..link.tlog_scan import decode_record, new_decoder
from .compare import OutputComparer, computed_payload, message_name
from .metrics import MetricsAccumulator
from .rebuild import SetupCollector

_HEARTBEAT = mavlink.MAVLINK_MSG_ID_HEARTBEAT
_STATUSTEXT = mavlink.MAVLINK_MSG_ID_STATUSTEXT
_SETPOINT = mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED
_IMU = mavlink.MAVLINK_MSG_ID_HIGHRES_IMU
#: Companion messages the metrics read (the others are only counted).
_METRIC_IDS = (_SETPOINT, _STATUSTEXT)
#: Decoders of the companion's messages (never fed to the core): the setpoints without pymavlink.
_COMPANION_DECODERS = {**codec.FAST_DECODERS,
                       _SETPOINT: codec.FastDecoder(mavlink.MAVLink_set_position_target_local_ned_message)}


@dataclass(frozen=True)
class Divergence:
    """The first place where the replay's outputs differ from the recording.

    Attributes
    ----------
    t_s : float or None
        Vehicle time (s) of the core at that point.
    offset : int or None
        File offset of the recorded record (None: the recording had ended).
    index : int
        Companion outputs compared before this one.
    recorded, computed : str or None
        Message types (None: nothing there).
    field : str or None
        First differing field (None when the types differ or one side is missing).
    recorded_value, computed_value : object
    kind : str
        ``value``: one output differs; ``drift`` (drift mode, at the end): a field's
        differences add up to more than float64 drift explains (``recorded_value`` is then
        the mean |difference| per output, ``computed_value`` its bound).
    """

    t_s: float | None
    offset: int | None
    index: int
    recorded: str | None
    computed: str | None
    field: str | None = None
    recorded_value: object = None
    computed_value: object = None
    kind: str = "value"

    def describe(self) -> str:
        """One line: when, where, what."""
        t = "before the vehicle clock" if self.t_s is None else f"t={self.t_s:.6f} s"
        if self.kind == "drift":
            return (f"{t} (end of the recording, {self.index} outputs of the message): {self.recorded}.{self.field} "
                    f"mean |difference| {_fmt(self.recorded_value)} per output, more than float64 drift between "
                    f"machines explains (bound {_fmt(self.computed_value)})")
        at = "after the end of the recording" if self.offset is None else f"record at byte {self.offset}"
        head = f"{t} ({at}, output #{self.index})"
        if self.recorded is None:
            return f"{head}: computed {self.computed}, recorded nothing"
        if self.computed is None:
            return f"{head}: recorded {self.recorded}, computed nothing"
        if self.field is None:
            return f"{head}: recorded {self.recorded}, computed {self.computed}"
        return (f"{head}: {self.recorded}.{self.field} recorded {_fmt(self.recorded_value)} "
                f"computed {_fmt(self.computed_value)}")

    def to_dict(self) -> dict:
        def plain(v):
            return v if isinstance(v, (int, float, str)) or v is None else repr(v)

        return {"t_s": self.t_s, "offset": self.offset, "index": self.index, "recorded": self.recorded,
                "computed": self.computed, "field": self.field, "recorded_value": plain(self.recorded_value),
                "computed_value": plain(self.computed_value), "kind": self.kind, "description": self.describe()}


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.9g}"
    return repr(v)


@dataclass(frozen=True)
class Comparison:
    """How the replay's outputs compare with the recording.

    Attributes
    ----------
    identical : bool
        Every recorded output matched (``mode``) and nothing was left over.
    mode : str
        ``bitwise`` (float32 fields bit for bit), ``drift`` (the environment differs
        from the recording's, or is unknown: continuous outputs within float64
        drift, ``companion.replay.compare``) or ``absolute`` (``tolerance``).
    tolerance : float
        0, or the absolute tolerance on float fields (mode ``absolute``).
    n_compared, n_bitwise, n_within_tolerance, n_differing : int
        Outputs compared; identical byte for byte; different but within
        tolerance; different beyond it (after the first divergence the count
        includes knock-on misalignment).
    first_divergence : Divergence or None
    max_abs_diff : dict
        Largest |difference| per ``MESSAGE.field`` among outputs that differed.
    n_runner_heartbeats : int
        Companion HEARTBEATs skipped before the vehicle clock ran.
    injected : tuple of str
        The outside events re-injected (STATUSTEXT texts).
    withheld : tuple of str
        Message types not fed to the core.
    environment : tuple of str or None
        Why the mode is ``drift``: the fingerprint keys that differ from the
        recording's (``("unknown",)``: the recording has none); None when not
        known to the caller.
    drift : dict
        Drift mode: per ``MESSAGE.field`` that differed, [mean |difference| per
        output, its bound].
    """

    identical: bool
    tolerance: float
    n_compared: int
    n_bitwise: int
    n_within_tolerance: int
    n_differing: int
    first_divergence: Divergence | None
    max_abs_diff: dict
    n_runner_heartbeats: int
    injected: tuple
    withheld: tuple
    mode: str = "bitwise"
    environment: tuple | None = None
    drift: dict | None = None

    def to_dict(self) -> dict:
        return {"identical": self.identical, "mode": self.mode,
                "environment": None if self.environment is None else list(self.environment),
                "drift": dict(self.drift or {}), "tolerance": self.tolerance, "n_compared": self.n_compared,
                "n_bitwise": self.n_bitwise, "n_within_tolerance": self.n_within_tolerance,
                "n_differing": self.n_differing,
                "first_divergence": None if self.first_divergence is None else self.first_divergence.to_dict(),
                "max_abs_diff": dict(self.max_abs_diff), "n_runner_heartbeats": self.n_runner_heartbeats,
                "injected": list(self.injected), "withheld": list(self.withheld)}


class ReplaySession:
    """One pass over a .tlog's records (module docstring).

    Parameters
    ----------
    metrics : MetricsAccumulator
    core : FlightCore or None
        A fresh core built like the recorded flight's (``companion.replay.rebuild``);
        None: metrics only.
    tolerance : float
        See ``Comparison``.
    withhold : iterable of int
        Vehicle message ids not fed to the core.
    vehicle_system : int
    drift : bool
        Compare in drift mode (``Comparison.mode``; a tolerance > 0 wins).
    environment : sequence of str or None
        Reported as ``Comparison.environment``.
    """

    def __init__(self, metrics: MetricsAccumulator, core=None, tolerance: float = 0.0, withhold=(),
                 vehicle_system: int = 1, drift: bool = False, environment=None) -> None:
        self.metrics = metrics
        self.core = core
        self.comparer = OutputComparer(tolerance, drift) if core is not None else None
        self.environment = None if environment is None else tuple(environment)
        self.withhold = frozenset(int(w) for w in withhold)
        self.vsys = int(vehicle_system)
        self.pending: deque = deque()
        self.first: Divergence | None = None
        self.n_differing = 0
        self.n_runner_heartbeats = 0
        self.n_undecodable = 0
        self.injected: list = []      # the first 100 texts (``n_injected`` counts them all)
        self.n_injected = 0
        self.seen_imu = False
        self._dec = new_decoder()
        self._finished = False
        #: The setup record, collected on the way (``setup_collector.finish()``).
        self.setup_collector = SetupCollector()
        core_ids = set()
        if core is not None:
            for name in core.handled_types:
                mid = getattr(mavlink, f"MAVLINK_MSG_ID_{name}", None)
                if mid is not None and mid not in self.withhold:
                    core_ids.add(int(mid))
        self._core_ids = frozenset(core_ids)
        self._need = frozenset(core_ids | set(MetricsAccumulator.MSG_IDS) | {_IMU})

    def feed(self, records) -> None:
        """Process ``records`` (``RawRecord``s, in file order).

        A vehicle message is decoded only when the core acts on its type
        (``FlightCore.handled_types``: any other leaves the core as it was)
        or the metrics read it."""
        dec = self._dec
        metrics = self.metrics
        core = self.core
        pending = self.pending
        core_ids = self._core_ids
        need = self._need
        vsys = self.vsys
        for rec in records:
            mid = rec.msgid
            sysid = rec.sysid
            if rec.compid == COMPANION_COMPONENT_ID and sysid == COMPANION_SYSTEM_ID:
                self._companion(rec)
                continue
            if mid not in need:
                if sysid == vsys:
                    metrics.count_vehicle()
                continue
            msg = decode_record(rec, dec)
            if msg is None:
                self.n_undecodable += 1
                continue
            if sysid == vsys:
                metrics.vehicle(msg, mid)
            if mid == _IMU:
                self.seen_imu = True
            if mid in core_ids:
                core.handle(msg)
                if core.outbox:
                    pending.extend(core.take_outbox())

    def _companion(self, rec) -> None:
        msg = None
        if rec.msgid in _METRIC_IDS:
            msg = decode_record(rec, self._dec, _COMPANION_DECODERS)
            if msg is not None:
                self.metrics.companion(msg)
                if rec.msgid == _STATUSTEXT:
                    self.setup_collector.feed(msg)
        else:
            self.metrics.count_companion()
        core = self.core
        if core is None:
            return
        if rec.msgid == _HEARTBEAT and not self.seen_imu:
            self.n_runner_heartbeats += 1
            return
        pending = self.pending
        if not pending and rec.msgid == _STATUSTEXT and msg is not None:
            text = str(msg.text)
            if text.startswith(INTERRUPT_PREFIX):
                core.interrupt(text[len(INTERRUPT_PREFIX):])
                self._injected(text)
            elif text.startswith(DEGRADE_PREFIX):
                core.degrade(text[len(DEGRADE_PREFIX):])
                self._injected(text)
            pending.extend(core.take_outbox())
        index = self.comparer.n_compared
        if not pending:
            self._diverged(Divergence(core.view.t_s, rec.offset, index, message_name(rec.msgid), None))
            return
        out = pending.popleft()
        diff = self.comparer.compare(out, rec)
        if diff is None:
            return
        if diff.field is None:        # another message type: the values are the type names
            self._diverged(Divergence(core.view.t_s, rec.offset, index, diff.recorded_value, diff.computed_value))
        else:
            name = message_name(rec.msgid)
            self._diverged(Divergence(core.view.t_s, rec.offset, index, name, name, diff.field, diff.recorded_value,
                                      diff.computed_value))

    def _injected(self, text: str) -> None:
        self.n_injected += 1
        if len(self.injected) < 100:
            self.injected.append(text)

    def _diverged(self, d: Divergence) -> None:
        self.n_differing += 1
        if self.first is None:
            self.first = d

    def finish(self) -> Comparison | None:
        """End of the recording: leftover outputs diverge; the comparison (None without a core)."""
        core = self.core
        if core is None:
            return None
        if not self._finished:
            self._finished = True
            if not core.finished:
                core.link_lost("the recording ends")
                self.pending.extend(core.take_outbox())
            if self.pending:
                out = self.pending[0]
                msgid, _ = computed_payload(out, self.comparer.mav)
                self._diverged(Divergence(core.view.t_s, None, self.comparer.n_compared, None, message_name(msgid)))
            for ex in self.comparer.drift_excess():
                name, field = ex["field"].split(".", 1)
                self._diverged(Divergence(core.view.t_s, None, ex["n_outputs"], name, name, field, ex["mean_abs_diff"],
                                          ex["bound"], kind="drift"))
        c = self.comparer
        return Comparison(
            identical=self.first is None,
            tolerance=c.tolerance,
            n_compared=c.n_compared,
            n_bitwise=c.n_bitwise,
            n_within_tolerance=c.n_within,
            n_differing=self.n_differing,
            first_divergence=self.first,
            max_abs_diff=dict(c.max_abs_diff),
            n_runner_heartbeats=self.n_runner_heartbeats,
            injected=tuple(self.injected),
            withheld=tuple(message_name(w) for w in sorted(self.withhold)),
            mode=c.mode,
            environment=self.environment,
            drift=c.drift_summary(),
        )
