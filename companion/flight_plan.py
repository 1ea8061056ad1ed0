"""What a flight flies: ``FlightPlan`` (the runner's view of a plan, ENU map
frame) and the transformations of one before flight (a sortie's own LQR
trajectory, a uniform slow-down, the sensor coverage gate).

Shared by ``companion fly``, ``companion replay`` and the campaigns (kept out
of ``companion.commands`` so that nothing below the commands imports them).
numpy and the LQR solver are imported on first use: ``companion fly --plan``
starts without them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass


@dataclass(frozen=True, eq=False)
class FlightPlan:
    """What the runner needs from a plan (ENU, map frame)."""

    trajectory: object
    waypoints_p_enu_m: np.ndarray
    target_enu_m: np.ndarray
    coverage_fraction: float | None
    waypoints_t_s: np.ndarray | None = None
    waypoints_v_enu_m_s: np.ndarray | None = None
    waypoints_a_enu_m_s2: np.ndarray | None = None
    path_xy_m: np.ndarray | None = None
    waypoints_corner: np.ndarray | None = None
    main_segments_xy: np.ndarray | None = None
    #: Where it comes from, for the preflight check's messages (plan file, mission, option).
    source: str = ""
    #: SHA-256 (hex) of the plan.json it was read from (``PlanFile.sha256_hex``), for the
    #: flight's setup record; None when planned here, or unknown.
    plan_sha256_hex: str | None = None

    @classmethod
    def from_plan(cls, plan, source: str = "") -> "FlightPlan":
        """From a ``companion.planner.Plan``."""
        import numpy as np

        w = plan.waypoints
        return cls(plan.trajectory, np.asarray(w.p_enu_m, dtype=float), np.asarray(plan.target_enu_m, dtype=float),
                   float(plan.stats.coverage_fraction), np.asarray(w.t_s, dtype=float),
                   np.asarray(w.v_enu_m_s, dtype=float), np.asarray(w.a_enu_m_s2, dtype=float),
                   np.asarray(plan.coverage.path_xy_m, dtype=float), np.asarray(w.corner, dtype=bool),
                   np.asarray([[a, b] for a, b in plan.coverage.main_segments], dtype=float).reshape(-1, 2, 2),
                   source)

    def cut(self, cut_s: float, config) -> "FlightPlan":
        """The way-points up to the first one at or after ``cut_s`` seconds
        (so the flight lasts at least ``cut_s``), the last made a stop (v = a = 0), and the LQR trajectory re-solved through
        them with ``config`` (TrajectoryConfig): a short mission that ends at
        rest instead of a reference that halts at cruise speed."""
        import numpy as np

        from .trajectory import generate_trajectory

        t = self.waypoints_t_s
        n = min(len(t), max(2, int(np.searchsorted(t, t[0] + cut_s, side="left")) + 1))
        t = t[:n].copy()
        p = self.waypoints_p_enu_m[:n]
        v = self.waypoints_v_enu_m_s[:n].copy()
        a = self.waypoints_a_enu_m_s2[:n].copy()
        speed = float(np.linalg.norm(v[-1]))
        if speed > 0.0:
            # The new stop ends a run: its piece also has to ramp down, which
            # ``companion.coverage.extract_waypoints`` pays for with half a
            # smooth ramp, t_acc / 2 = 0.5 * 1.875 V / a_ref (a_ref = 0.5 m/s^2).
            t[-1] += 0.5 * 1.875 * speed / 0.5
        v[-1] = 0.0
        a[-1] = 0.0
        traj = generate_trajectory(t, p, v, a, config, target_enu_m=self.target_enu_m)
        corner = None
        if self.waypoints_corner is not None:
            corner = self.waypoints_corner[:n].copy()
            corner[-1] = True
        # The coverage stays the whole plan's: the report's flown coverage is
        # then the part of it this shorter flight covered. The replanner takes
        # the cut's legs as its coverage segments.
        return FlightPlan(traj, p, self.target_enu_m, self.coverage_fraction, t, v, a, self.path_xy_m, corner,
                          source=f"{self.source} --cut {cut_s:g}".strip())


def slowed_flight_plan(fp: FlightPlan, k: float) -> FlightPlan:
    """``fp`` flown k >= 1 times slower: t -> t0 + k (t - t0), so speeds are
    divided by k and accelerations by k^2 (the pieces' polynomials are in the
    normalised time of each piece: only the knot times change)."""
    import numpy as np

    from .trajectory import Trajectory

    tr = fp.trajectory
    t0 = float(tr.t0)
    scale = np.array([1.0, 1.0 / k, 1.0 / (k * k)])[None, :, None]
    traj = Trajectory.from_pieces(t0 + k * (tr.knot_times_s - t0), tr.position_coefficients, tr.waypoint_knots,
                                  tr.waypoint_targets * scale, tr.config, tr.target_enu_m)
    wt = None if fp.waypoints_t_s is None else t0 + k * (fp.waypoints_t_s - t0)
    wv = None if fp.waypoints_v_enu_m_s is None else fp.waypoints_v_enu_m_s / k
    wa = None if fp.waypoints_a_enu_m_s2 is None else fp.waypoints_a_enu_m_s2 / (k * k)
    return dataclasses.replace(fp, trajectory=traj, waypoints_t_s=wt, waypoints_v_enu_m_s=wv,
                               waypoints_a_enu_m_s2=wa)


def sensor_coverage_gate(mission, fp: FlightPlan, mode: str, dem=None) -> tuple[FlightPlan, dict]:
    """The pre-flight sensor coverage check (``companion.replan.coverage_check``).

    ``dem``: the mission's elevation model (read here when not given).
    Returns the plan to fly (``fp``, or with ``mode`` "slow" and short gaps
    only, ``fp`` slowed uniformly so that none is left) and report.json's
    ``sensor_coverage`` (``slowed_mission`` applies its ``time_scale`` to the
    replanner's own speed limit). Raises ``PlanError`` naming the first gap when
    ``mode`` is "refuse", or when a gap is blind. Without the replanner
    (``replan.enabled: false``) nothing reads the rangefinders: not checked.
    """
    from mavcore.errors import PlanError
    from .replan.coverage_check import mission_coverage
    from .replan.replanner import mission_replan_config

    if not mission.replan.enabled:
        return fp, {"mode": mode, "checked": False, "gaps": [], "time_scale": 1.0}
    radius = float(mission_replan_config(mission).body_radius_m)
    if dem is None:
        from mavcore.maps.field import load_mission_dem

        dem = load_mission_dem(mission)
    cov = mission_coverage(mission, fp.trajectory, radius, dem)
    doc = {"mode": mode, "checked": True, "gaps": [g.to_dict() for g in cov.gaps], "time_scale": 1.0}
    if not cov.gaps:
        return fp, doc
    more = f" (and {len(cov.gaps) - 1} more)" if len(cov.gaps) > 1 else ""
    source = fp.source or str(mission.source)
    if mode == "refuse" or cov.blind:
        first = next(g for g in cov.gaps if g.kind == "blind") if cov.blind else cov.gaps[0]
        hint = ("; no speed makes it safe" if first.kind == "blind" else "; --sensor-gap slow flies it slower")
        raise PlanError(source, f"{first.describe()}{more}{hint}")
    k = float(cov.time_scale)
    slow = slowed_flight_plan(fp, k)
    again = mission_coverage(mission, slow.trajectory, radius, dem)
    if again.gaps:   # sampling between the samples of the first check
        k *= again.time_scale
        slow = slowed_flight_plan(fp, k)
    doc["time_scale"] = k
    return slow, doc


def slowed_mission(mission, time_scale: float):
    """``mission`` with the avoidance speed limit (``replan.speed_m_s``, else
    ``flight.speed_m_s``) divided by ``time_scale`` (itself when 1): a
    trajectory slowed for its sensors is not avoided faster than it is flown."""
    if time_scale <= 1.0:
        return mission
    rp = mission.replan
    speed = rp.speed_m_s if rp.speed_m_s is not None else mission.flight.speed_m_s
    return dataclasses.replace(mission, replan=dataclasses.replace(rp, speed_m_s=float(speed) / time_scale))


def sortie_flight_plan(t_s, p_enu_m, v_enu_m_s, a_enu_m_s2, target_enu_m, config,
                       path_xy_m=None, corner=None, source: str = "") -> FlightPlan:
    """The FlightPlan of one sortie's way-points (ENU map frame): the LQR trajectory
    through them with the mission's weights; the runner flies it like a whole plan."""
    import numpy as np

    from .trajectory import generate_trajectory

    t, p, v, a = (np.asarray(x, dtype=float) for x in (t_s, p_enu_m, v_enu_m_s, a_enu_m_s2))
    traj = generate_trajectory(t, p, v, a, config, target_enu_m=target_enu_m)
    return FlightPlan(traj, p, np.asarray(target_enu_m, dtype=float), None, t, v, a,
                      None if path_xy_m is None else np.asarray(path_xy_m, dtype=float),
                      None if corner is None else np.asarray(corner, dtype=bool), source=source)
