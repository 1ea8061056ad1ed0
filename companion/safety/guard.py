"""The guard: one 3-D check of every reference before it reaches the link (pure).

Modes propose, the guard disposes (docs/replan.md "The guard"). The vehicle is
the sphere of the airframe radius ``R`` (``companion.margins``); it must keep

- ``R + terrain_clearance_m`` between its centre and the terrain under it
  (height above the DEM; the replanner's floor ``floor_agl_m``, at least R);
- ``R + row_clearance_m`` from the vine rows extruded to the canopy (the
  plan's own margin, ``coverage.safety_margin_m``), less half an OGM cell
  (the planner's erosion is measured between cell centres);
- ``R + obstacle_clearance_m`` from every obstacle the vehicle knows
  (``replan.clearance_m``), read through ``obstacle_distance``
  (``companion.safety.obstacles``).

Rules, for a sample (p, v) of a reference; ``d`` its distance to a surface,
``req`` the distance it must keep, ``approach`` the rate at which ``d``
shrinks along ``v`` (a finite difference of ``d`` over ``STEP_M``):

``clearance``  d < req and approach > ``SPEED_TOLERANCE_M_S``: the reference
               closes on a surface it is already too near (moving away or
               along it, a reference inside the clearance may get out);
``speed``      (terrain and obstacles) approach > v_max(d - req) +
               ``SPEED_TOLERANCE_M_S``, the stopping law of PX4's collision
               prevention (``companion.safety.stopping``; ``accel_m_s2``,
               ``delay_s`` as CP_DELAY, d - req as CP_DIST): the vehicle can
               always stop before the clearance. Not for the rows: they are
               known in advance, and a whole trajectory is checked against them.

A whole candidate trajectory is sampled every ``SAMPLE_DT_S`` from its start
to its end (not its first seconds) and every sample must pass both rules and
the margin rule of its path (``companion.safety.margin_rule``): never within
the airframe radius of a surface (contact); a candidate that starts inside a
clearance never gets closer than it has been until it is out (moving away is
always allowed, closing never is); once out, it stays out.
``check_path`` applies the margin rule to a path of points alone: the
reference shaper's predicted brake (``companion.replan.brake``), so the
avoiding modes keep the stopping point of the reference they fly outside the
clearance (docs/replan.md "The stopping point").
A landing is checked as the column under the vehicle's braking footprint
(from where it is to where it stops), from its height down to the ground:
every point keeps the clearance of the rows and obstacles (``check_landing``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .margin_rule import CLOSING_TOL_M, MarginRule, margin_violations
from . import gate_forecast
from .grace import GRACE_S, grace_accepts  # noqa: F401  (the gate's rule; re-exported)
from .stopping import stopping_distance_m, stopping_speed_m_s

#: Sensing and control delay (s) of the stopping law (PX4 CP_DELAY). The fallback's
#: brake (the reference shaper at 1 m/s^2 and 2 m/s^3) stops from 1 m/s in 0.97 m and
#: from 0.5 m/s in 0.37 m; v tau + v^2 / (2 a) with tau = 0.5 s gives 1.0 m and 0.375 m,
#: so a reference the law passed can always be braked before the clearance.
DELAY_S = 0.5
#: Approach speeds within this (m/s) of the allowed one pass (the finite difference's noise).
SPEED_TOLERANCE_M_S = 0.05
#: Length (m) of the finite-difference step along the velocity.
STEP_M = 0.02
#: Candidate trajectories are sampled this often (s): 5 cm at 1 m/s.
SAMPLE_DT_S = 0.05
#: Samples per chunk of a long trajectory (bounded memory).
CHUNK = 20000
#: Vertical spacing (m) of the points of a landing column.
COLUMN_STEP_M = 0.05
#: A reference brakes toward a surface when its approach speed falls at this fraction of
#: the acceleration limit or faster (the shaper's brake reaches it in 0.15 s at 2 m/s^3).
BRAKING_FRACTION = 0.3
#: Speeds (m/s) below this are at rest (no approach).
REST_M_S = 1e-3
KINDS = ("terrain", "row", "obstacle")


def _step(x: np.ndarray) -> tuple:
    """(nonzero (K,), h (K,)) of (K, 3) rates ``x`` (velocities, accelerations): which exceed
    ``REST_M_S`` and the time step that moves ``STEP_M`` along them (0 where not): the finite
    differences of the rules (``Guard._judge``, ``_flag_points``)."""
    n = np.sqrt(np.einsum("ki,ki->k", x, x))
    nonzero = n > REST_M_S
    return nonzero, np.where(nonzero, STEP_M / np.maximum(n, REST_M_S), 0.0)


def _flag_points(p_enu_m, v_enu_m_s, a_enu_m_s2) -> tuple:
    """(p, v, a, points, steps) of K samples: the (3K, 3) points whose distances judge them
    (each sample, a ``STEP_M`` step along its velocity, one along its acceleration) and the
    steps' (moving, dt, accelerating, ha) arrays (``Guard.sample_flags``)."""
    p = np.asarray(p_enu_m, float).reshape(-1, 3)
    v = np.asarray(v_enu_m_s, float).reshape(-1, 3)
    a = np.asarray(a_enu_m_s2, float).reshape(-1, 3)
    moving, dt = _step(v)
    accel, ha = _step(a)
    return p, v, a, np.vstack([p, p + v * dt[:, None], p + a * ha[:, None]]), (moving, dt, accel, ha)


