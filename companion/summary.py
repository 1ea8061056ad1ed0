"""The console's words for a flight, rendered from its report (``FlightReport``).

report.json is the one source of truth for the coverage flown, the control
mode in use (and when it changed), the phase and the faults; ``companion
fly``, ``companion demo`` and the progress line say what these functions
make of it, so the console never disagrees with the file. Pure: a report in,
strings out.
"""

from __future__ import annotations


def coverage_text(flown: float | None, planned: float | None) -> str:
    """"coverage 1.6% flown of 97.6% planned" (fractions in [0, 1]); "n/a" parts when unknown."""
    f = "n/a" if flown is None else f"{flown:.1%}"
    if planned is None:
        return f"coverage {f} flown"
    return f"coverage {f} flown of {planned:.1%} planned"


def control_text(rep) -> str:
    """"companion control" or, after a hand-over, "companion control, vehicle control
    from t=12.3 s (reason)" (vehicle clock)."""
    text = f"{rep.control} control"
    for c in rep.control_mode_changes:
        t = "" if c.get("t_s") is None else f" from t={c['t_s']:.1f} s"
        text += f", {c['to']} control{t} ({c['reason']})"
    return text


def outcome_text(rep) -> str:
    """"completed", or "NOT completed in phase trajectory, ended holding"."""
    if rep.completed:
        return "completed"
    end = f", ended {rep.end_phase}" if rep.end_phase and rep.end_phase != rep.phase else ""
    return f"NOT completed in phase {rep.phase}{end}"


def failure_lines(rep) -> list[str]:
    """Why a flight is not completed: the first violation, then each output fault."""
    if rep.completed:
        return []
    lines = [f"NOT completed in phase {rep.phase}: {rep.error or (rep.violation or {}).get('detail') or rep.phase}"]
    for f in rep.faults:
        if f["detail"] != rep.error:
            lines.append(f"fault ({f['kind']}): {f['detail']}")
    return lines
