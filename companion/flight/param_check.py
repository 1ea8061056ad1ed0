"""The pre-flight parameter check (``--check-params``, docs/flying-a-real-vehicle.md
"Parameters to set"): read each parameter the personality declares
(``Autopilot.param_checks``) and warn of a value outside what a flight under the
companion's setpoints needs. A warning, not a refusal: the pilot decides.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

#: STATUSTEXT prefix of a parameter outside what the flight needs.
PARAM_PREFIX = "companion: param "


def warning_text(w: dict) -> str:
    """The STATUSTEXT of one warning (at most 50 characters)."""
    shown = "?" if w["value"] is None else f"{w['value']:g}"
    return f"{PARAM_PREFIX}{w['name']}={shown} {w['problem']}"[:50]


def check_params(read, checks, enc, emit):
    """Generator (driven by ``FlightCore``'s procedure): ``read(name)`` is the core's
    PARAM_REQUEST_READ generator (a ``ParamResult``); each value that ``check.problem``
    refuses is a warning ``{name, value, problem, why}``, said as a STATUSTEXT WARNING
    through ``emit``. Returns the warnings."""
    out = []
    for check in checks:
        r = yield from read(check.name)
        problem = check.problem(r.value)
        if problem is not None:
            w = {"name": check.name, "value": r.value, "problem": problem, "why": check.why}
            out.append(w)
            emit(enc.statustext_encode(mavlink.MAV_SEVERITY_WARNING, warning_text(w).encode()))
    return out
