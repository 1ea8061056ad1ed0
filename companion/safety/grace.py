"""The gate's grace: which failing frame samples it still flies (pure; ``GuardGate.dispose``,
and the avoiding modes' forecast of it, ``companion.safety.gate_forecast``)."""

from __future__ import annotations

#: A frame sample that fails is flown for this long (s) before it is refused, unless the
#: mode brakes (``GuardGate``): the time the reference shaper takes to reach
#: ``BRAKING_FRACTION`` of 1 m/s^2 at 2 m/s^3 (0.15 s), with room to spare.
GRACE_S = 0.25


def grace_accepts(ok: bool, braking: bool, t_s: float, since_s: float | None,
                  grace_s: float = GRACE_S) -> tuple[bool, float | None]:
    """The gate's rule on one frame sample (``GuardGate.dispose``): (flown, the failing run's
    start after it). A sample that passes is flown and ends the run (None); one that fails
    starts a run (at ``t_s``) or goes on with it, and is flown while it brakes toward that
    surface or within ``grace_s`` of the run's start."""
    if ok:
        return True, None
    since = t_s if since_s is None else since_s
    return bool(braking or t_s - since <= grace_s), since
