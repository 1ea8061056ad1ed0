"""The plan the replanner follows and re-plans: trajectory, way-points, coverage segments.

Times are the plan's clock (the first way-point at the trajectory's t0; the
replanner maps vehicle time onto it when the trajectory phase starts).
Every turning point of the coverage path is a corner way-point, so the legs
of the path are the pieces between consecutive corner way-points; the
"next turning point" of Fig. 5 is the end corner of the current leg.

``segments`` are the coverage's main segments (the runs that cover the
corridors) still to fly, in flight order, each with the way-points at its
two ends; a re-route uses them to know what is left to cover.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mavcore.mission.schema import FlightConfig
from ..trajectory import Trajectory
from mavcore.mission.trajectory import TrajectoryConfig

#: An end of a main segment matches a corner way-point within this distance (m).
_MATCH_TOL_M = 0.05
#: Legs this close (m) to the nearest are tied (at a turn, the direction decides).
_LEG_TIE_M = 0.3
#: Turning points closer than this (m) to the previous one do not start a leg.
_MIN_LEG_M = 0.5


@dataclass(frozen=True)
class Segment:
    """A main segment still to cover (ENU m), flown from ``start_xy`` to ``end_xy``.

    ``first_wp`` and ``last_wp`` index the way-points at its two ends (the
    plan's arrays); ``first_wp`` may be 0 for a segment entered before the
    plan began (a re-solved plan that starts inside it).
    """

    start_xy: tuple[float, float]
    end_xy: tuple[float, float]
    first_wp: int
    last_wp: int

    @property
    def length_m(self) -> float:
        return float(np.hypot(self.end_xy[0] - self.start_xy[0], self.end_xy[1] - self.start_xy[1]))


@dataclass(frozen=True, eq=False)
class GlobalPlan:
    """The trajectory being followed and what is needed to re-plan it.

    Attributes
    ----------
    trajectory : Trajectory
        LQR trajectory (plan clock, ENU).
    t_s : (N,) way-point times (s, plan clock).
    p_enu_m, v_enu_m_s, a_enu_m_s2 : (N, 3) way-point constraints.
    corner : (N,) bool, turning points.
    segments : tuple of Segment
        Main segments not yet finished when the plan was made, in flight order.
    target_enu_m : (3,) array or None
        Pointing target S_p.
    flight : FlightConfig
        Height above the terrain, speed and way-point interval (re-routes).
    trajectory_config : TrajectoryConfig
        LQR weights (re-solves).
    min_segment_m : float
        Shortest main segment worth flying (the coverage setting).
    final_xy : (2,) the end of the whole coverage path (ENU m).
    turns_enu_m : (K, 3) array
        The turning points of the path being flown (ENU m): the legs between
        them are the corridors' lines the avoidance keeps to. A rejoined plan
        keeps its parent's (its first way-point, the state it starts from,
        is not a turning point of the path).
    new_until_s : float or None
        A rejoined plan is new up to this time (plan clock) and flies its parent's
        trajectory, to within ``rejoin.CONVERGED_M``, after it: the guard checks it up to
        here (``rejoin.converged_from``). None: the whole plan is new.
    """

    trajectory: Trajectory
    t_s: np.ndarray
    p_enu_m: np.ndarray
    v_enu_m_s: np.ndarray
    a_enu_m_s2: np.ndarray
    corner: np.ndarray
    segments: tuple[Segment, ...]
    target_enu_m: np.ndarray | None
    flight: FlightConfig
    trajectory_config: TrajectoryConfig
    min_segment_m: float
    final_xy: tuple[float, float]
    turns_enu_m: np.ndarray
    new_until_s: float | None = None

    @classmethod
    def from_plan(cls, plan, mission) -> "GlobalPlan":
        """From ``companion.planner.plan_mission``'s ``Plan`` and its ``Mission``."""
        wp = plan.waypoints
        segs = np.asarray([[a, b] for a, b in plan.coverage.main_segments], dtype=float).reshape(-1, 2, 2)
        path = np.asarray(plan.coverage.path_xy_m, dtype=float)
        return cls.from_waypoints(plan.trajectory, wp.t_s, wp.p_enu_m, wp.v_enu_m_s, wp.a_enu_m_s2,
                                  wp.corner, segs, plan.target_enu_m, mission.flight, mission.trajectory,
                                  mission.coverage.min_segment_m, tuple(path[-1]))

    @classmethod
    def from_waypoints(cls, trajectory, t_s, p_enu_m, v_enu_m_s, a_enu_m_s2, corner, segments_xy,
                       target_enu_m, flight, trajectory_config, min_segment_m, final_xy=None) -> "GlobalPlan":
        """Assemble a plan; ``segments_xy`` (k, 2, 2) main segments in flight order
        (each [start, end], ENU m) are matched to the way-points at their ends.

        ``segments_xy`` None (a plan read from plan.json, which has no main
        segments): every leg between turning points at least ``min_segment_m``
        long counts as coverage. ``final_xy`` None: the last way-point.
        """
        p = np.asarray(p_enu_m, dtype=float)
        corner = np.asarray(corner, dtype=bool)
        if segments_xy is None:
            segments_xy = legs_as_segments(p[:, :2], corner, float(min_segment_m))
        if final_xy is None:
            final_xy = p[-1, :2]
        segs = match_segments(np.asarray(segments_xy, dtype=float).reshape(-1, 2, 2), p[:, :2], corner)
        turns = merge_turns(p[np.union1d(np.flatnonzero(corner), [0, len(p) - 1])])
        return cls(trajectory, np.asarray(t_s, dtype=float), p, np.asarray(v_enu_m_s, dtype=float),
                   np.asarray(a_enu_m_s2, dtype=float), corner, segs,
                   None if target_enu_m is None else np.asarray(target_enu_m, dtype=float),
                   flight, trajectory_config, float(min_segment_m),
                   (float(final_xy[0]), float(final_xy[1])), turns)

    def leg_frame(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Leg k (clamped): start and end turning points (3,), the horizontal unit
        vector along it and the one to its left (2,), ENU."""
        k = min(max(int(k), 0), len(self.turns_enu_m) - 2)
        A, B = self.turns_enu_m[k], self.turns_enu_m[k + 1]
        d = B[:2] - A[:2]
        n = float(np.hypot(*d))
        u = d / n if n > 1e-9 else np.array([1.0, 0.0])
        return A, B, u, np.array([-u[1], u[0]])

    def leg_near(self, p_enu_m, direction_xy=None) -> int:
        """Index of the leg nearest (horizontally) to ``p_enu_m``; among legs within
        ``_LEG_TIE_M`` of the nearest, the one most along ``direction_xy`` (at a turn)."""
        T = self.turns_enu_m[:, :2]
        if len(T) < 2:
            return 0
        a, b = T[:-1], T[1:]
        ab = b - a
        L2 = np.maximum(np.einsum("ki,ki->k", ab, ab), 1e-18)
        q = np.asarray(p_enu_m, dtype=float)[:2]
        s = np.clip(((q - a) * ab).sum(axis=1) / L2, 0.0, 1.0)
        d = np.hypot(*(a + s[:, None] * ab - q).T)
        near = np.flatnonzero(d <= d.min() + _LEG_TIE_M)
        if direction_xy is None or len(near) == 1:
            return int(near[0])
        u = ab[near] / np.sqrt(L2[near])[:, None]
        return int(near[np.argmax(u @ np.asarray(direction_xy, dtype=float))])

    def waypoint_index_at(self, t_s: float) -> int:
        """Index of the last way-point whose time is <= ``t_s`` (plan clock; 0 before the start)."""
        return max(0, int(np.searchsorted(self.t_s, t_s, side="right")) - 1)

    def segment_at(self, wp_index: int) -> tuple[int | None, int]:
        """(index of the segment being flown after way-point ``wp_index`` or None,
        index of the first segment not yet started)."""
        current = None
        nxt = len(self.segments)
        for i, s in enumerate(self.segments):
            if s.first_wp <= wp_index < s.last_wp:
                current = i
            if s.first_wp > wp_index:
                nxt = i
                break
        return current, nxt


def match_segments(segments_xy: np.ndarray, wp_xy: np.ndarray, corner: np.ndarray) -> tuple[Segment, ...]:
    """Way-points at the ends of each main segment (flight order, monotone).

    Each end is the first corner way-point (from the previous match on)
    within ``_MATCH_TOL_M``; failing that (a segment end the path planner
    merged into a straight continuation), the nearest way-point from the
    previous match on.
    """
    out = []
    cursor = 0
    n = len(wp_xy)
    for a, b in segments_xy:
        ends = []
        for q in (a, b):
            d = np.hypot(*(wp_xy[cursor:] - q).T)
            hits = np.flatnonzero(corner[cursor:] & (d <= _MATCH_TOL_M))
            k = cursor + (int(hits[0]) if len(hits) else int(np.argmin(d)))
            ends.append(k)
            cursor = min(k, n - 1)
        out.append(Segment((float(a[0]), float(a[1])), (float(b[0]), float(b[1])), ends[0], ends[1]))
    return tuple(out)


def merge_turns(turns: np.ndarray, min_leg_m: float = _MIN_LEG_M) -> np.ndarray:
    """The turning points without those closer than ``min_leg_m`` (horizontally) to
    the previous one kept (the last is always kept, replacing a too-near one):
    a leg a few centimetres long (a re-route's back-off, a grid path's step)
    has no direction to keep to."""
    out = [turns[0]]
    for q in turns[1:]:
        if np.hypot(*(q[:2] - out[-1][:2])) >= min_leg_m:
            out.append(q)
    if len(turns) > 1 and not np.array_equal(out[-1], turns[-1]):
        if len(out) > 1 and np.hypot(*(turns[-1][:2] - out[-1][:2])) < min_leg_m:
            out[-1] = turns[-1]
        else:
            out.append(turns[-1])
    return np.array(out).reshape(-1, 3)


def legs_as_segments(wp_xy: np.ndarray, corner: np.ndarray, min_length_m: float) -> np.ndarray:
    """(k, 2, 2) the legs between consecutive turning points at least ``min_length_m`` long."""
    idx = np.flatnonzero(corner)
    out = [(wp_xy[a], wp_xy[b]) for a, b in zip(idx[:-1], idx[1:])
           if np.hypot(*(wp_xy[b] - wp_xy[a])) >= min_length_m]
    return np.array(out, dtype=float).reshape(-1, 2, 2)
