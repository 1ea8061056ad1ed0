"""The MAVLink parameter protocol, both sides, as pure state machines.

https://mavlink.io/en/services/parameter.html:

- PARAM_REQUEST_LIST: the vehicle sends every parameter as PARAM_VALUE
  (``param_count``, ``param_index``);
- PARAM_REQUEST_READ by name (``param_index`` -1) or by index: one
  PARAM_VALUE; a vehicle that has no such parameter does not answer (PX4),
  so a client reads with a timeout and a retry;
- PARAM_SET: the vehicle answers with the PARAM_VALUE it has afterwards
  (the old value when it refused the new one), to every peer.

Values travel as a float32 ``param_value``; an INT32 parameter is either
cast (ArduPilot) or its bytes copied into the float (PX4, "bytewise":
``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE``).

- ``Parameters``: the vehicle's named, typed, bounded values (the store).
- ``ParamServer`` (the SITL, ``sitl.server``): what a PARAM_* message asks
  of the store and what goes back (``ParamReply``).
- The companion's side (read and set one parameter, with their timeouts
  and retries on the caller's clock) is ``mavcore.services.param_client``.

No sockets, no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from mavcore import codec
from mavcore.autopilot import PX4_AUTOPILOT, READ_ONLY_PARAMS, Autopilot, ParamSpec

PARAM_TYPE_INT32 = mavlink.MAV_PARAM_TYPE_INT32


# --- the store -----------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ParamSetResult:
    """Outcome of a PARAM_SET: ``ok`` False -> ``reason``; ``value`` is the
    value the parameter has afterwards (the old one when rejected)."""

    ok: bool
    value: float | int
    reason: str = ""


class Parameters:
    """Named, typed parameter values in the stack's list order (by index).

    The list (``specs``) holds the stack's wire names and units. The flight
    stack reads its values by internal name in SI units (PX4's names):
    ``aliases`` (``mavcore.autopilot.ParamAlias``) map an internal name to a
    listed one and its unit factor, ``fixed`` gives internal values the stack
    has no parameter for. ``p[name]`` and ``set(name, v)`` take either kind
    of name (an internal one in SI units).

    Parameters
    ----------
    specs : tuple of ParamSpec
    initial : dict, optional
        Start values overriding the defaults (e.g. the mission's noise).
    aliases : tuple of ParamAlias, optional
    fixed : dict, optional
    """

    def __init__(self, specs: tuple[ParamSpec, ...] = PX4_AUTOPILOT.param_specs, initial: dict | None = None,
                 aliases: tuple = (), fixed: dict | None = None) -> None:
        self.specs = tuple(specs)
        self._index = {s.name: i for i, s in enumerate(self.specs)}
        self._values = [self._typed(s, s.default) for s in self.specs]
        #: internal name -> (index of the listed parameter, wire units per SI unit)
        self._alias = {a.internal: (self._index[a.wire], float(a.wire_per_si)) for a in aliases}
        self._fixed = dict(fixed or {})
        #: Incremented by every successful ``set``: lets a reader cache derived values.
        self.version = 0
        for k, v in (initial or {}).items():
            r = self.set(k, v)
            if not r.ok:
                raise ValueError(f"parameter {k}: {r.reason}")

    @staticmethod
    def _typed(spec: ParamSpec, value):
        return int(value) if spec.param_type == PARAM_TYPE_INT32 else float(value)

    def __len__(self) -> int:
        return len(self.specs)

    @classmethod
    def for_autopilot(cls, autopilot: Autopilot, initial: dict | None = None) -> "Parameters":
        """The parameter set of a personality (``mavcore.autopilot``)."""
        return cls(autopilot.param_specs, initial, autopilot.param_aliases, autopilot.fixed_params)

    def __contains__(self, name: str) -> bool:
        """A listed (wire) name: what PARAM_* messages may name."""
        return name in self._index

    def __getitem__(self, name: str):
        i = self._index.get(name)
        if i is not None:
            return self._values[i]
        a = self._alias.get(name)
        if a is not None:
            return self._values[a[0]] / a[1]
        return self._fixed[name]

    def index(self, name: str) -> int:
        """Index of a parameter; KeyError if unknown."""
        return self._index[name]

    def spec(self, name: str) -> ParamSpec:
        return self.specs[self._index[name]]

    def by_index(self, i: int) -> tuple[ParamSpec, float | int]:
        """(spec, value) of the i-th parameter; IndexError if out of range."""
        if not 0 <= i < len(self.specs):
            raise IndexError(i)
        return self.specs[i], self._values[i]

    def set(self, name: str, value) -> ParamSetResult:
        """Set a parameter (typed, bounds-checked); an internal name's value is in SI units."""
        i = self._index.get(name)
        if i is None and name in self._alias:
            i, k = self._alias[name]
            try:
                value = round(float(value) * k, 6)
            except (TypeError, ValueError):
                pass
            if self.specs[i].param_type == PARAM_TYPE_INT32:
                try:
                    value = round(float(value))
                except (TypeError, ValueError, OverflowError):
                    pass
            name = self.specs[i].name
        if i is None:
            return ParamSetResult(False, math.nan, f"unknown parameter {name}")
        spec = self.specs[i]
        try:
            v = float(value)
        except (TypeError, ValueError):
            return ParamSetResult(False, self._values[i], f"{name}: not a number")
        if not math.isfinite(v):
            return ParamSetResult(False, self._values[i], f"{name}: not finite")
        if spec.param_type == PARAM_TYPE_INT32 and v != int(v):
            return ParamSetResult(False, self._values[i], f"{name}: must be an integer")
        if not spec.min <= v <= spec.max:
            return ParamSetResult(False, self._values[i], f"{name}: outside [{spec.min:g}, {spec.max:g}]")
        self._values[i] = self._typed(spec, v)
        self.version += 1
        return ParamSetResult(True, self._values[i])


# --- server side (the vehicle) ----------------------------------------------------


@dataclass(frozen=True, slots=True)
class ParamReply:
    """What a PARAM_* request gets.

    ``index``: the parameter whose PARAM_VALUE goes back (None: no answer);
    ``to_all``: to every peer (PARAM_SET), else to the requester's link;
    ``applied``: a value changed (the vehicle pushes it into its models);
    ``warning``: a STATUSTEXT to say, or None.
    """

    index: int | None
    to_all: bool = False
    applied: bool = False
    warning: str | None = None


class ParamServer:
    """The vehicle's side of the parameter protocol over a ``Parameters`` store.

    ``bytewise``: INT32 values travel byte-copied in the float (PX4), else cast.
    """

    def __init__(self, params: Parameters, bytewise: bool = True, read_only=READ_ONLY_PARAMS) -> None:
        self.params = params
        self.bytewise = bool(bytewise)
        self.read_only = frozenset(read_only)

    def __len__(self) -> int:
        return len(self.params)

    def value_message(self, mav, i: int):
        """PARAM_VALUE of the i-th parameter."""
        spec, value = self.params.by_index(i)
        wire = codec.param_to_wire(value, spec.param_type) if self.bytewise else float(value)
        return mav.param_value_encode(spec.name.encode("ascii"), wire, spec.param_type, len(self.params), i)

    def request_list(self) -> range:
        """PARAM_REQUEST_LIST: the indices to send, in order."""
        return range(len(self.params))

    def request_read(self, param_id: str, param_index: int) -> ParamReply:
        """PARAM_REQUEST_READ: by index (>= 0) or by name; unknown -> no answer (PX4)."""
        idx = int(param_index)
        if idx < 0:
            if param_id not in self.params:
                return ParamReply(None)
            idx = self.params.index(param_id)
        elif idx >= len(self.params):
            return ParamReply(None)
        return ParamReply(idx)

    def set(self, param_id: str, wire_value: float, wire_type: int) -> ParamReply:
        """PARAM_SET: store the value if it fits; the PARAM_VALUE goes to every peer."""
        p = self.params
        if param_id not in p:
            return ParamReply(None, warning=f"Unknown parameter {param_id[:30]}")
        i = p.index(param_id)
        if param_id in self.read_only:
            return ParamReply(i, warning=f"Param rejected: {param_id} is read-only")
        spec = p.spec(param_id)
        if spec.param_type == PARAM_TYPE_INT32 and int(wire_type) == PARAM_TYPE_INT32 and self.bytewise:
            value = codec.param_from_wire(wire_value, PARAM_TYPE_INT32)
        else:
            value = float(wire_value)
        r = p.set(param_id, value)
        return ParamReply(i, to_all=True, applied=r.ok, warning=None if r.ok else f"Param rejected: {r.reason}")
