"""The guard at the flight's one exit: every frame's reference passes the guard
before it is sent; a refused one is replaced by the checked fallback, a braked
hover (pure state machine, no I/O; docs/replan.md "The guard").

``GuardGate.dispose`` takes the reference a mode proposed for this frame. If
the guard passes it, it is flown and remembered as the last accepted state.
A sample that fails is still flown while the mode brakes toward that surface
(``Verdict.braking``), or for ``GRACE_S`` (0.25 s) from the first failing
sample: a late detection gives the mode that long to start braking (the
replanner's governor does at once; its shaper reaches the braking rate in
0.15 s). Otherwise the gate *engages*: from then on it flies its own reference, the last
accepted state braked to rest by a ``ReferenceShaper`` (zero velocity command)
at the emergency brake's limits when they are given (``replan.emergency_accel_m_s2``,
``emergency_jerk_m_s3``: a refused sample is what the normal brake did not stop for),
else at the guard's acceleration limit, then held there. The stopping law
already held on the last accepted sample, so that braking ends before the
clearance. The mode's reference is no longer flown; the flight core ends the
flight once the gate is at rest (a checked landing, or a hover and report).
"""

from __future__ import annotations

import math

from ..trajectory.reference import RefSample
from ..replan.shaper import EMERGENCY_OMEGA_RAD_S, ReferenceShaper
from .divert import CANDIDATES_PER_FRAME, Divert, candidates, search
from .guard import Guard, Verdict, grace_accepts

#: Refusals kept for the report (the count goes on).
MAX_REFUSALS_KEPT = 20
#: The brake is at rest below this speed (m/s) and acceleration (m/s^2).
REST_V_M_S, REST_A_M_S2 = 0.02, 0.05
_Z3 = (0.0, 0.0, 0.0)


