"""What the gate will say of a shaped reference and its brake (pure; ``Guard.forecast_brake``;
docs/replan.md "The stopping point").

The avoiding modes keep the stopping point of the reference they fly outside the
clearance: the margin rule on the shaper's predicted brake (``Guard.check_path``).
The gate judges every frame sample by other rules as well: the stopping law of
the speed rule, which a sample may break only while it brakes toward that
surface or within ``GRACE_S`` of the failing run's start (``grace_accepts``).
Passing the margin rule does not pass those. The law assumes the approach goes
on at its present rate for the delay and then brakes at the limit; a reference
passing beside a post closes at a rate that falls as it goes by, so its brake
keeps clear while the law fails. Obstacles-wide seed 20261160, flight 47: an
avoiding reference at 0.87 m/s beside a post closed at 0.74 m/s where the law
allowed 0.69 m/s. It was flown while its deceleration toward the post stayed
above ``BRAKING_FRACTION`` of the limit; once the deceleration eased, 0.36 s into
the run, the gate refused it and the flight ended "failed".

So the state a mode commits must be one whose brake the gate flies: every point
of the predicted brake (``brake.brake_states``, one per step) judged as the gate
judges a frame sample (``Guard.sample_flags``), the failing run carried on from
the one the gate is in. A deceleration cannot be restored within a frame (the
jerk limit moves it 8 mm/s^2 a frame), so only this look ahead lets the mode
brake harder before the gate would refuse. The brake is judged every step, not
every frame: a stretch that neither passes nor brakes can begin up to a step
before the point that shows it, so the prediction gets ``GRACE_S`` less one step.
"""

from __future__ import annotations

from dataclasses import replace

from .grace import GRACE_S, grace_accepts


def brake_verdict(guard, P, V, A, dt_s: float, since_s: float | None, terrain: bool = True,
                  flags: tuple | None = None):
    """The gate's verdict on a predicted brake: (M, 3) positions ``P``, velocities ``V`` and
    accelerations ``A`` (ENU), the first the state to be committed, one every ``dt_s``.
    ``since_s``: the start of the failing run the gate is in, relative to the first point
    (<= 0; None when its last sample passed). The first point the gate would refuse, as
    ``Guard.check_sample``'s verdict (``t_s``: its time after the first), or None.
    ``flags``: ``guard.sample_flags`` of the points when already known (``Guard.check_brake``)."""
    ok, braking, surface = guard.sample_flags(P, V, A, terrain) if flags is None else flags
    if ok.all():
        return None
    since = since_s
    grace = GRACE_S - dt_s
    for k in range(len(ok)):
        t = k * dt_s
        flown, since = grace_accepts(bool(ok[k]), bool(braking[k]), t, since, grace)
        if not flown:
            v = guard.check_sample(P[k], V[k], terrain, A[k])
            if v.ok:                          # the scalar and array laws at a tie
                return replace(v, ok=False, rule="speed", surface=surface[k], t_s=t,
                               detail=f"brake at +{t:.2f} s: {surface[k]} speed (at a tie)",
                               point_enu_m=tuple(float(c) for c in P[k]))
            return replace(v, detail=f"brake at +{t:.2f} s: {v.detail}", t_s=t)
    return None