@dataclass(frozen=True)
class GuardConfig:
    """The guard's numbers (module doc). Lengths m, speeds m/s.

    Attributes
    ----------
    airframe_radius_m : float
        R, the sphere holding the vehicle.
    terrain_clearance_m, row_clearance_m, obstacle_clearance_m : float
        Clearance from the airframe's surface to the terrain, the rows, the obstacles.
    accel_m_s2 : float
        Braking acceleration of the stopping law.
    delay_s : float
        Sensing and control delay of the stopping law (CP_DELAY).
    """

    airframe_radius_m: float
    terrain_clearance_m: float
    row_clearance_m: float
    obstacle_clearance_m: float
    accel_m_s2: float
    delay_s: float = DELAY_S

    def required_m(self, kind: str) -> float:
        """Distance (m) the vehicle's centre keeps from a surface of ``kind``."""
        return self.airframe_radius_m + getattr(self, f"{kind}_clearance_m")

    @classmethod
    def from_mission(cls, mission) -> "GuardConfig":
        """A mission's guard: R from ``companion.margins``, the terrain clearance up to
        ``replan.floor_agl_m`` (at least 0), the rows ``coverage.safety_margin_m``,
        the obstacles ``replan.clearance_m``, braking at ``replan.accel_m_s2``."""
        from ..margins import mission_airframe_radius_m

        R = mission_airframe_radius_m(mission)
        rp = mission.replan
        return cls(R, max(0.0, float(rp.floor_agl_m) - R), float(mission.coverage.safety_margin_m),
                   float(rp.clearance_m), float(rp.accel_m_s2))


@dataclass(frozen=True, slots=True)
class Verdict:
    """The guard's answer on a candidate.

    Attributes
    ----------
    ok : bool
    rule : str or None
        ``clearance``, ``speed`` or ``landing`` (None when ok); a replanner's candidate also
        ``ceiling`` or ``path`` (``companion.replan.pace``).
    surface : str or None
        ``terrain``, ``row`` or ``obstacle``.
    detail : str
        One line: what and where.
    t_s : float or None
        Time of the first failing sample (the candidate's clock; None for a point).
    point_enu_m : tuple or None
        That sample's position (ENU m).
    distance_m, required_m : float or None
        Its centre's distance to the surface and the distance it must keep (m).
    approach_m_s, allowed_m_s : float or None
        Its approach speed and the stopping law's limit (m/s).
    braking : bool
        A failing frame sample whose reference already brakes toward that surface
        (``Guard.check_sample``; the gate lets it brake).
    """

    ok: bool
    rule: str | None = None
    surface: str | None = None
    detail: str = ""
    t_s: float | None = None
    point_enu_m: tuple | None = None
    distance_m: float | None = None
    required_m: float | None = None
    approach_m_s: float | None = None
    allowed_m_s: float | None = None
    braking: bool = False

    def to_dict(self) -> dict:
        """Plain JSON types (report.json ``guard.refusals``)."""
        def num(x):
            return None if x is None or not math.isfinite(x) else float(x)
        return {"rule": self.rule, "surface": self.surface, "detail": self.detail, "candidate_t_s": num(self.t_s),
                "point_enu_m": None if self.point_enu_m is None else [float(c) for c in self.point_enu_m],
                "distance_m": num(self.distance_m), "required_m": num(self.required_m),
                "approach_m_s": num(self.approach_m_s), "allowed_m_s": num(self.allowed_m_s)}


PASS = Verdict(True)