class GuardGate:
    """Per-frame disposal of the references (module doc).

    Parameters
    ----------
    guard : Guard
    jerk_m_s3 : float
        Jerk limit of the brake (the replanner's ``jerk_m_s3``).
    emergency : (accel m/s^2, jerk m/s^3) or None
        The emergency brake's limits (``replan.emergency_accel_m_s2``, ``emergency_jerk_m_s3``;
        pole ``EMERGENCY_OMEGA_RAD_S``): the brake's, instead of (the guard's acceleration
        limit, ``jerk_m_s3``).
    """

    def __init__(self, guard: Guard, jerk_m_s3: float, emergency: tuple[float, float] | None = None) -> None:
        self.guard = guard
        if emergency is None:
            self.shaper = ReferenceShaper(guard.cfg.accel_m_s2, jerk_m_s3)
        else:
            self.shaper = ReferenceShaper(emergency[0], emergency[1], omega_rad_s=EMERGENCY_OMEGA_RAD_S)
        self.engaged = False
        self._last: RefSample | None = None
        self._t_prev: float | None = None
        self._hold: RefSample | None = None
        self.n_samples = 0
        self.n_trajectories = 0
        self.n_landings = 0
        self.n_landings_refused = 0
        self.landing_moves: list[dict] = []
        self.n_refusals = 0
        self.n_braking = 0
        self._since: float | None = None
        self.refusals: list[dict] = []

    def refuse(self, t_s: float, verdict: Verdict, what: str) -> None:
        """Record a refusal of ``what`` (``sample``, ``trajectory``, ``takeoff``, ``landing``)."""
        self.n_refusals += 1
        if len(self.refusals) < MAX_REFUSALS_KEPT:
            self.refusals.append({"t_s": None if t_s is None else float(t_s), "candidate": what,
                                  **verdict.to_dict()})

    def check_trajectory(self, t_s: float, trajectory, t_from_s: float | None,
                         t_to_s: float | None = None) -> Verdict:
        """A mode's new candidate trajectory, from ``t_from_s`` (its clock) to ``t_to_s``
        (where it stops being new: a rejoin's ``GlobalPlan.new_until_s``; None: its end)."""
        self.n_trajectories += 1
        v = self.guard.check_trajectory(trajectory, t_from_s, t_to_s)
        if not v.ok:
            self.refuse(t_s, v, "trajectory")
        return v

    def check_takeoff(self, t_s: float, segments) -> Verdict:
        """The take-off segments (terrain from the second segment on)."""
        self.n_trajectories += 1
        v = self.guard.check_segments(segments, terrain_from=1)
        if not v.ok:
            self.refuse(t_s, v, "takeoff")
        return v

    def check_landing(self, t_s: float, p_enu_m, v_enu_m_s) -> Verdict:
        """A landing from ``p`` moving at ``v`` (``Guard.check_landing``)."""
        self.n_landings += 1
        v = self.guard.check_landing(p_enu_m, v_enu_m_s)
        if not v.ok:
            self.n_landings_refused += 1
            self.refuse(t_s, v, "landing")
        return v

    def find_landing(self, t_s: float, start, home, transit_z_m: float | None, climb_speed_m_s: float,
                     transfer_speed_m_s: float):
        """(generator: yields between ``CANDIDATES_PER_FRAME`` candidates, the caller's frames)
        A checked move from the hover at ``start`` to the nearest spot whose landing the
        guard accepts (``companion.safety.divert``), returned, or None; recorded for the
        report (``landing_moves``), found or not."""
        d = yield from search(self.guard, start, home, transit_z_m, climb_speed_m_s, transfer_speed_m_s,
                              CANDIDATES_PER_FRAME)
        if d is not None:
            found = d.to_dict()
        else:
            n = len(candidates(start, home, transit_z_m, climb_speed_m_s, transfer_speed_m_s))
            found = {"spot_enu_m": None, "path_m": None, "kind": None, "duration_s": None, "candidates_tried": n}
        self.landing_moves.append({"t_s": float(t_s), "from_enu_m": [float(c) for c in start], **found})
        return d

    def release(self, t_s: float) -> None:
        """Stop flying the braked hover (the flight core flies a checked move from its
        rest point, ``find_landing``); the frames' references are disposed again."""
        self.engaged = False
        self._hold = None
        self._since = None
        self._t_prev = t_s

    @property
    def hold_point(self) -> tuple | None:
        """Where the braked hover rests (None before it does)."""
        return None if self._hold is None else tuple(float(c) for c in self._hold.p)

    def dispose(self, t_s: float, ref: RefSample | None, terrain: bool = True) -> tuple:
        """(the reference to fly, the refusal Verdict or None) for this frame's proposal."""
        if self.engaged:
            return self.brake(t_s), None
        self._t_prev = t_s
        if ref is None:
            return None, None
        self.n_samples += 1
        v = self.guard.check_sample(ref.p, ref.v, terrain, ref.a)
        flown, self._since = grace_accepts(v.ok, v.braking, t_s, self._since)
        if v.ok:
            self._last = ref
            return ref, None
        if flown:
            # the mode brakes toward it, or has GRACE_S to start braking
            self.n_braking += 1
            self._last = ref
            return ref, None
        self.refuse(t_s, v, "sample")
        self.engage(t_s, ref)
        return self.brake(t_s), v

    def engage(self, t_s: float, proposed: RefSample) -> None:
        """Fly the braked hover from the last accepted reference's state on (from
        ``proposed``'s when none was accepted yet)."""
        self.engaged = True
        ref = self._last if self._last is not None else proposed
        self._last = ref
        self.shaper.reset(ref.p, ref.v, ref.a, ref.jerk)
        self._t_prev = t_s

    def brake(self, t_s: float) -> RefSample:
        """This frame's reference of the braked hover."""
        if self._hold is not None:
            return self._hold
        dt = 0.0 if self._t_prev is None else max(t_s - self._t_prev, 0.0)
        self._t_prev = t_s
        st = self.shaper.step(dt, _Z3)
        last = self._last
        if math.sqrt(sum(x * x for x in st.v)) < REST_V_M_S and math.sqrt(sum(x * x for x in st.a)) < REST_A_M_S2:
            self._hold = RefSample(st.p, _Z3, _Z3, _Z3, _Z3, last.s, last.target)
            return self._hold
        return RefSample(st.p, st.v, st.a, st.jerk, st.snap, last.s, last.target)

    @property
    def at_rest(self) -> bool:
        """The braked hover has come to rest."""
        return self._hold is not None

    def to_dict(self) -> dict:
        """report.json ``guard`` (docs/report-json.md)."""
        return {"engaged": self.engaged, "samples_checked": self.n_samples, "samples_braking": self.n_braking,
                "trajectories_checked": self.n_trajectories, "landings_checked": self.n_landings,
                "landings_refused": self.n_landings_refused, "landing_moves": list(self.landing_moves),
                "refusals": self.n_refusals,
                "refusal_list": list(self.refusals)}