class Guard:
    """The guard (module doc).

    Parameters
    ----------
    cfg : GuardConfig
    scene : SafetyScene
        Terrain and rows.
    obstacle_distance : callable or None
        ``f((M, 3) ENU points) -> (M,) distance (m) to the nearest known obstacle
        surface, inf if none`` (``companion.safety.obstacles``); None: no obstacles.
        ``distances(..., known=K)`` calls it as ``f(points, K)`` (the replanner's map
        ``K`` whose added cells count: ``known_obstacle_distance`` takes it), for a 3-D
        route searched on the map it will be flown on (``companion.replan.route3d``).
    """

    def __init__(self, cfg: GuardConfig, scene, obstacle_distance=None) -> None:
        self.cfg = cfg
        self.scene = scene
        self.obstacle_distance = obstacle_distance
        self._req = {k: cfg.required_m(k) for k in KINDS}
        # the rows are known to the cell: the planner erodes the free space between cell
        # centres, so a plan keeps its margin to within half a cell (vineyard-1ha: 6 mm short)
        self._req["row"] -= 0.5 * scene.rows.res_m

    def required_m(self, kind: str) -> float:
        """Distance (m) the vehicle's centre keeps from the surfaces of ``kind`` (the rows'
        less half an OGM cell, class doc)."""
        return self._req[kind]

    # --- distances -----------------------------------------------------------------------

    def distances(self, points_enu_m: np.ndarray, terrain: bool = True, known=None) -> dict:
        """{kind: (M,) distance (m)} of (M, 3) ENU points: height above the terrain, distance
        to the rows, to the known obstacles (inf without; terrain inf when ``terrain`` is False).
        ``known``: the replanner's map whose added obstacle cells count (default the one the
        obstacle distance reads itself: ``known_obstacle_distance``'s ``known_map``)."""
        p = np.asarray(points_enu_m, float).reshape(-1, 3)
        inf = np.full(len(p), np.inf)
        out = {"terrain": p[:, 2] - self.scene.terrain.z(p[:, 0], p[:, 1]) if terrain else inf,
               "row": self.scene.rows.distance(p)}
        od = self.obstacle_distance
        if od is None:
            out["obstacle"] = inf
        else:
            out["obstacle"] = np.asarray(od(p) if known is None else od(p, known), float).reshape(-1)
        return out

    # --- rules ------------------------------------------------------------------------------

    def _rules(self, kind: str, d0, d1, moving, dt) -> tuple:
        """(approach, allowed, clearance broken, speed broken), (K,) each, of K samples of
        ``kind`` at distances ``d0`` whose step ``dt`` along the velocity (``_step``) reaches
        ``d1`` (module doc's rules; the rows have no speed rule: allowed inf)."""
        req = self._req[kind]
        with np.errstate(invalid="ignore"):
            approach = np.where(moving & np.isfinite(d0), (d0 - d1) / np.where(moving, dt, 1.0), 0.0)
        bad_c = (d0 < req) & (approach > SPEED_TOLERANCE_M_S)
        if kind == "row":
            return approach, np.full(len(d0), np.inf), bad_c, np.zeros(len(d0), bool)
        allowed = stopping_speed_m_s(d0 - req, self.cfg.accel_m_s2, self.cfg.delay_s)
        return approach, allowed, bad_c, approach > allowed + SPEED_TOLERANCE_M_S

    def _judge(self, p, v, t=None, terrain: bool = True, margin_bad: dict | None = None) -> Verdict:
        """The rules on (K, 3) samples p with velocities v (first failing sample, or PASS).
        ``margin_bad[kind]``: (K,) bool, the samples that break the margin rule of the
        candidate's path (``margin_rule``; they fail the clearance rule whatever their approach)."""
        p = np.asarray(p, float).reshape(-1, 3)
        v = np.asarray(v, float).reshape(-1, 3)
        moving, dt = _step(v)
        d_all = self.distances(np.vstack([p, p + v * dt[:, None]]), terrain)
        first, worst = len(p), None
        for kind in KINDS:
            d0, d1 = d_all[kind][:len(p)], d_all[kind][len(p):]
            if not np.isfinite(d0).any():
                continue
            req = self._req[kind]
            approach, allowed, bad_c, bad_s = self._rules(kind, d0, d1, moving, dt)
            if margin_bad is not None and kind in margin_bad:
                bad_c |= margin_bad[kind]
            bad = bad_c | bad_s
            if bad.any():
                k = int(np.argmax(bad))
                if k < first:
                    rule = "clearance" if bad_c[k] else "speed"
                    first, worst = k, (rule, kind, float(d0[k]), req, float(approach[k]), float(allowed[k]))
        if worst is None:
            return PASS
        rule, kind, d, req, app, allow = worst
        q = tuple(float(c) for c in p[first])
        tk = None if t is None else float(np.asarray(t, float).reshape(-1)[first])
        what = (f"{d - req:+.2f} m from its clearance" if rule == "clearance"
                else f"approach {app:.2f} m/s > {allow:.2f} m/s")
        if rule == "clearance" and d < self.cfg.airframe_radius_m:
            what += " (contact)"
        where = f" at t={tk:.2f} s" if tk is not None else ""
        return Verdict(False, rule, kind, f"{kind} {rule}: {what}{where}", tk, q, d, req, app, allow)

    def speed_limits(self, p_enu_m, u_enu) -> np.ndarray:
        """(M,) the largest speed (m/s) at (M, 3) points ``p`` moving along (M, 3) unit
        directions ``u`` that the speed rule passes: ``v_max(d - req)`` (the stopping law) over
        the approach per unit speed along ``u`` (a finite difference over ``STEP_M``), the
        least over the terrain and the obstacles; inf where ``u`` closes on neither, and
        inside a clearance (d < req), where no speed mends a closing path: the margin rule
        judges it (slowing a stopped vehicle's way out there made the LQR, its way-points far
        apart in time, drift toward the obstacle on its initial state: obstacles-wide seed
        20261127, flight 16). The same law as ``_judge``'s, for planning a speed rather than
        judging one."""
        p = np.asarray(p_enu_m, float).reshape(-1, 3)
        u = np.asarray(u_enu, float).reshape(-1, 3)
        d_all = self.distances(np.vstack([p, p + STEP_M * u]))
        out = np.full(len(p), np.inf)
        for kind in ("terrain", "obstacle"):
            d0, d1 = d_all[kind][:len(p)], d_all[kind][len(p):]
            with np.errstate(invalid="ignore"):
                closing = np.where(np.isfinite(d0), (d0 - d1) / STEP_M, 0.0)
            allowed = stopping_speed_m_s(d0 - self._req[kind], self.cfg.accel_m_s2, self.cfg.delay_s)
            lim = np.where((closing > 1e-6) & ~(d0 < self._req[kind]), allowed / np.maximum(closing, 1e-6), np.inf)
            out = np.minimum(out, lim)
        return out

    def check_sample(self, p_enu_m, v_enu_m_s, terrain: bool = True, a_enu_m_s2=None) -> Verdict:
        """One reference sample (position ENU m, velocity ENU m/s): both rules (module doc).
        ``terrain`` False: the terrain is not checked (take-off from the ground).
        ``a_enu_m_s2``: the sample's acceleration; a failing verdict then says whether
        the reference is braking toward that surface (``Verdict.braking``: its approach
        speed falls at ``BRAKING_FRACTION`` of the acceleration limit or faster)."""
        v = self._judge_one(p_enu_m, v_enu_m_s, terrain)
        if v.ok or a_enu_m_s2 is None:
            return v
        a = np.asarray(a_enu_m_s2, float).reshape(3)
        an = float(np.sqrt(a @ a))
        if an <= REST_M_S:
            return v
        h = STEP_M / an
        p = np.asarray(p_enu_m, float).reshape(3)
        d = self.distances(np.vstack([p, p + a * h]), v.surface == "terrain")[v.surface]
        decel = (d[1] - d[0]) / h           # the rate at which the approach speed falls
        return replace(v, braking=bool(decel >= BRAKING_FRACTION * self.cfg.accel_m_s2))

    def sample_flags(self, p_enu_m, v_enu_m_s, a_enu_m_s2, terrain: bool = True) -> tuple:
        """(ok (K,), braking (K,), surface (K,)) of K samples (positions, velocities,
        accelerations (K, 3)): ``check_sample``'s verdict on each, in arrays: its ``ok``, and
        where it fails its ``braking`` toward the surface it names and that surface (an object
        array of str; None and False where ok). The reference shaper's predicted brake is
        judged with it as the gate would judge it (``grace_accepts``)."""
        p = np.asarray(p_enu_m, float).reshape(-1, 3)
        return self._flags_at(p, v_enu_m_s, a_enu_m_s2, self.distances(p, terrain), terrain)[:3]

    def check_brake(self, here_enu_m, p_enu_m, v_enu_m_s, a_enu_m_s2, margin_m: float,
                    inner_tol_m: float, step_all: bool = False) -> tuple:
        """(``check_path`` of the path from ``here`` through the (K, 3) points ``p``, the
        ``sample_flags`` of the K samples (p, v, a), whether every sample was stepped): the
        reference shaper's predicted brake judged by the margin rule and as the gate judges a
        sample. A distance query costs mostly per call (the terrain, the rows and the obstacle
        map each answer once), so ``step_all`` (the caller's guess: its last brake needed the
        steps) asks for the points and all their steps at once; otherwise the points first,
        and the steps only of those whose bound may fail (``_flags_at``)."""
        p = np.asarray(p_enu_m, float).reshape(-1, 3)
        here = np.asarray(here_enu_m, float).reshape(-1, 3)
        n, K = len(here), len(p)
        if step_all:
            p, v, a, pts, steps = _flag_points(p, v_enu_m_s, a_enu_m_s2)
            d = self.distances(np.vstack([here, pts]))
            verdict = self._margin_verdict(np.vstack([here, p]), {k: d[k][:n + K] for k in KINDS}, margin_m, None,
                                           inner_tol_m)
            return verdict, self._flags({k: d[k][n:] for k in KINDS}, K, steps), True
        path = np.vstack([here, p])
        d = self.distances(path)
        verdict = self._margin_verdict(path, d, margin_m, None, inner_tol_m)
        flags = self._flags_at(p, v_enu_m_s, a_enu_m_s2, {k: d[k][n:] for k in KINDS}, True)
        return verdict, flags[:3], flags[3]

    def _flags_at(self, p, v_enu_m_s, a_enu_m_s2, d0: dict, terrain: bool) -> tuple:
        """``sample_flags`` given the samples' own distances ``d0``, and whether any sample
        was stepped. A sample that cannot
        fail is not stepped (the distance queries cost mostly per call): the approach
        cannot exceed the speed toward the rows and the obstacles (their distances are
        1-Lipschitz), nor the sink rate plus the level speed times the steepest slope toward
        the terrain (``TerrainField.max_slope``). So a sample outside every clearance whose
        bound the law allows passes; only the others need the steps along their velocity and
        acceleration (``_flags``)."""
        v = np.asarray(v_enu_m_s, float).reshape(-1, 3)
        a = np.asarray(a_enu_m_s2, float).reshape(-1, 3)
        K = len(p)
        speed = np.sqrt(np.einsum("ki,ki->k", v, v))
        bound = {"row": speed, "obstacle": speed,
                 "terrain": np.maximum(-v[:, 2], 0.0) + np.hypot(v[:, 0], v[:, 1]) * self.scene.terrain.max_slope}
        maybe = np.zeros(K, bool)
        cfg = self.cfg
        for kind in KINDS:
            dk = d0[kind]
            fin = np.isfinite(dk)
            if not fin.any():
                continue
            req = self._req[kind]
            m = dk < req
            if kind != "row":
                allowed = stopping_speed_m_s(dk - req, cfg.accel_m_s2, cfg.delay_s)
                m |= bound[kind] > allowed + SPEED_TOLERANCE_M_S - 1e-9
            maybe |= m & fin
        ok = np.ones(K, bool)
        braking = np.zeros(K, bool)
        surface = np.full(K, None, dtype=object)
        idx = np.flatnonzero(maybe)
        if len(idx):
            _, _, _, pts, steps = _flag_points(p[idx], v[idx], a[idx])
            k = len(idx)
            dd = self.distances(pts[k:], terrain)
            o, b, s = self._flags({kind: np.concatenate([d0[kind][idx], dd[kind]]) for kind in KINDS}, k, steps)
            ok[idx], braking[idx], surface[idx] = o, b, s
        return ok, braking, surface, bool(len(idx))

    def forecast_brake(self, here_enu_m, p_enu_m, v_enu_m_s, a_enu_m_s2, dt_s: float, since_s: float | None,
                       margin_m: float, inner_tol_m: float, step_all: bool = False) -> tuple:
        """(Verdict, (ok, braking) of the first sample, stepped) on the reference shaper's
        predicted brake: (K, 3) positions, velocities and accelerations every ``dt_s`` from the
        state to be committed (the first) to rest, after ``here``. It passes the margin rule
        (``check_path`` with ``margin_m``, ``inner_tol_m``) and the gate flies every sample of
        it, the gate's failing run begun at ``since_s`` relative to the first sample
        (``gate_forecast``; None: no run). ``step_all``, stepped: ``check_brake``'s."""
        verdict, flags, stepped = self.check_brake(here_enu_m, p_enu_m, v_enu_m_s, a_enu_m_s2, margin_m,
                                                   inner_tol_m, step_all)
        if verdict.ok:
            refused = gate_forecast.brake_verdict(self, p_enu_m, v_enu_m_s, a_enu_m_s2, dt_s, since_s, flags=flags)
            verdict = PASS if refused is None else refused
        return verdict, (bool(flags[0][0]), bool(flags[1][0])), stepped

    @staticmethod
    def gate_run(ok: bool, braking: bool, t_s: float, since_s: float | None) -> float | None:
        """The start of the gate's failing run after a sample it judged (``grace_accepts``)."""
        return grace_accepts(ok, braking, t_s, since_s)[1]

    def _flags(self, d: dict, K: int, steps: tuple) -> tuple:
        """``sample_flags`` from the distances of ``_flag_points``'s points."""
        moving, dt, accel, ha = steps
        failed = np.zeros(K, bool)
        braking = np.zeros(K, bool)
        surface = np.full(K, None, dtype=object)
        for kind in KINDS:                    # the first kind that fails names the surface
            d0, d1, d2 = d[kind][:K], d[kind][K:2 * K], d[kind][2 * K:]
            if not np.isfinite(d0).any():
                continue
            _, _, bad_c, bad_s = self._rules(kind, d0, d1, moving, dt)
            with np.errstate(invalid="ignore"):
                decel = np.where(accel & np.isfinite(d0), (d2 - d0) / np.where(accel, ha, 1.0), 0.0)
            bad = bad_c | bad_s
            new = bad & ~failed
            braking[new] = decel[new] >= BRAKING_FRACTION * self.cfg.accel_m_s2
            surface[new] = kind
            failed |= bad
        return ~failed, braking, surface

    def row_room(self, p_enu_m) -> tuple[float, tuple[float, float, float]]:
        """(room m, unit normal) of a point against the rows: its distance to them less the
        distance it must keep (negative inside the clearance), and the direction in which
        that distance grows fastest (central differences of ``STEP_M``; the distance is
        1-Lipschitz, so this is the normal away from the nearest row surface). (inf, 0)
        without rows. The replanner's avoidance governs its approach with it, so the
        guard's ``clearance`` rule has nothing to refuse (docs/replan.md "Rows")."""
        rows = self.scene.rows
        x, y, z = float(p_enu_m[0]), float(p_enu_m[1]), float(p_enu_m[2])
        d = rows.distance_one(x, y, z)
        if not math.isfinite(d):
            return math.inf, (0.0, 0.0, 0.0)
        e = STEP_M
        g = ((rows.distance_one(x + e, y, z) - rows.distance_one(x - e, y, z)) / (2.0 * e),
             (rows.distance_one(x, y + e, z) - rows.distance_one(x, y - e, z)) / (2.0 * e),
             (rows.distance_one(x, y, z + e) - rows.distance_one(x, y, z - e)) / (2.0 * e))
        norm = math.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
        n = (0.0, 0.0, 0.0) if norm <= 1e-9 else (g[0] / norm, g[1] / norm, g[2] / norm)
        return d - self._req["row"], n

    def _judge_one(self, p, v, terrain: bool) -> Verdict:
        """``_judge`` of one sample in plain floats (the per-frame path: about a third
        of the array version's cost); the same rules, the same verdicts."""
        vx, vy, vz = float(v[0]), float(v[1]), float(v[2])
        speed = math.sqrt(vx * vx + vy * vy + vz * vz)
        if speed <= REST_M_S:
            return PASS                  # at rest: no approach, neither rule can fail
        x, y, z = float(p[0]), float(p[1]), float(p[2])
        h = STEP_M / speed
        x1, y1, z1 = x + vx * h, y + vy * h, z + vz * h
        rows, ter = self.scene.rows, self.scene.terrain.scalar
        pairs = {"row": (rows.distance_one(x, y, z), rows.distance_one(x1, y1, z1))}
        if terrain:
            pairs["terrain"] = (z - ter(x, y), z1 - ter(x1, y1))
        od = self.obstacle_distance
        if od is not None:
            d = od(np.array([[x, y, z], [x1, y1, z1]]))
            pairs["obstacle"] = (float(d[0]), float(d[1]))
        cfg = self.cfg
        at = cfg.accel_m_s2 * cfg.delay_s
        for kind in KINDS:
            if kind not in pairs:
                continue
            d0, d1 = pairs[kind]
            if not math.isfinite(d0):
                continue
            req = self._req[kind]
            approach = (d0 - d1) / h
            allowed = math.inf
            if kind != "row":
                allowed = math.sqrt(2.0 * cfg.accel_m_s2 * max(d0 - req, 0.0) + at * at) - at
            if d0 < req and approach > SPEED_TOLERANCE_M_S:
                rule = "clearance"
            elif approach > allowed + SPEED_TOLERANCE_M_S:
                rule = "speed"
            else:
                continue
            what = (f"{d0 - req:+.2f} m from its clearance" if rule == "clearance"
                    else f"approach {approach:.2f} m/s > {allowed:.2f} m/s")
            return Verdict(False, rule, kind, f"{kind} {rule}: {what}", None, (x, y, z), d0, req, approach, allowed)
        return PASS

    def check_points(self, p_enu_m, v_enu_m_s, t_s=None, terrain: bool = True) -> Verdict:
        """The samples of a candidate (K, 3) positions and velocities at times ``t_s`` (K,):
        the rules at every sample, and the margin rule along them (module doc)."""
        p = np.asarray(p_enu_m, float).reshape(-1, 3)
        d = self.distances(p, terrain)
        R = self.cfg.airframe_radius_m
        bad = {kind: margin_violations(d[kind], self._req[kind], R) for kind in KINDS}
        return self._judge(p, v_enu_m_s, t_s, terrain, bad)

    def check_path(self, points_enu_m, margin_m: float = 0.0, tol_m: float | None = None,
                   inner_tol_m: float | None = None) -> Verdict:
        """The margin rule (``margin_rule``) along a path of (M, 3) ENU points, in order,
        against every surface, with the distance to keep raised by ``margin_m`` and the
        closing allowed inside it ``tol_m`` (default ``CLOSING_TOL_M``); with
        ``inner_tol_m``, the rule at the clearance itself too (no margin), closing inside it
        at most that: the reference shaper's predicted brake (``companion.replan.brake``).
        The failing verdict's ``point_enu_m`` is the first point that breaks it."""
        p = np.asarray(points_enu_m, float).reshape(-1, 3)
        return self._margin_verdict(p, self.distances(p), margin_m, tol_m, inner_tol_m)

    def _margin_verdict(self, p, d: dict, margin_m: float, tol_m, inner_tol_m) -> Verdict:
        """``check_path`` of the points ``p`` whose distances are ``d``."""
        R = self.cfg.airframe_radius_m
        rules = [(margin_m, CLOSING_TOL_M if tol_m is None else float(tol_m))]
        if inner_tol_m is not None:
            rules.append((0.0, float(inner_tol_m)))
        for (margin, tol), kind in ((r, k) for r in rules for k in KINDS):
            req = self._req[kind] + margin
            bad = margin_violations(d[kind], req, R, tol)
            if bad.any():
                k = int(np.argmax(bad))
                q = tuple(float(c) for c in p[k])
                return Verdict(False, "clearance", kind,
                               f"{kind} clearance: stopping point {d[kind][k] - req:+.2f} m from its clearance",
                               None, q, float(d[kind][k]), req)
        return PASS

    def normal(self, kind: str, p_enu_m) -> np.ndarray:
        """(3,) unit direction in which the distance to the surfaces of ``kind`` grows fastest
        at ``p`` (central differences of ``STEP_M``; zeros where flat or infinite)."""
        p = np.asarray(p_enu_m, float).reshape(3)
        e = STEP_M
        q = np.vstack([p + e * np.eye(3), p - e * np.eye(3)])
        d = self.distances(q)[kind]
        if not np.isfinite(d).all():
            return np.zeros(3)
        g = (d[:3] - d[3:]) / (2.0 * e)
        n = float(np.linalg.norm(g))
        return g / n if n > 1e-9 else np.zeros(3)

    def check_trajectory(self, trajectory, t_from_s: float | None = None, t_to_s: float | None = None,
                         terrain: bool = True) -> Verdict:
        """A candidate trajectory (``sample(times)`` with ``.p``, ``.v``; ``t0``, ``tf``) from
        ``t_from_s`` (default its start) to ``t_to_s`` (default its end), sampled every
        ``SAMPLE_DT_S`` in chunks of ``CHUNK`` (module doc)."""
        t0 = float(trajectory.t0 if t_from_s is None else max(t_from_s, trajectory.t0))
        tf = float(trajectory.tf if t_to_s is None else min(t_to_s, trajectory.tf))
        n = int(math.floor(max(tf - t0, 0.0) / SAMPLE_DT_S)) + 1
        R = self.cfg.airframe_radius_m
        rules = {k: MarginRule(self._req[k], R) for k in KINDS}
        for k0 in range(0, n, CHUNK):
            t = t0 + SAMPLE_DT_S * np.arange(k0, min(k0 + CHUNK, n))
            if k0 + CHUNK >= n and tf - t[-1] > 1e-9:
                t = np.append(t, tf)
            s = trajectory.sample(t)
            p, v = np.asarray(s.p, float).reshape(-1, 3), np.asarray(s.v, float).reshape(-1, 3)
            d = self.distances(p, terrain)
            verdict = self._judge(p, v, t, terrain, {kind: rules[kind].step(d[kind]) for kind in KINDS})
            if not verdict.ok:
                return verdict
        return PASS

    def check_ceiling(self, trajectory, t_from_s: float, t_to_s: float | None, ceiling_agl_m: float,
                      tol_m: float = 0.0) -> Verdict:
        """A replanner's candidate from ``t_from_s`` to ``t_to_s`` (None: its end) stays under
        the ceiling: the terrain plus ``ceiling_agl_m`` plus ``tol_m`` (samples every
        ``SAMPLE_DT_S``; rule ``ceiling``, surface ``terrain``). The climbs and the routes keep
        under it by construction; an LQR fitted through sparse way-points need not
        (``companion.replan.pace``)."""
        t0 = float(max(t_from_s, trajectory.t0))
        tf = float(trajectory.tf if t_to_s is None else min(t_to_s, trajectory.tf))
        t = np.append(np.arange(t0, tf, SAMPLE_DT_S), tf)
        p = np.asarray(trajectory.sample(t).p, float).reshape(-1, 3)
        over = p[:, 2] - (self.scene.terrain.z(p[:, 0], p[:, 1]) + ceiling_agl_m + tol_m)
        if not (over > 0.0).any():
            return PASS
        k = int(np.argmax(over > 0.0))
        return self.refusal("ceiling", "terrain", f"ceiling: {over[k] + tol_m:+.2f} m above the "
                            f"{ceiling_agl_m:g} m ceiling at t={t[k]:.2f} s", float(t[k]), p[k])

    @staticmethod
    def refusal(rule: str, surface: str | None, detail: str, t_s: float | None, point_enu_m) -> Verdict:
        """A failing verdict of a rule judged outside the guard's own (the replanner's
        ``pace``: a ceiling, a path kept)."""
        return Verdict(False, rule, surface, detail, t_s,
                       None if point_enu_m is None else tuple(float(c) for c in point_enu_m))

    def check_obstacle_clear(self, trajectory, t_from_s: float) -> Verdict:
        """The part of a candidate from ``t_from_s`` to its end keeps out of every known
        obstacle's clearance (samples every ``SAMPLE_DT_S``; the clearance alone, not the
        speed rule, not the rows): the tail of a rejoin, which flies the installed plan
        (``companion.replan.pace``), must not run into an obstacle seen since."""
        if self.obstacle_distance is None:
            return PASS
        t0, tf = float(max(t_from_s, trajectory.t0)), float(trajectory.tf)
        req = self._req["obstacle"]
        n = int(math.floor(max(tf - t0, 0.0) / SAMPLE_DT_S)) + 1
        for k0 in range(0, n, CHUNK):
            t = t0 + SAMPLE_DT_S * np.arange(k0, min(k0 + CHUNK, n))
            p = np.asarray(trajectory.sample(t).p, float).reshape(-1, 3)
            d = np.asarray(self.obstacle_distance(p), float)
            bad = d < req
            if bad.any():
                k = int(np.argmax(bad))
                return Verdict(False, "clearance", "obstacle",
                               f"obstacle clearance: {d[k] - req:+.2f} m from its clearance at t={t[k]:.2f} s "
                               "(the plan it rejoins)", float(t[k]), tuple(float(c) for c in p[k]), float(d[k]), req)
        return PASS

    def check_segments(self, segments, terrain_from: int = 0) -> Verdict:
        """Straight segments ``[(p0, p1, duration_s), ...]`` (the take-off) flown back to back
        at their mean speed, sampled every ``COLUMN_STEP_M``; the terrain is checked from
        segment ``terrain_from`` on (the first climb leaves the ground)."""
        for i, (p0, p1, T) in enumerate(segments):
            a, b = np.asarray(p0, float), np.asarray(p1, float)
            L = float(np.linalg.norm(b - a))
            m = max(2, int(math.ceil(L / COLUMN_STEP_M)) + 1)
            s = np.linspace(0.0, 1.0, m)[:, None]
            v = np.broadcast_to((b - a) / max(float(T), 1e-9), (m, 3))
            verdict = self.check_points(a + s * (b - a), v, None, terrain=i >= terrain_from)
            if not verdict.ok:
                return verdict
        return PASS

    def braking_footprint(self, p_enu_m, v_enu_m_s, n: int = 8) -> np.ndarray:
        """(n, 2) points from ``p`` along the horizontal velocity to where the vehicle
        stops (``stopping_distance_m``); at rest the one point under it (the n columns
        would be the same column)."""
        p = np.asarray(p_enu_m, float)
        vh = np.asarray(v_enu_m_s, float)[:2]
        sp = float(np.hypot(*vh))
        if sp <= REST_M_S:
            return p[None, :2].copy()
        s = stopping_distance_m(sp, self.cfg.accel_m_s2, self.cfg.delay_s)
        return p[:2] + np.linspace(0.0, s, n)[:, None] * (vh / sp)

    def check_landing(self, p_enu_m, v_enu_m_s) -> Verdict:
        """May the vehicle land from ``p`` (moving at ``v``)? Every point of the columns
        under its braking footprint, from its height down to the ground (the sphere's
        centre at R above it), keeps the clearance of the rows and the obstacles."""
        p = np.asarray(p_enu_m, float)
        xy = self.braking_footprint(p, v_enu_m_s)
        ground = self.scene.terrain.z(xy[:, 0], xy[:, 1])
        R = self.cfg.airframe_radius_m
        top = max(float(p[2]), float(ground.max()) + R)
        zs = np.arange(top, float(ground.min()) + R - 1e-9, -COLUMN_STEP_M)
        pts = np.array([(x, y, z) for (x, y), g in zip(xy, ground) for z in zs if z >= g + R - 1e-9]).reshape(-1, 3)
        d = self.distances(pts, terrain=False)
        for kind in ("row", "obstacle"):
            bad = d[kind] < self._req[kind]
            if bad.any():
                k = int(np.argmin(d[kind]))
                q = tuple(float(c) for c in pts[k])
                return Verdict(False, "landing", kind,
                               f"landing refused: {kind} {d[kind][k]:.2f} m from the descent at z={q[2]:.2f} m "
                               f"(keep {self._req[kind]:.2f} m)", None, q, float(d[kind][k]), self._req[kind])
        return PASS
