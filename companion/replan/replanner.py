"""The replanner's state machine (paper Fig. 5, issue 8): follow the plan while
clear, follow the improved APF while an unknown obstacle is within range,
climb over it or stop and re-route, rejoin without a jump.

Modes (``ReplanStep.mode``)

``follow``  the plan's trajectory, evaluated by a forward cursor (no cache).
            An unknown obstacle point within the trigger range (d_o, or the
            braking distance plus the clearance if longer) and not behind
            the vehicle starts ``avoid`` from the current reference state.
``avoid``   the improved APF (eqs. 14-19), start = the reference where the
            obstacle was detected, goal = the end of the current leg (the
            next turning point, Fig. 5), obstacles = the remembered points
            within d_o (one per cluster, ``CLUSTER_M``). Its force sets a
            velocity command, the gradient flow F / (k_att ``FLOW_TIME_S``)
            (it slows where the forces balance), which is constrained and
            shaped (``shaper``) into p, v, a, jerk, snap:

            - speed: the plan's (or ``speed_m_s``) horizontally,
              ``vertical_speed_m_s`` vertically;

            - corridor: the lateral offset from the leg's line stays within
              ``lateral_limit_m`` (soft walls, the rows are walls);
            - height: between ``floor_agl_m`` and ``ceiling_agl_m`` above the terrain;
            - clearance governor (our addition, see below): the speed v
              toward any remembered point d away satisfies v^2 / (2 a_b) +
              v ``GOVERNOR_LAG_S`` <= d - clearance - ``GOVERNOR_MARGIN_M``,
              a_b = ``accel_m_s2`` / 2, so the shaped reference can always
              brake before the clearance;
            - no data, no go (PX4's CP_GO_NO_DATA = 0, ``nodata``): with the
              governor on, a horizontal direction that no rangefinder has
              reported on within ``nodata.NO_DATA_TIMEOUT_S`` is blocked;
              the command keeps only its vertical part.
``climb``   the vertical escape (Fig. 19: "the obstacle avoidance was
            performed vertically"), the same APF with virtual goals. When no
            lateral gap of the corridor lets the vehicle pass an obstacle
            ahead at its height with the clearance, or when the APF makes no
            progress along the leg for ``stall_s`` (a local minimum, or an
            oscillation), the pass height is the top of the obstacle points
            ahead plus the clearance and margins (``PASS_MARGIN_M``), at most
            the ceiling; it grows with the points seen while rising. *Rise*:
            the goal is the pass height above the point of the leg's line
            where the escape began. *Over*: once the way ahead is clear at that height, the
            goal is on the leg's line at the pass height, d_o beyond the
            farthest obstacle point seen (a goal this near keeps the
            improved repulsion, scaled by the goal distance squared, from
            pushing the vehicle far above the obstacle).
``stop``    when the obstacle's top (plus margins) is above the ceiling, or
            the escape did not pass the obstacle within
            ``escape_timeout_s``: the velocity command is zero until the
            reference is at rest (the governor's braking law left the room
            for it), then ``reroute`` (``STOP_THEN``).
``reroute`` after a stop (a tall obstacle, or an escape that timed out),
            ``reroute.reroute`` re-plans the remaining coverage from the current
            state; this mode lasts until the new plan's second way-point, then
            ``follow``.
``rejoin``  when no remembered point within d_o is ahead of (or beside)
            the vehicle, the LQR is re-solved from the reference state
            through the way-points still ahead (``rejoin.rejoin``, checked
            for jerk and clearance; retried every ``REJOIN_RETRY_S``); this
            mode lasts until its first way-point, then ``follow``.
``hold``    only when the re-route after a stop finds no route (or the guard
            refuses it): hold the position and report (``ReplanStep.hold``),
            the event's detail adding the independent route check's verdict
            (``_hold``, the one way into this mode).
``done``    the (re)planned coverage trajectory reached its end.

Never pressing on: in every mode but ``follow``/``rejoin``/``reroute``
the governor limits the approach speed to every remembered point, and
``follow`` hands over to ``avoid`` with room to brake.

Departures from the paper, each with an ablation in
``tests/test_replan_closedloop.py`` (same flight, one switch): the
clearance governor (``clearance_governor``; the improved APF alone lets a
vehicle whose goal is near an obstacle come within the clearance, since
U_rep -> 0 at the goal); the corridor walls (``lateral_limit_m``; the APF
alone pushes the vehicle toward the rows); the vertical escape
(``vertical_escape``; without it the APF stays in the local minimum in front
of a post across the corridor, Fig. 19 goes over such obstacles without
saying how); the velocity-command shaping (``accel_m_s2``/``jerk_m_s3``;
the paper moves a particle along the force, whose setpoint steps no vehicle
can follow).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, replace

import numpy as np

from mavcore.mission.replan import ReplanConfig
from .brake import BRAKE_DT_S, EMERGENCY_BRAKE_DT_S, brake_states
from ..trajectory.reference import RefSample
from ..trajectory.cursor import TrajectoryCursor
from .apf import ApfParams, apf_force
from .globalplan import GlobalPlan
from .heading_bias import HeadingBias, rotate_evidence
from .knownmap import KNOWN_ADDED, KNOWN_GROUND, UNKNOWN, KnownMap
from .lift import WALL_MARGIN_M as LIFT_WALL_MARGIN_M, Over
from .margin_exit import margin_exit
from .corner import leg_end_wall_m
from .closing import MATCH_M, ClosingSpeed, allowed_approach_m_s, give_way_range_m, give_way_speed_m_s
from .nodata import BeamFreshness, block_no_data
from .pace import pace
from .attitude_wait import AttitudeWait
from .perception import Pose, PoseHistory, attitude_perturbations, beam_evidence, field_sine_range
from .rejoin import converged_from, rejoin
from .repair import MAX_REPAIRS, repair
from .reroute import reroute, with_blocking
from .reroute3d import reroute_3d
from .shaper import EMERGENCY_OMEGA_RAD_S, ReferenceShaper
from .route3d import Route3D, RouteScene, find_route
from .routecheck import route_exists
from .voxmap import L_CANDIDATE, ObstacleMap

MODES = ("follow", "avoid", "climb", "stop", "reroute", "rejoin", "hold", "done")
#: What a ``stop`` hands over to once at rest: the look (give way), or the re-route. Never a
#: bare hold: only a re-route that finds no route holds, with the route check's verdict.
STOP_THEN = ("look", "reroute")
#: Event actions (``ReplanEvent.action``); ``skip``: coverage of the plan left out (``coverage_skipped``).
ACTIONS = ("avoid", "climb", "stop", "reroute", "rejoin", "hold", "skip")
_FOLLOWING = ("follow", "rejoin", "reroute")

#: The governor keeps the reference this much (m) beyond the clearance while braking.
GOVERNOR_MARGIN_M = 0.1
#: The stopping point of every avoiding reference (``_shape``) keeps this much (m) beyond
#: the guard's clearances: the brake is predicted every ``brake.BRAKE_DT_S``, within
#: 4.5 cm of the frame-stepped brake (``tests/test_replan_brake.py``).
STOP_MARGIN_M = 0.05
#: Closing (m) allowed to a stopping point inside the guard's clearance itself: float noise
#: only. The rule is judged afresh every frame, from where the reference is, so an allowance
#: is a ratchet (5 mm a frame let a climb creep 0.15 m into a row's clearance at 0.02 m/s).
#: Within ``STOP_MARGIN_M`` of the clearance the margin rule's own 5 mm holds (a slow creep
#: there, whose brake is predicted exactly enough, ends at the clearance).
STOP_TOL_M = 1e-6
#: The governor's braking law allows for this lag (s) of the shaped reference: with the
#: default limits (1 m/s^2, 2 m/s^3) the shaper stops from 1 m/s in 0.97 m, from
#: 0.5 m/s in 0.37 m; v^2 / (2 a_b) + v t_lag gives 1.6 m and 0.55 m.
GOVERNOR_LAG_S = 0.6
#: A re-route keeps this much (m) beyond the clearance and body from the obstacle's
#: footprint: the sensors saw one face of it, its sides may reach a little farther.
ROUTE_MARGIN_M = 0.3
#: Margins (m) beyond the clearance and body the 3-D leave's lattice keeps, tried in turn: the
#: route's, the governor's, and last none, the independent route check's own question
#: (``routecheck``), so that the leave finds a route whenever the check does.
LEAVE_MARGINS_M = (ROUTE_MARGIN_M, GOVERNOR_MARGIN_M, 0.0)
#: A route the guard refuses for what its own polyline passes is searched again round the
#: map's voxels within the clearance and body plus this (m) of the refused sample.
CONFLICT_REACH_M = 0.5
#: The ground's slope under an avoiding command is taken over this distance (m) along it.
SLOPE_STEP_M = 0.5
#: Extra height (m) above the top of an obstacle plus the clearance and the governor margin.
PASS_MARGIN_M = 0.1
#: Obstacle points closer than this (m) to a nearer one belong to the same obstacle.
CLUSTER_M = 1.0
#: At most this many obstacles enter the APF sum.
MAX_OBSTACLES = 4
#: The rise of the vertical escape ends within this height (m) of the pass height.
RISE_TOL_M = 0.1
#: A rejoin waits until |a| and |jerk| are within this fraction of their limits (per axis).
CALM_FRACTION = 0.5
#: Time constant of the gradient flow (s): the velocity command is F / (k_att T), so
#: the attraction alone closes on the goal at 1/T of the distance per second.
FLOW_TIME_S = 1.0
#: The rejoin waits until no point is within the trigger range plus this (m).
REJOIN_HYSTERESIS_M = 0.3
#: A rejoin that fails its checks is tried again after this long (s).
REJOIN_RETRY_S = 0.25
#: The shaper leaves the emergency limits only when the normal brake keeps this much (m) more
#: than the stopping point's margin (``Replanner._shape``): hysteresis.
EMERGENCY_EXIT_MARGIN_M = 0.1
#: A rejoin is admitted only if the follow mode's own trigger (``_threat``) stays quiet along
#: its first this many seconds (s), sampled every ``REJOIN_CHECK_DT_S``
#: (``Replanner._retriggers``).
REJOIN_QUIET_S, REJOIN_CHECK_DT_S = 1.0, 0.1
#: Soft-wall gain (1/s): the speed toward a wall is at most this times the distance left.
WALL_GAIN_1_S = 2.0
#: A mover measured less than this far (m) along the corridor from the vehicle (or its return's
#: spread, if more) does not choose the side a give-way backs away to (``_give_way_side``).
MOVER_GAP_MIN_M = 0.1
#: The lateral wall sits this far (m) inside ``lateral_limit_m`` (the shaper's lag).
WALL_MARGIN_M = 0.1
#: Progress along the leg smaller than this (m) does not count (stall detection).
PROGRESS_M = 0.05
#: Points with a beam this much (m) short of their return are cleared by it.
CLEAR_MARGIN_M = 0.15
#: Within this distance (m) of the leg's end corner the APF goal moves to the next one.
GOAL_REACHED_M = 0.3
#: The reference is at rest below these speed (m/s) and acceleration (m/s^2).
REST_V_M_S, REST_A_M_S2 = 0.02, 0.05
#: With ``give_way`` the vehicle stops at a new unknown obstacle and watches it this
#: long (s, at rest) before it avoids it as a still one (``_look``): a worker crossing
#: the corridor is read as moving only while the beams do not sweep
#: (``closing``: ``still``). Four baselines of the closing-speed rule.
LOOK_S = 4.0 * 0.3
#: The vehicle is still (its beams do not sweep) below this measured speed (m/s): over
#: the closing rule's longest baseline (0.6 s) it moves 0.06 m, a sweep of 0.1 m/s,
#: a third of the slowest speed the rule reads as a mover (0.3 m/s).
STILL_M_S = 0.1
#: Propeller radius (m) added to the arm length for the body radius when the mission gives none.
PROP_RADIUS_M = 0.127
#: While an avoiding reference passes over a remembered point (horizontally within the
#: clearance, the body, the governor margin and this lag's travel) it does not come
#: down: the beams see a low obstacle's sides below its top, so the top may stand
#: higher than every point remembered (0.24 m in randomized SITL flight 37, passed
#: at 0.35 m while the APF's goal pulled the reference down toward the plan height).
HOLD_HEIGHT_LAG_S = 1.0
#: Events kept in the statistics (the count goes on).
MAX_EVENTS_KEPT = 1000
#: A rejoin that leaves out more plan than this (m) beyond what its chord covers reports it.
SKIP_REPORT_M = 1.0
#: A hold's route check looks for the coverage ends this near (m) ...
ROUTE_CHECK_RADIUS_M = 15.0
#: ... at most this many, nearest first.
ROUTE_CHECK_GOALS = 6
#: A corner way-point matches a leg's turning point within this distance (m).
CORNER_MATCH_M = 0.05


@dataclass(frozen=True, slots=True)
class ReplanEvent:
    """A replanning event.

    Attributes
    ----------
    t_s : float
        Vehicle time (s).
    pos_enu_m : 3-tuple
        Vehicle position (the estimate passed to ``step``; ENU m).
    obstacle_range_m : float or None
        Distance from the reference to the nearest remembered obstacle point (m).
    action : str
        ``avoid``, ``climb``, ``stop``, ``reroute``, ``rejoin`` or ``hold``.
    detail : str
        Why, in a few words.
    """

    t_s: float
    pos_enu_m: tuple
    obstacle_range_m: float | None
    action: str
    detail: str = ""


@dataclass(frozen=True, slots=True)
class ReplanStep:
    """What the replanner answers every frame.

    Attributes
    ----------
    ref : RefSample
        The reference to fly this frame (ENU).
    mode : str
        One of ``MODES``.
    finished : bool
        The coverage trajectory, however replanned, has reached its end.
    hold : bool
        No route: the vehicle holds; land and report.
    events : tuple of ReplanEvent
        Events of this step.
    """

    ref: RefSample
    mode: str
    finished: bool
    hold: bool
    events: tuple


@dataclass(frozen=True)
class ReplanStats:
    """Summary for report.json ``replanning``.

    Attributes
    ----------
    events : int
        Number of events.
    event_list : tuple of ReplanEvent
        The first ``MAX_EVENTS_KEPT`` events.
    max_lateral_deviation_m : float
        Largest horizontal distance from the reference to the leg being
        avoided (or the one before it, after a turn), while avoiding and
        rejoining (m).
    extra_path_m : float
        Length of the flown reference minus the planned trajectory's length (m).
    max_climb_m : float
        Largest height of the reference above the planned flight height while
        avoiding and rejoining (m).
    min_obstacle_range_m : float or None
        Smallest distance from the reference to a remembered obstacle point (m).
    readings, unknown_hits, ignored_readings : int
        DISTANCE_SENSOR readings handled, returns classified unknown, readings without evidence.
    coverage_skipped : tuple of (from_s, to_s, length_m, reason)
        Plan left out by rejoins and re-routes (plan-clock times, s; m).
    max_height_agl_m : float or None
        Largest height of the reference above the terrain under it while avoiding
        and rejoining (m; None when it never did): the height band's ceiling is
        ``ceiling_agl_m``.
    ceiling_agl_m : float
        The avoiding modes' ceiling above the terrain (m, ``replan.ceiling_agl_m``).
    """

    events: int
    event_list: tuple
    max_lateral_deviation_m: float
    extra_path_m: float
    max_climb_m: float
    min_obstacle_range_m: float | None
    readings: int
    unknown_hits: int
    ignored_readings: int
    coverage_skipped: tuple = ()
    max_height_agl_m: float | None = None
    ceiling_agl_m: float = math.inf

    def to_dict(self) -> dict:
        """Plain JSON types (report.json ``replanning``; events as {t_s, pos_enu_m, obstacle_range_m, action, detail})."""
        def num(x):
            return None if x is None else float(x)
        return {
            "events": int(self.events),
            "event_list": [{"t_s": float(e.t_s), "pos_enu_m": [float(c) for c in e.pos_enu_m],
                            "obstacle_range_m": num(e.obstacle_range_m), "action": e.action, "detail": e.detail}
                           for e in self.event_list],
            "max_lateral_deviation_m": float(self.max_lateral_deviation_m),
            "extra_path_m": float(self.extra_path_m),
            "max_climb_m": float(self.max_climb_m),
            "min_obstacle_range_m": num(self.min_obstacle_range_m),
            "readings": int(self.readings),
            "unknown_hits": int(self.unknown_hits),
            "ignored_readings": int(self.ignored_readings),
            "coverage_skipped": [{"from_s": float(a), "to_s": float(b), "length_m": float(L), "reason": r}
                                 for a, b, L, r in self.coverage_skipped],
            "max_height_agl_m": num(self.max_height_agl_m),
            "ceiling_agl_m": float(self.ceiling_agl_m),
        }


def _pointing(p, target) -> tuple:
    if target is None:
        return (0.0, 1.0, 0.0)
    u = (target[0] - p[0], target[1] - p[1], target[2] - p[2])
    n = math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
    return (0.0, 1.0, 0.0) if n < 1e-9 else (u[0] / n, u[1] / n, u[2] / n)


def _segment_distance(p, a, b, before: bool = False, beyond: bool = False) -> float:
    """Horizontal distance (m) from the point p to the segment a-b (ENU xy); ``before`` /
    ``beyond``: the segment runs on past a / past b (a ray or a line)."""
    ax, ay = float(a[0]), float(a[1])
    dx, dy = float(b[0]) - ax, float(b[1]) - ay
    L2 = dx * dx + dy * dy
    t = 0.0 if L2 <= 0.0 else ((p[0] - ax) * dx + (p[1] - ay) * dy) / L2
    if not before:
        t = max(t, 0.0)
    if not beyond:
        t = min(t, 1.0)
    return math.hypot(p[0] - ax - t * dx, p[1] - ay - t * dy)


def lateral_offset(p, legs, avoided: int = 0) -> float:
    """Horizontal offset (m) of p across a path of legs ((a, b), ...; ENU xy): the
    distance to the nearest leg, the first one and the ``avoided`` one (the leg the
    avoidance is on) running on behind their starts and the last one on past its end.
    Backing along the path (a stop that gives way keeps its distance by reversing down
    the corridor, past the corner its leg began at) is not a lateral deviation; leaving
    the line is."""
    n = len(legs)
    return min(_segment_distance(p, a, b, before=(i == 0 or i == avoided), beyond=(i == n - 1))
               for i, (a, b) in enumerate(legs))


def lateral_gap(lat_m: np.ndarray, half_width_m: float, clearance_m: float, min_gap_m: float = 0.02) -> bool:
    """True if some lateral position in [-half_width, half_width] keeps ``clearance_m``
    from every obstacle offset in ``lat_m`` (a gap of at least ``min_gap_m``)."""
    lat = np.sort(np.asarray(lat_m, dtype=float))
    lo, hi = lat - clearance_m, lat + clearance_m
    cur = -half_width_m
    for s, e in zip(lo.tolist(), hi.tolist()):
        if s - cur > min_gap_m:
            return True
        cur = max(cur, e)
        if cur >= half_width_m:
            return False
    return half_width_m - cur > min_gap_m


def cluster_nearest(points: np.ndarray, dist: np.ndarray, merge_m: float, k_max: int) -> np.ndarray:
    """Up to ``k_max`` points, one per cluster: repeatedly the nearest point left,
    then drop every point within ``merge_m`` of it. ``dist``: the points' distances."""
    order = np.argsort(dist)
    pts = points[order]
    out = []
    alive = np.ones(len(pts), dtype=bool)
    for i in range(len(pts)):
        if not alive[i]:
            continue
        out.append(pts[i])
        if len(out) == k_max:
            break
        d = pts - pts[i]
        alive &= np.einsum("ki,ki->k", d, d) > merge_m * merge_m
    return np.array(out).reshape(-1, 3)


def path_length_m(trajectory, dt_s: float = 0.05, chunk: int = 20000) -> float:
    """Length (m) of a trajectory's path sampled every ``dt_s``, in chunks of ``chunk``
    samples (an 11 h plan is 800,000 samples: sampled at once, a 100 MB peak)."""
    t0, tf = float(trajectory.t0), float(trajectory.tf)
    n = int(math.floor((tf - t0) / dt_s)) + 1
    total, prev = 0.0, None
    for k in range(0, n, chunk):
        t = t0 + dt_s * np.arange(k, min(k + chunk, n))
        if k + chunk >= n:
            t = np.append(t, tf)
        p = trajectory.derivatives(t)[:, 0, :]      # positions only: sample(t).p without the pointing
        if prev is not None:
            p = np.vstack([prev, p])
        total += float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))
        prev = p[-1:]
    return total


def horizontal_clusters(points: np.ndarray, link_m: float) -> np.ndarray:
    """Cluster label of each point (k, 3): single linkage on the horizontal distance
    (points closer than ``link_m`` belong together)."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(points)
    if n == 0:
        return np.zeros(0, dtype=int)
    d = points[:, None, :2] - points[None, :, :2]
    adj = np.einsum("ijk,ijk->ij", d, d) <= link_m * link_m
    return connected_components(csr_matrix(adj), directed=False)[1]


def unpassable_points(points: np.ndarray, ground_z, ceiling_agl_m: float, keep_m: float,
                      link_m: float = CLUSTER_M, confirmed: np.ndarray | None = None) -> np.ndarray:
    """The points of the obstacles (horizontal clusters) the vehicle cannot pass over:
    ``too_tall`` (the cluster's top, from its ``confirmed`` points when it has any).
    A re-route goes round these; a low obstacle near them is climbed over when the
    new route meets it (walling it off too sealed the vehicle into a pocket of the
    free space in the randomized SITL benchmark)."""
    if len(points) == 0:
        return points
    labels = horizontal_clusters(points, link_m)
    keep = np.zeros(len(points), dtype=bool)
    conf = np.ones(len(points), dtype=bool) if confirmed is None else np.asarray(confirmed, dtype=bool)
    for c in np.unique(labels):
        m = labels == c
        sel = m & conf if (m & conf).any() else m
        k = int(np.argmax(np.where(sel, points[:, 2], -np.inf)))
        top = points[k]
        if too_tall(float(top[2]), ground_z(float(top[0]), float(top[1])) + ceiling_agl_m, keep_m):
            keep |= m
    return points[keep]


def too_tall(top_z: float, ceiling_z: float, keep_m: float) -> bool:
    """An obstacle whose top is at ``top_z`` cannot be passed over under ``ceiling_z``:
    at the highest the avoiding reference goes (the ceiling less the wall margin) the
    clearance governor, which keeps ``keep_m`` (airframe radius + clearance) plus
    ``GOVERNOR_MARGIN_M`` from every point, would not let it move over the top. (Judged
    on ``keep_m`` alone, tops within the governor's margin of the limit were climbed
    and then never passed: 20 s over the post, "escape not through", a hold.) No
    margin is stacked on the top estimate itself, and the top comes from returns on
    a beam's axis where there are any (a wide beam's edge candidates read high: the
    upper edge of its field)."""
    return top_z + keep_m + GOVERNOR_MARGIN_M > ceiling_z - WALL_MARGIN_M


def first_waypoint_ahead(plan: GlobalPlan, wp_leave: int, p_enu_m, u_xy, speed_m_s: float,
                         vertical_speed_m_s: float) -> int:
    """The first way-point to rejoin after an avoidance along the leg direction ``u_xy``.

    From the way-point after ``wp_leave`` (the last passed when the avoidance
    began) on: the first turning point still ahead of the reference by more
    than ``GOAL_REACHED_M`` (a turn is never cut; one the avoidance reached,
    its goal, counts as passed), or the first other way-point ahead of it by more than the
    lead: 1 m, 1 s at the plan speed, and the distance flown at that speed
    while coming down (or up) to it at the vertical speed (no turning back to
    reach it). ``u_xy`` is the direction of the leg the avoidance is on
    (it moves to the next leg when the avoidance reaches a turn), so way-points
    behind a turn already passed are measured along the new leg.
    """
    P = np.asarray(p_enu_m, dtype=float)
    n = len(plan.t_s)
    for i in range(wp_leave + 1, n):
        q = plan.p_enu_m[i]
        a_i = float((q[:2] - P[:2]) @ u_xy)
        if plan.corner[i]:
            if a_i > GOAL_REACHED_M:
                return i
            continue                      # a turn reached or passed (the avoidance went round it)
        t_down = 1.875 * abs(float(q[2] - P[2])) / vertical_speed_m_s
        if a_i > max(1.0, speed_m_s, speed_m_s * t_down):
            return i
    return n - 1


def next_corner_visit(plan: GlobalPlan, xy, after: int) -> int:
    """Index of the first corner way-point after ``after`` at ``xy`` (ENU m, within
    ``CORNER_MATCH_M``); ``after`` when there is none. A path may pass the same
    corner twice (a re-route's back-track): the visit that starts a leg the
    avoidance turned onto is the first one after the previous leg's start."""
    q = plan.p_enu_m[after + 1:, :2] - np.asarray(xy, dtype=float)[:2]
    hits = np.flatnonzero(plan.corner[after + 1:] & (np.hypot(q[:, 0], q[:, 1]) < CORNER_MATCH_M))
    return after + 1 + int(hits[0]) if len(hits) else after


def rejoin_skip(plan: GlobalPlan, start: int, first: int, p_enu_m, u_xy) -> tuple[float, float, float] | None:
    """Plan left out by a rejoin through way-point ``first`` of an avoidance on the leg
    (direction ``u_xy``) entered at way-point ``start``: the plan's path from ``start``
    to ``first``, less the avoidance's progress along the leg from ``start`` and the
    rejoin's horizontal chord to ``first`` (what the vehicle covers). Returns (from_s,
    to_s, length_m) on the plan's clock when that exceeds ``SKIP_REPORT_M``, else None."""
    P = np.asarray(p_enu_m, dtype=float)
    xy = plan.p_enu_m[start:first + 1, :2]
    plan_len = float(np.sum(np.hypot(*np.diff(xy, axis=0).T))) if len(xy) > 1 else 0.0
    progress = max(0.0, float((P[:2] - xy[0]) @ np.asarray(u_xy, dtype=float)))
    chord = float(np.hypot(*(plan.p_enu_m[first, :2] - P[:2])))
    left = plan_len - progress - chord
    if left <= SKIP_REPORT_M:
        return None
    return float(plan.t_s[start]), float(plan.t_s[first]), left


def mission_replan_config(mission) -> ReplanConfig:
    """The mission's ``replan`` settings with ``body_radius_m`` filled in from the
    vehicle when unset: the arm length plus ``PROP_RADIUS_M`` (a 10-inch propeller)."""
    cfg = mission.replan
    if cfg.body_radius_m is None:
        cfg = dataclasses.replace(cfg, body_radius_m=float(mission.vehicle.arm_m) + PROP_RADIUS_M)
    return cfg


class Replanner:
    """Obstacle-avoiding reference generator (module doc).

    Parameters
    ----------
    cfg : ReplanConfig
    known : KnownMap
    plan : GlobalPlan

    Call ``start`` once at the start of the trajectory phase, ``on_pose``
    every frame with the estimated pose, ``on_range`` with every decoded
    DISTANCE_SENSOR, then ``step`` every frame.
    """

    def __init__(self, cfg: ReplanConfig, known: KnownMap, plan: GlobalPlan) -> None:
        self.cfg = cfg
        self.known = known
        self.apf = ApfParams(cfg.k_att, cfg.k_rep, cfg.influence_range_m, cfg.n)
        self.speed_m_s = float(cfg.speed_m_s if cfg.speed_m_s is not None else plan.flight.speed_m_s)
        #: distance kept from every obstacle point by the vehicle's centre: the clearance plus the body
        self._keep_m = cfg.clearance_m + (cfg.body_radius_m or 0.0)
        #: the persistent obstacle map (``voxmap``): cleared only by beams, never by time or a re-route
        self.memory = ObstacleMap(cfg.voxel_m, CLEAR_MARGIN_M)
        #: (tilt, heading) tolerances (rad) of the attitude allowance; None when both are 0
        tt, th = math.radians(cfg.tilt_tolerance_deg), math.radians(cfg.heading_tolerance_deg)
        self._allowance = (tt, th) if (tt > 0.0 or th > 0.0) else None
        self._active_key: tuple | None = None
        self._active = np.zeros((0, 3))
        self._known0 = known                   # the map before any re-route added cells to it
        self._active_conf = np.zeros(0, dtype=bool)
        self.poses = PoseHistory()
        self.attitude = AttitudeWait()      # readings wait for the attitude of their time
        self.heading = HeadingBias()
        self.fresh = BeamFreshness()
        self.closing = ClosingSpeed()       # movers: the governor bounds the closing speed
        self.shaper = ReferenceShaper(cfg.accel_m_s2, cfg.jerk_m_s3)
        self._brake = 0.5 * cfg.accel_m_s2
        self._target = None if plan.target_enu_m is None else tuple(float(x) for x in plan.target_enu_m)
        self.mode = "follow"
        self._offset: float | None = None
        self._tau_prev: float | None = None
        self._set_plan(plan)
        self._planned_length = path_length_m(plan.trajectory)
        # statistics
        self._events: list[ReplanEvent] = []
        self._n_events = 0
        self._flown = 0.0
        self._p_prev: tuple | None = None
        self._max_lat = 0.0
        #: The side (+1 / -1 along the corridor) a stop gives way to a crossing mover (``_give_way``).
        self._give_way_sign: float | None = None
        self._fleeing = False                     # a stop backs away from a mover at full speed
        self._max_agl: float | None = None
        self._min_range: float | None = None
        self.n_readings = self.n_unknown = self.n_ignored = 0
        self._skipped: list[tuple] = []
        # avoidance context
        self._static: RefSample | None = None
        self._mode_until = -math.inf
        self._stop_then = ""
        self._look_since: float | None = None     # the look's rest began (tau); None: not at rest
        self._still = False                       # the reference is at rest and the vehicle still
        self._vel = (0.0, 0.0, 0.0)
        self._next_rejoin = -math.inf
        self._dev_leg: tuple | None = None
        self._dev_avoided = 0                     # index in ``_dev_leg`` of the avoided leg
        #: frames whose command ``_shape`` cut so that the reference's stopping point keeps clear
        self.n_stop_limited = 0
        #: the shaper brakes at the emergency limits (``_shape``; docs/replan.md "The emergency brake")
        self.emergency = False
        self.n_emergency_brakes = 0
        self._emergency_why = ""
        self._evading = False                     # a stop gives way to a mover coming closer
        #: the start (vehicle time s) of the run of failing samples the gate is judging, as
        #: ``_shape`` predicts it from what it commits; None: the last one passed
        self._gate_since: float | None = None
        #: the last predicted brake needed the guard's steps (``Guard.check_brake``'s guess)
        self._brake_stepped = False
        #: the guard (``companion.safety.Guard``; set by the flight's builder): a re-route or
        #: a rejoin is paced to its stopping law and checked whole before it is installed
        #: (``pace``); None: installed as planned
        self.guard = None

    @classmethod
    def from_plan(cls, plan, mission) -> "Replanner":
        """For a ``companion.planner.Plan`` of ``mission`` (its maps, coverage and trajectory);
        ``replan.body_radius_m`` unset is taken from the vehicle (``mission_body_radius_m``)."""
        known = KnownMap.from_mission(mission, plan.grid, plan.dem, plan.coverage.free_eroded)
        return cls(mission_replan_config(mission), known, GlobalPlan.from_plan(plan, mission))

    # --- plan bookkeeping -------------------------------------------------------------

    def _set_plan(self, plan: GlobalPlan) -> None:
        self.plan = plan
        self._cursor = TrajectoryCursor(plan.trajectory)
        self._n_legs = max(1, len(plan.turns_enu_m) - 1)

    def _paced(self, plan: GlobalPlan, st, parent: GlobalPlan | None = None) -> tuple:
        """(plan or None, verdict, seconds added): a new plan retimed to the guard's
        stopping law (``pace``); None when the guard still refuses it. ``parent``: the
        plan a rejoin leaves, which it is new only until it flies again
        (``rejoin.converged_from``)."""
        if self.guard is None:
            return plan, None, 0.0
        x0 = np.array([st.p, st.v, st.a, st.jerk], dtype=float)
        horizon = None if parent is None else \
            (lambda p: converged_from(p.trajectory, parent.trajectory, float(p.t_s[0])))
        paced, verdict = pace(plan, x0, self.guard, horizon, self.cfg.ceiling_agl_m)
        if not verdict.ok:
            return None, verdict, 0.0
        return paced, verdict, float(paced.t_s[-1] - plan.t_s[-1])

    def _checked(self, plan: GlobalPlan, st) -> tuple:
        """(plan or None, verdict, seconds added, note, conflict): the one place a re-route is
        proposed (docs/replan.md "One picture, and a repair"). The candidate is paced to the
        guard and judged whole (``pace``); refused, it is repaired where its fit cut what its
        route kept (``repair``: denser way-points, slower) and judged again, at most
        ``MAX_REPAIRS`` times. ``note`` says how often it was repaired, or why not;
        ``conflict`` ((k, 3) or None): where the route itself breaks an obstacle's clearance,
        the map's voxels there, for the search to go round (None: not that)."""
        if self.guard is None:
            return plan, None, 0.0, "", None
        x0 = np.array([st.p, st.v, st.a, st.jerk], dtype=float)
        t_end = float(plan.t_s[-1])
        cand, n = plan, 0
        while True:
            paced, verdict = pace(cand, x0, self.guard, ceiling_agl_m=self.cfg.ceiling_agl_m)
            if verdict.ok:
                return paced, verdict, float(paced.t_s[-1] - t_end), (f"repaired {n} x" if n else ""), None
            fix = repair(paced, x0, verdict, self.guard) if n < MAX_REPAIRS else None
            if fix is None or fix.plan is None:
                note = f"repaired {n} x" if fix is None else (f"repaired {n} x, then " if n else "") + fix.reason
                conflict = None if fix is None else self._conflict(verdict)
                return None, verdict, 0.0, note, conflict
            cand, n = fix.plan, n + 1

    def _conflict(self, verdict) -> np.ndarray | None:
        """(k, 3) what the refused sample of a route that itself breaks a clearance came too
        close to, for the 2-D search to keep from as from an obstacle: the map's voxels, or
        the row cells (at the sample's height), within the clearance and body plus
        ``CONFLICT_REACH_M`` of it; None for the terrain or without a point."""
        if verdict.point_enu_m is None or verdict.surface not in ("obstacle", "row"):
            return None
        q = np.asarray(verdict.point_enu_m, float)
        reach = self._keep_m + CONFLICT_REACH_M
        if verdict.surface == "obstacle":
            pts = self.memory.points()
            return pts[np.linalg.norm(pts - q, axis=1) <= reach] if len(pts) else None
        grid = self.known.grid
        rc = self.known.cell_of(float(q[0]), float(q[1]))
        if rc is None:
            return None
        k = int(np.ceil(reach / grid.resolution_m))
        r0, c0 = max(0, rc[0] - k), max(0, rc[1] - k)
        rows, cols = np.nonzero(np.asarray(grid.occupied)[r0:rc[0] + k + 1, c0:rc[1] + k + 1])
        if not len(rows):
            return None
        x, y = grid.cell_to_world(rows + r0, cols + c0)
        near = np.hypot(x - q[0], y - q[1]) <= reach
        return np.column_stack([x[near], y[near], np.full(int(near.sum()), q[2])]) if near.any() else None

    def _leg_frame(self, k: int):
        """(A (3,), B (3,), u_t (2,), u_n (2,)) of leg k of the plan (``GlobalPlan.leg_frame``)."""
        return self.plan.leg_frame(k)

    # --- the contract ----------------------------------------------------------------------

    def start(self, t_s: float) -> None:
        """The trajectory phase starts at vehicle time ``t_s`` (the plan's t0 maps onto it)."""
        self._offset = float(t_s) - self.plan.trajectory.t0
        self._tau_prev = None

    def on_pose(self, t_s: float, pos_enu_m, R_enu_flu, attitude=None) -> None:
        """The estimated pose at vehicle time ``t_s`` (position ENU m, R body FLU -> ENU).
        ``attitude``: (vehicle time s, R, body rates FLU) of the vehicle's last ATTITUDE when the pose's
        rotation is carried from it; None when it comes from the companion's observer.
        Readings that waited for that attitude (``attitude_wait``) are placed now."""
        self.poses.add(t_s, pos_enu_m, R_enu_flu)
        aw = self.attitude
        aw.live = attitude is not None
        if attitude is not None:
            aw.measured(*attitude)
        if len(aw):
            for arrival, reading, pose in aw.ready(t_s, self.poses):
                self._place(arrival, reading, pose)

    def on_range(self, t_s: float, reading) -> None:
        """One decoded DISTANCE_SENSOR (``mavcore.codec.Range``) received at ``t_s``."""
        self.n_readings += 1
        tb = reading.time_boot_ms * 1e-3
        if self.attitude.stale(tb):
            self.attitude.hold(t_s, reading)
            return
        pose = self.poses.at(tb)
        if pose is None:
            pose = self.poses.at(t_s)
        self._place(t_s, reading, self.attitude.pose_at(tb, pose))

    def _place(self, t_s: float, reading, pose) -> None:
        """The evidence of ``reading`` (received at ``t_s``) placed with ``pose``."""
        ev = None if pose is None else beam_evidence(reading, pose, self.cfg.offset_of(reading.sensor_id))
        if ev is None:
            self.n_ignored += 1
            return
        # the rows measure the estimate's heading error (``heading_bias``): the beam is turned by it
        self.heading.observe(t_s, ev, self._explained, self._on_terrain, self._near_remembered)
        if self.heading.estimate_rad:
            ev = rotate_evidence(ev, self.heading.estimate_rad)
        self.fresh.on_evidence(t_s, reading.sensor_id, reading.R_flu_sensor, reading.hfov_rad, reading.vfov_rad)
        mem = self.memory
        if len(mem):
            mem.clear_beam(ev)
        if ev.hit is None:
            return
        unknown = not self._explained(ev) and not self._explained_within_attitude(reading, pose)
        if not unknown and self.cfg.give_way and self.known.classify(*ev.hit) == KNOWN_ADDED:
            # an added obstacle is one the vehicle saw still, not one the survey mapped: it may
            # move (a worker stands, then walks). Its returns are read for an approach, so the
            # measurement has its history when one leaves the added cells and is unknown again.
            # Unread, a worker standing where a re-route went round it walked 0.38 m at the
            # hovering vehicle before its return left the cells, and the approach then took its
            # 0.3 s baseline more: fresh seed 20261224 along, flight 7, contact. Its returns stay
            # explained: made unknown on an approach, the realistic sensor profile's false
            # approaches on a still added obstacle stopped a flight 60 times in 400 s until the
            # gate refused a sample (fresh seed 20261227 across, flight 4)
            self._measure_approach(t_s, reading.sensor_id, ev)
        if unknown:
            # the return may come from anywhere in the field of view: keep the edge
            # points too where they are a voxel apart and not on a known feature, as
            # candidates (``voxmap``: one beam through them clears them, and unless an
            # axis hit confirms them they lapse after ``voxmap.CANDIDATE_LIFETIME_S``)
            mem.add(ev.hit)
            if ev.distance_m * math.tan(ev.half_max_rad) > self.cfg.voxel_m:
                for q in ev.fan_hits:
                    if self.known.classify(*q) == UNKNOWN:
                        mem.add(q, L_CANDIDATE, t_s)
            self.n_unknown += 1
            if self.cfg.give_way:          # else no approach is ever measured: a still world
                self._measure_approach(t_s, reading.sensor_id, ev)

    def _measure_approach(self, t_s: float, sensor_id: int, ev) -> None:
        """Feed a return to the approach measurement (``closing.ClosingSpeed``)."""
        lo, hi = field_sine_range(ev)
        self.closing.on_hit(t_s, sensor_id, ev.hit, ev.axis, self._still, ev.origin,
                            (ev.origin[2], ev.distance_m, lo, hi), ev.distance_m * math.tan(ev.half_max_rad))

    def _explained_within_attitude(self, reading, pose) -> bool:
        """The attitude allowance: the known map explains the return with the beam placed by
        an attitude within ``replan.tilt_tolerance_deg`` / ``heading_tolerance_deg`` of the
        estimate (``perception.attitude_perturbations``; docs/replan.md "The attitude
        allowance")."""
        turns = self._allowance
        if not turns:
            return False
        offset = self.cfg.offset_of(reading.sensor_id)
        for R in attitude_perturbations(pose.R, *turns):
            ev = beam_evidence(reading, Pose(pose.t_s, pose.p, R), offset)
            if ev is None or ev.hit is None:
                continue
            if self.heading.estimate_rad:
                ev = rotate_evidence(ev, self.heading.estimate_rad)
            # the return's own points only: the nearest ground in a turned field is no
            # evidence (on a slope a 1 deg turn brought it level with a low post's return)
            if self._explained(ev, ground_in_view=False):
                return True
        return False

    def _near_remembered(self, ev) -> bool:
        """The return's axis point lies within a voxel of an obstacle point the map remembers."""
        mem = self.memory
        if not len(mem):
            return False
        r = self.cfg.voxel_m
        if mem.points_lower_bound(ev.hit) > r:
            return False
        return bool(mem.distance(np.asarray(ev.hit, dtype=float).reshape(1, 3))[0] <= r)

    def _on_terrain(self, ev) -> bool:
        """A point of the return (its axis hit or a field-of-view edge) is on the terrain."""
        classify = self.known.classify
        return classify(*ev.hit) == KNOWN_GROUND or any(classify(*q) == KNOWN_GROUND for q in ev.fan_hits)

    def _explained(self, ev, ground_in_view: bool = True) -> bool:
        """The known map accounts for the return along the axis or a field-of-view edge,
        or (``ground_in_view``) the ground is in view at the return's distance (anywhere in
        the field: a beam rolled about its axis sees the ground first at a corner)."""
        known, o, d = self.known, ev.origin, ev.distance_m
        if known.explains(o, ev.axis, d):
            return True
        for q in ev.fan_hits:
            if known.explains(o, ((q[0] - o[0]) / d, (q[1] - o[1]) / d, (q[2] - o[2]) / d), d):
                return True
        if ground_in_view and (ev.half_h_rad > 0.0 or ev.half_v_rad > 0.0):
            g = known.ground_in_view_m(o, ev.axis, ev.h_axis, ev.v_axis, ev.half_h_rad, ev.half_v_rad)
            return d >= g - known.tolerance_m
        return False

    def step(self, t_s: float, pos_enu_m, vel_enu_m_s) -> ReplanStep:
        """The reference for this frame (vehicle time ``t_s``; the estimated state)."""
        if self._offset is None:
            self.start(t_s)
        tau = t_s - self._offset
        dt = 0.0 if self._tau_prev is None else tau - self._tau_prev
        self._tau_prev = tau
        self._pos = pos_enu_m
        self._vel = vel_enu_m_s
        self._t_s = t_s
        self._still = False                      # set by ``_look`` while at rest
        self._evading = False                    # set by ``_stop`` while a mover comes closer
        events: list = []
        self.memory.expire_candidates(t_s)
        mode = self.mode
        n_emergency = self.n_emergency_brakes
        if mode in _FOLLOWING:
            ref = self._follow(tau, events)
        elif mode in ("avoid", "climb"):
            ref = self._avoid(tau, dt, events)
        elif mode == "stop":
            ref = self._stop(tau, dt, events)
        else:
            ref = self._static
        if self.n_emergency_brakes != n_emergency:
            self._emergency_event(events)
        self._account(ref)
        return ReplanStep(ref, self.mode, self.mode == "done", self.mode == "hold", tuple(events))

    @property
    def plan_end_s(self) -> float:
        """Vehicle time (s) at which the plan being flown (the last installed: the plan, a
        re-route, a rejoin) ends."""
        offset = 0.0 if self._offset is None else self._offset
        return offset + float(self.plan.trajectory.tf)

    @property
    def stats(self) -> ReplanStats:
        """Statistics so far (report.json ``replanning``)."""
        return ReplanStats(self._n_events, tuple(self._events), self._max_lat,
                           self._flown - self._planned_length, self._max_climb(), self._min_range,
                           self.n_readings, self.n_unknown, self.n_ignored, tuple(self._skipped),
                           self._max_agl, float(self.cfg.ceiling_agl_m))

    # --- the obstacle map's views ---------------------------------------------------------

    def _points(self) -> np.ndarray:
        """(k, 3) the occupied voxels the avoidance reacts to: the whole map but those over
        the cells a re-route added to the known map (the new plan goes round them, and
        reacting to them again would undo it). The map itself keeps them: rejoin
        candidates, re-routes and the route check read it whole."""
        pts = self.memory.points()
        if not len(pts) or self.known is self._known0:
            self._active_conf = self.memory.confirmed()
            return pts
        key = (self.memory.version, id(self.known))
        if self._active_key != key:
            g = self.known.grid
            r, c = g.world_to_cell(pts[:, 0], pts[:, 1])
            r, c = np.rint(r).astype(int), np.rint(c).astype(int)
            rows, cols = g.shape
            on = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
            added = np.zeros(len(pts), dtype=bool)
            added[on] = self.known.known_added[r[on], c[on]]
            self._active = pts[~added]
            self._active_conf = self.memory.confirmed()[~added]
            self._active_key = key
        return self._active

    def _confirmed(self) -> np.ndarray:
        """(k,) bool, aligned with ``_points()``: the voxel was hit on a beam's axis."""
        self._points()
        return self._active_conf

    # --- modes --------------------------------------------------------------------------

    def _event(self, events: list, action: str, rng: float | None, detail: str = "") -> None:
        pos = tuple(float(x) for x in self._pos)
        e = ReplanEvent(float(self._t_s), pos, rng, action, detail)
        events.append(e)
        self._n_events += 1
        if len(self._events) < MAX_EVENTS_KEPT:
            self._events.append(e)

    def _skip(self, events: list, from_s: float, to_s: float, length_m: float, reason: str) -> None:
        """Coverage left out: the ``skip`` event and ``coverage_skipped``."""
        self._skipped.append((from_s, to_s, length_m, reason))
        self._event(events, "skip", None, f"{length_m:.1f} m of plan skipped ({reason}), "
                    f"plan {from_s:.1f}-{to_s:.1f} s")

    def _ref(self, p, v, a, j, s) -> RefSample:
        return RefSample(tuple(p), tuple(v), tuple(a), tuple(j), tuple(s), _pointing(p, self._target))

    def _rest(self, p) -> RefSample:
        z = (0.0, 0.0, 0.0)
        return RefSample(tuple(float(x) for x in p), z, z, z, z, _pointing(p, self._target))

    def _follow(self, tau: float, events: list) -> RefSample:
        cur = self._cursor
        s = cur.sample(tau)
        if tau >= cur.tf:
            self.mode = "done"
            self._static = RefSample(s.p, s.v, s.a, s.jerk, s.snap, _pointing(s.p, self._target))
            return self._static
        if self.mode != "follow" and tau >= self._mode_until:
            self.mode = "follow"
            self._dev_leg = None
        if self._dev_leg is not None:
            self._deviation(s.p)
        if len(self.memory):
            rng = self._threat(s.p, s.v, lambda: self._leg_frame(self.plan.leg_near(s.p, s.v[:2]))[2])
            if rng is not None:
                self._enter_avoid(tau, s, rng, events)
                if self.cfg.give_way:
                    # people and machines move here: stop and look before avoiding it as still
                    self._enter_stop(tau, events, "look", "stopping to see whether it moves")
        return RefSample(s.p, s.v, s.a, s.jerk, s.snap, _pointing(s.p, self._target))

    def _trigger_m(self, speed: float) -> float:
        """Range (m) at which an obstacle point starts an avoidance: d_o, or farther when
        the governor's braking distance from ``speed`` (plus 0.5 m) needs it."""
        speed += self.closing.approach_m_s(getattr(self, "_t_s", None))
        return max(self.cfg.influence_range_m, speed * speed / (2.0 * self._brake) + speed * GOVERNOR_LAG_S
                   + self._keep_m + GOVERNOR_MARGIN_M + 0.5)

    def _threat(self, p, v, leg_u, extra_m: float = 0.0) -> float | None:
        """Distance to the nearest remembered point within the trigger range (plus
        ``extra_m``) that is not behind (along the horizontal velocity, or ``leg_u``
        when hovering, at least -(clearance + body + ``extra_m``)); None if none.
        Behind counts as safe only in a still world: while a mover's approach is
        measured (``closing``), every point within the range is a threat.
        The same test starts an avoidance and (with ``REJOIN_HYSTERESIS_M``, and
        the leg ``follow`` will use) allows the rejoin, so the two cannot
        alternate. A point behind a row (the straight line to it crosses an
        occupied cell below the canopy) is in another corridor: the map remembers
        obstacles for good, and one seen from the next corridor is no threat here.
        ``leg_u`` may be a callable returning it: the leg is then looked up only when
        it is needed (hovering, with points remembered), not every frame."""
        pts = self._points()
        if not len(pts):
            return None
        speed = math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
        reach = self._trigger_m(speed) + extra_m
        if self.memory.points_lower_bound(p) > reach:
            return None                     # every point is out of the trigger range
        rel = pts - np.asarray(p)
        dist = np.sqrt(np.einsum("ki,ki->k", rel, rel))
        vh = math.hypot(v[0], v[1])
        if vh > 0.05:
            u = np.array([v[0] / vh, v[1] / vh])
        else:
            u = leg_u() if callable(leg_u) else leg_u
        ok = dist <= reach
        if self.closing.approach_m_s(getattr(self, "_t_s", None)) <= 0.0:
            # a still world: what is behind stays behind. A measured approach is not
            # located, and a mover closes from any side (mix flight 84: a walker came up
            # behind a vehicle slowed to 0.1 m/s, ignored as behind until 1.1 m away)
            ok &= rel[:, :2] @ u >= -self._keep_m - extra_m
        if ok.any():
            idx = np.flatnonzero(ok)
            ok[idx[self._behind_row(p, pts[idx])]] = False
        return float(dist[ok].min()) if ok.any() else None

    def _behind_row(self, p, pts: np.ndarray) -> np.ndarray:
        """(k,) bool: the horizontal line from ``p`` to each point crosses an occupied map
        cell (sampled every half cell) while both are below the canopy."""
        known = self.known
        g = known.grid
        ground = known.ground_z(float(p[0]), float(p[1]))
        top = ground + known.canopy_height_m
        if p[2] > top or not len(pts):
            return np.zeros(len(pts), dtype=bool)
        d = pts[:, :2] - np.asarray(p[:2], dtype=float)
        L = float(np.sqrt(np.einsum("ki,ki->k", d, d)).max())
        f = np.linspace(0.0, 1.0, max(2, int(L / (0.5 * g.resolution_m)) + 1))
        r, c = g.world_to_cell(p[0] + f[None, :] * d[:, :1], p[1] + f[None, :] * d[:, 1:])
        r, c = np.rint(r).astype(int), np.rint(c).astype(int)
        rows, cols = g.shape
        on = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
        hit = np.zeros(r.shape, dtype=bool)
        hit[on] = g.occupied[r[on], c[on]]
        return hit.any(axis=1) & (pts[:, 2] <= top)

    def _enter_avoid(self, tau: float, s, rng: float, events: list) -> None:
        self.shaper.reset(s.p, s.v, s.a, s.jerk)
        self._gate_since = None
        k = self.plan.leg_near(s.p, s.v[:2])
        self._avoid_leg = k
        self._wp_leave = self.plan.waypoint_index_at(tau)
        self._leg_wp = self._wp_leave          # the avoided leg began at or before it
        A, B, u, n = self._leg_frame(k)
        self._dev_leg = ((A[:2].copy(), B[:2].copy()),)
        self._dev_avoided = 0
        along = float((np.asarray(s.p[:2]) - A[:2]) @ u)
        self._progress = along
        self._t_progress = tau
        self._t_avoid = tau
        self._t_climb = None
        self.mode = "avoid"
        self._event(events, "avoid", rng, f"unknown obstacle within {self._trigger_m(self.speed_m_s):.2f} m")

    def _avoid(self, tau: float, dt: float, events: list) -> RefSample:
        cfg = self.cfg
        P = np.array(self.shaper.p)
        k = self._avoid_leg
        A, B, u, n = self._leg_frame(k)
        if math.hypot(*(B[:2] - P[:2])) < GOAL_REACHED_M and k < self._n_legs - 1:
            k = self._avoid_leg = k + 1
            A, B, u, n = self._leg_frame(k)
            self._leg_wp = next_corner_visit(self.plan, A, self._leg_wp)
            self._dev_leg = (self._dev_leg[-1], (A[:2].copy(), B[:2].copy()))   # this leg and the one before
            self._dev_avoided = 1
            self._progress = float((P[:2] - A[:2]) @ u)
            self._t_progress = tau
            # along-leg coordinates change with the leg: restart the escape's goals on it
            self._far_along = float(P[:2] @ u)
            self._rise_xy = A[:2] + float((P[:2] - A[:2]) @ u) * u
        pts = self._points()
        rel = pts - P
        dist = np.sqrt(np.einsum("ki,ki->k", rel, rel))
        along = rel[:, :2] @ u
        c = self._keep_m
        near = dist <= give_way_range_m(cfg.influence_range_m, self._trigger_m(self.speed_m_s),
                                        self.closing.approach_m_s(self._t_s))
        v = self.shaper.v
        if tau >= self._next_rejoin and self._calm() and self._threat(
                P, v, lambda: self._leg_frame(self.plan.leg_near(P, v[:2]))[2], REJOIN_HYSTERESIS_M) is None:
            ref = self._try_rejoin(tau, events)
            if ref is not None:
                return ref
        # the way ahead, at the current height
        c_pass = c + GOVERNOR_MARGIN_M
        lat_o = (pts[:, :2] - A[:2]) @ n
        ahead = (along > -c) & (along <= cfg.influence_range_m) & (np.abs(lat_o) <= cfg.lateral_limit_m + c_pass)
        band = ahead & (np.abs(pts[:, 2] - P[2]) < c_pass)
        passable = not band.any() or lateral_gap(lat_o[band], cfg.lateral_limit_m - WALL_MARGIN_M, c_pass)
        stalled = tau - self._t_progress > cfg.stall_s
        ground = self.known.ground_z(float(P[0]), float(P[1]))
        z_ceiling = ground + cfg.ceiling_agl_m
        if tau - self._t_avoid > cfg.escape_timeout_s and self.mode == "avoid" and not cfg.vertical_escape:
            return self._enter_stop(tau, events, "reroute", f"no way past in {cfg.escape_timeout_s:g} s "
                                    "(vertical escape off)")
        if self.mode == "avoid" and (not passable or stalled) and cfg.vertical_escape:
            self.mode = "climb"
            self._t_climb = tau
            self._climb_phase = "rise"
            self._rise_xy = A[:2] + float((P[:2] - A[:2]) @ u) * u      # on the leg's line
            self._z_pass = P[2]
            self._far_along = float(P[:2] @ u)
            self._event(events, "climb", self._nearest(dist), "no lateral gap" if not passable else "no progress")
        goal = B.copy()
        if self.mode == "climb":
            if ahead.any():
                conf = self._confirmed()
                top_of = ahead & conf if (ahead & conf).any() else ahead
                z_top = float(pts[top_of, 2].max())
                self._z_pass = max(self._z_pass, z_top + c_pass + PASS_MARGIN_M)
                if not passable and too_tall(z_top, z_ceiling, self._keep_m):
                    return self._enter_stop(tau, events, "reroute", f"obstacle top above {z_top - ground:.2f} m, "
                                            f"ceiling {cfg.ceiling_agl_m:g} m")
                self._far_along = float(along[ahead].max()) + float(P[:2] @ u)
            elif not stalled:
                # nothing ahead and moving on: what this escape met is passed, and its clock
                # restarts; the next obstacle gets its own escape_timeout_s (a climb over a
                # phantom flew on at the pass height for 18 s, the rejoin refused by a post
                # further on, and met that post with 1 s left: obstacles-wide seed 20261128,
                # flight 0)
                self._t_climb = tau
            if tau - self._t_climb > cfg.escape_timeout_s:
                # not a hold: the way ahead is blocked for this escape, not for every route
                # (docs/replan.md "Every hold is justified")
                return self._enter_stop(tau, events, "reroute", f"escape not through in {cfg.escape_timeout_s:g} s")
            z_goal = min(self._z_pass, z_ceiling - WALL_MARGIN_M)
            if self._climb_phase == "rise" and passable and P[2] >= z_goal - RISE_TOL_M:
                self._climb_phase = "over"
            if self._climb_phase == "rise":
                goal = np.array([self._rise_xy[0], self._rise_xy[1], z_goal])
            else:
                # beyond the farthest point seen, on the leg's line, one influence range on,
                # and at least that far ahead of the vehicle: with the next obstacle
                # seen beyond the influence range but within the trigger distance no
                # rejoin is allowed, and a goal left behind held the vehicle there
                # (20 s, then "escape not through": randomized benchmark flight 43)
                s_goal = min(max(self._far_along, float(P[:2] @ u)) + cfg.influence_range_m, float(B[:2] @ u))
                xy = A[:2] + (s_goal - float(A[:2] @ u)) * u
                goal = np.array([xy[0], xy[1], z_goal])
        end_m = leg_end_wall_m(self.plan, k, P, cfg.lateral_limit_m - WALL_MARGIN_M)
        v_cmd = self._apf_velocity(P, pts[near], dist[near], goal, A, u, n, ground, end_m)
        st = self._shape(dt, v_cmd)
        prog = float((np.asarray(st.p[:2]) - A[:2]) @ u)
        if prog > self._progress + PROGRESS_M:
            self._progress = prog
            self._t_progress = tau
        self._deviation(st.p)
        return self._ref(st.p, st.v, st.a, st.jerk, st.snap)

    def _nearest(self, dist: np.ndarray) -> float | None:
        return float(dist.min()) if len(dist) else None

    def _apf_velocity(self, P, obs, obs_dist, goal, A, u, n, ground, end_m: float = math.inf) -> list:
        """Velocity command (ENU m/s) from the APF force, constrained (module doc); ``end_m``:
        the distance along the leg to its end corner's wall (``corner.leg_end_wall_m``)."""
        if len(obs):
            obstacles = cluster_nearest(obs, obs_dist, CLUSTER_M, MAX_OBSTACLES)
        else:
            obstacles = obs
        # gradient flow: v = F / (k_att T_FLOW), then the speed limits (in _constrain)
        v = apf_force(P, obstacles, goal, self.apf).total / (self.apf.k_att * FLOW_TIME_S)
        v = self._constrain(P, v, A, u, n, ground, end_m)
        if len(obs) and self.cfg.clearance_governor:
            v = self._govern(P, v, obs, obs_dist)
            v = self._constrain(P, v, A, u, n, ground, end_m)
            v = self._govern_rows(P, v)
            v = self._govern(P, v, obs, obs_dist, scale_only=True)
            if v[2] < 0.0 and self._over_points(P, v, obs):
                v[2] = 0.0
        elif self.cfg.clearance_governor:
            v = self._govern_rows(P, v)
        v = self._band_over_slope(P, v, ground)
        t_s = getattr(self, "_t_s", None)      # None: called outside ``step``
        if self.cfg.clearance_governor and t_s is not None:
            pose = self.poses.at(t_s)
            if pose is not None:
                return block_no_data(v, self.fresh.has_data(t_s, pose.R, v))
        return v.tolist()

    def _band_over_slope(self, P, v, ground: float) -> np.ndarray:
        """The height band holds over sloping ground: the height above the terrain changes
        at ``v_z - slope * v_h``, so where the ground falls away (or rises) along the
        command faster than the vertical speed left after the governors can follow, the
        level part is scaled down until the height above ground leaves the band no faster
        than its walls allow (``_wall_speed``; the slope over ``SLOPE_STEP_M`` ahead). Held
        at constant height over remembered points it may not descend onto, a climb crept on
        down a slope to 3.30 m above the ground under a 3 m ceiling (mix 20261210 flight 6;
        3.22 m on mix 20261200 flight 0), and from above the ceiling no re-route can start
        (the guard refuses it)."""
        v = np.asarray(v, dtype=float)
        h = math.hypot(float(v[0]), float(v[1]))
        if h < 1e-9:
            return v
        cfg = self.cfg
        x, y = float(P[0]) + SLOPE_STEP_M * float(v[0]) / h, float(P[1]) + SLOPE_STEP_M * float(v[1]) / h
        rise = (self.known.ground_z(x, y) - ground) / SLOPE_STEP_M * h      # m/s the ground comes up
        vz = float(v[2])
        k = 1.0
        if rise < 0.0:           # falling away: the height above ground grows at vz - rise
            room = self._wall_speed(ground + cfg.ceiling_agl_m - WALL_MARGIN_M - float(P[2]))
            if vz - rise > room:
                k = max(0.0, (room - vz) / -rise)
        elif rise > 0.0:         # coming up: it shrinks at rise - vz
            room = self._wall_speed(float(P[2]) - ground - cfg.floor_agl_m - WALL_MARGIN_M)
            if rise - vz > room:
                k = max(0.0, (room + vz) / rise)
        if k >= 1.0:
            return v
        return np.array([float(v[0]) * k, float(v[1]) * k, vz])

    def _over_points(self, P, v, obs) -> bool:
        """A remembered point below the reference lies horizontally within the
        clearance, the body, the governor margin and ``HOLD_HEIGHT_LAG_S`` of travel."""
        below = obs[:, 2] < P[2]
        if not below.any():
            return False
        reach = self._keep_m + GOVERNOR_MARGIN_M + math.hypot(float(v[0]), float(v[1])) * HOLD_HEIGHT_LAG_S
        d = obs[below, :2] - P[:2]
        return bool((np.einsum("ki,ki->k", d, d) < reach * reach).any())

    def _constrain(self, P, v, A, u, n, ground, end_m: float = math.inf) -> np.ndarray:
        """Corridor walls, height band and speed limits on a velocity command. The walls:
        both sides of the leg, and across it ``end_m`` ahead where the path turns at the
        leg's end (``companion.replan.corner``: the next leg's side wall, met before the
        switch)."""
        cfg = self.cfg
        vt, vn, vz = float(v[:2] @ u), float(v[:2] @ n), float(v[2])
        lat = float((P[:2] - A[:2]) @ n)
        L = cfg.lateral_limit_m - WALL_MARGIN_M
        wall = self._wall_speed
        vn = min(max(vn, -wall(L + lat)), wall(L - lat))
        if math.isfinite(end_m):
            vt = min(vt, wall(end_m))
        vz = self._height_band(float(P[2]), vz, ground)
        h = math.hypot(vt, vn)
        cap = give_way_speed_m_s(self.speed_m_s, self.closing.approach_m_s(getattr(self, "_t_s", None)))
        if h > cap:
            vt, vn = vt * cap / h, vn * cap / h
        return np.array([vt * u[0] + vn * n[0], vt * u[1] + vn * n[1], vz])

    def _height_band(self, z: float, vz: float, ground: float) -> float:
        """A vertical command (m/s) within the height band at height ``z`` (m) over ``ground``:
        the floor and the ceiling are walls (``_wall_speed``, ``WALL_MARGIN_M`` inside them),
        and the vertical speed limit."""
        cfg = self.cfg
        z_lo, z_hi = ground + cfg.floor_agl_m + WALL_MARGIN_M, ground + cfg.ceiling_agl_m - WALL_MARGIN_M
        return min(max(vz, -cfg.vertical_speed_m_s, -self._wall_speed(z - z_lo)),
                   cfg.vertical_speed_m_s, self._wall_speed(z_hi - z))

    def _allowed_speed(self, room_m):
        """Largest speed (m/s) that stops within ``room_m`` (scalar or array): braking at
        a_b after a lag, v^2 / (2 a_b) + v t_lag = room."""
        bt = self._brake * GOVERNOR_LAG_S
        return np.sqrt(bt * bt + 2.0 * self._brake * room_m) - bt

    def _wall_speed(self, d: float) -> float:
        """Largest speed (m/s) toward a wall ``d`` m away (negative: pushed back from beyond it):
        the soft-wall gain and the braking law, whichever is lower."""
        if d <= 0.0:
            return WALL_GAIN_1_S * d
        return min(WALL_GAIN_1_S * d, float(self._allowed_speed(d)))

    def _govern(self, P, v, obs, obs_dist, scale_only: bool = False, movers: bool = True) -> np.ndarray:
        """Clearance governor: the approach speed to each point is at most the v with
        v^2 / (2 a_b) + v t_lag = d - clearance - margin (braking at a_b after the
        shaper's lag t_lag = ``GOVERNOR_LAG_S``), less a mover's closing speed
        (``movers`` False: every point still, the guard's own law).

        ``scale_only``: the command is only ever shortened, never lengthened, so what
        ``_constrain`` bounded (the corridor's walls, the height band, the speed cap) stays
        bounded. Where a mover's speed asks to back away faster than the command does
        (both speeds negative), scaling up carried the vehicle through its corner wall
        at 1.0-1.2 m/s where 0.6-0.9 was allowed (obstacles-wide seed 20261166, flight 20:
        0.71 m off the path); the push itself comes from the full governor before the walls."""
        d = np.maximum(obs_dist, 1e-9)
        nrm = (P - obs) / d[:, None]                        # from each point to the vehicle
        w = self.closing.approach_m_s(getattr(self, "_t_s", None)) if movers else 0.0
        allow = allowed_approach_m_s(self._allowed_speed(np.maximum(0.0, d - self._keep_m - GOVERNOR_MARGIN_M)), w)
        if scale_only:
            approach = -(nrm @ v)
            bad = approach > allow + 1e-12
            if bad.any():
                v = v * min(1.0, max(0.0, float(np.min(allow[bad] / approach[bad]))))
            return v
        v = v.copy()
        for i in np.argsort(d)[:64]:
            approach = -float(nrm[i] @ v)
            if approach > allow[i]:
                v = v + (approach - allow[i]) * nrm[i]
        return v

    def _govern_rows(self, P, v) -> np.ndarray:
        """The clearance governor against the vine rows (the guard's row rule, through
        ``Guard.row_room``): the approach to the nearest row surface is at most the speed
        that stops ``GOVERNOR_MARGIN_M`` short of the distance the guard makes the
        reference keep, none inside it. The corridor walls of ``_constrain`` are drawn
        along the leg being flown; at a leg's end (a headland turn, a row's end) they are
        not the rows, and an avoidance there closed on a row until the guard refused it
        (obstacles-wide, seed 20261127, flight 4). No guard, no governor."""
        if self.guard is None:
            return v
        room, nrm = self.guard.row_room(P)
        if not math.isfinite(room):
            return v
        nrm = np.asarray(nrm)
        allow = float(self._allowed_speed(max(0.0, room - GOVERNOR_MARGIN_M)))
        approach = -float(nrm @ v)
        if approach > allow:
            v = v + (approach - allow) * nrm
        return v

    def _shape(self, dt: float, v_cmd):
        """The shaper's step toward ``v_cmd``: the one exit of every avoiding mode's reference
        (avoid, climb, stop, the look, giving way; docs/replan.md "The stopping point").
        The state it reaches must be able to stop in time: the shaper's own brake from it
        (``brake_path``: zero command, the jerk ramp and any acceleration still toward a
        surface included) passes the guard's margin rule (``Guard.check_path``) with
        ``STOP_MARGIN_M`` more, from where the reference is now, and never enter the
        clearance itself nor close inside it (``STOP_TOL_M``). If not, the command loses its approach to the surface that
        failed (the normal there, at most twice), and failing that it is zero: the state
        then moves along the brake predicted from the last one, which passed. When even the
        brake fails (the state already closes inside a clearance), the candidate whose path
        comes least close wins, braking included. The command
        governors (``_govern``, ``_govern_rows``) limit the command; this limits the
        reference actually flown (a row's end closed on at 0.11-0.20 m/s for over a
        second while the command moved away, and the guard refused the sample:
        obstacles-wide seed 20261127, flight 15). No guard, or no governor: as commanded."""
        sh = self.shaper
        # the height band holds for every mode's command, whatever pushed it (a give-way's row
        # governor over a row's top pushes up: fresh seed 20261224 along, flight 16, took the
        # reference to 0.12 m over the 3 m ceiling, and the guard refused every re-route from there)
        v_cmd = list(v_cmd)
        v_cmd[2] = self._height_band(sh.p[2], float(v_cmd[2]), self.known.ground_z(sh.p[0], sh.p[1]))
        if self.guard is None or dt <= 0.0 or not self.cfg.clearance_governor:
            return sh.step(dt, v_cmd)
        cmd = np.asarray(v_cmd, dtype=float)
        here = np.asarray(sh.p, dtype=float)[None, :]

        since = None if self._gate_since is None else self._gate_since - self._t_s

        brakes = {}

        def judged(st, margin_m=STOP_MARGIN_M):
            # from where the reference is now, through the frame's step, to its stopping point;
            # the brake keeps STOP_MARGIN_M beyond the clearance (the prediction's error at
            # speed), and never enters the clearance itself nor closes inside it; and the gate
            # flies every point of it (``Guard.forecast_brake``: the speed rule, braking, the grace).
            # A state judged again this frame (at another margin, or as the fallback after the
            # exit's check) reuses its brake: it depends only on the state and the limits
            dt_brake = EMERGENCY_BRAKE_DT_S if self.emergency else BRAKE_DT_S
            key = (st, self.emergency)
            if key not in brakes:
                brakes[key] = brake_states(st.p, st.v, st.a, st.jerk, sh, dt_brake, st.brake_u)
            P, V, A = brakes[key]
            verdict, flags0, self._brake_stepped = self.guard.forecast_brake(
                here, P, V, A, dt_brake, since, margin_m, STOP_TOL_M, self._brake_stepped)
            return np.vstack([here, P]), verdict, flags0

        def commit(st, flags0):
            # the gate's failing run, as the gate will judge this sample (``Guard.gate_run``;
            # ``flags0``: the state's own (ok, braking), the first point of its judged brake)
            self._gate_since = self.guard.gate_run(*flags0, self._t_s, self._gate_since)
            return sh.commit(st)

        if self.emergency and not self._evading and self._calm():
            # back to the normal limits once the state is well within them (``_calm``: half of
            # them) and their brake from here passes with EMERGENCY_EXIT_MARGIN_M more (the
            # emergency brake is for what the normal one can no longer stop for; without the
            # margin the two alternated from frame to frame beside a post: fresh seed 20261155
            # of obstacles-wide, flight 2)
            # the state judged is the normal limits' own next one at a zero command (what this
            # frame falls back to), not the present state, and at the frame's own margin too:
            # the margin rule is not monotonic in its margin (a brake that starts inside the
            # wider band passes by not closing there, where the narrower one, once kept, must
            # be kept). Judged from the present state and at the wider margin only, the exit
            # passed while the fallback's step failed, and the two alternated every frame at
            # rest beside a row (mix seed 20261200, flight 0, with tilted beams reading movers:
            # 987 events in 11.5 s; with the fallback's state but one margin, the same every
            # frame from 122.05 s)
            self._set_emergency(False)
            fallback = sh.preview(dt, (0.0, 0.0, 0.0))
            if not (judged(fallback, STOP_MARGIN_M + EMERGENCY_EXIT_MARGIN_M)[1].ok and judged(fallback)[1].ok):
                self._set_emergency(True)

        tried = []
        for _ in range(3):
            st = sh.preview(dt, cmd.tolist())
            path, verdict, flags0 = judged(st)
            if verdict.ok:
                return commit(st, flags0)
            tried.append((st, path, flags0))
            # its approach along the normal there goes, and as much away as the state still
            # closes (the shaper then turns that round first: motion along the surface is kept)
            n = self.guard.normal(verdict.surface, verdict.point_enu_m)
            closing = max(0.0, -float(n @ np.asarray(st.v)))
            approach = -float(n @ cmd) + closing
            if approach <= 1e-9:
                break
            cmd = cmd + approach * n
        self.n_stop_limited += 1
        st = sh.preview(dt, (0.0, 0.0, 0.0))
        path, verdict, flags0 = judged(st)
        if verdict.ok:
            return commit(st, flags0)
        if not self.emergency:
            # the normal brake that keeps the clearance itself (no STOP_MARGIN_M: that band is
            # the prediction's allowance, and the next frame judges again) still stops for it:
            # it is flown. Failing the band alone took the emergency brake whenever a brake
            # ridden along the band's edge closed a millimetre more than the last one (mix seed
            # 20261200 flight 0: 92 emergency brakes at rest beside a row, 125.6-127 s)
            _, verdict0, flags00 = judged(st, 0.0)
            if verdict0.ok:
                return commit(st, flags00)
            # the normal brake can no longer stop for it (it came into view inside that
            # stopping distance: a walker out of a row, fresh seed 20261152 flight 10, met at
            # 0.52 m/s by a brake at 1 m/s^2): the emergency brake, until calm (``_calm``)
            tried.append((st, path, flags0))
            self._set_emergency(True)
            self.n_emergency_brakes += 1          # ``step`` reports it (``_emergency_event``)
            self._emergency_why = "cannot stop in time"
            st = sh.preview(dt, (0.0, 0.0, 0.0))
            path, verdict, flags0 = judged(st)
            if verdict.ok:
                return commit(st, flags0)
        # even braking closes (the state already closes inside a clearance: the map grew round
        # it): the candidate whose path comes least close, braking included, the earliest of
        # equals (moving away, or on along the surface, is never worse than braking; a zero
        # command here also stopped every climb, which then timed out: obstacles-wide seed
        # 20261127, flight 11)
        tried.append((st, path, flags0))
        rooms = [self._least_room(p) for _, p, _ in tried]
        st, _, flags0 = tried[int(np.argmax(rooms))]
        return commit(st, flags0)

    def _emergency_event(self, events: list) -> None:
        """The ``stop`` event of an emergency brake begun this frame."""
        pts = self._points()
        near = self._nearest(np.linalg.norm(pts - np.asarray(self.shaper.p), axis=1)) if len(pts) else None
        self._event(events, "stop", near, f"emergency brake at {self.cfg.emergency_limits()[0]:g} m/s^2: "
                    f"the brake at {self.cfg.accel_m_s2:g} m/s^2 {self._emergency_why}")

    def _set_emergency(self, on: bool) -> None:
        """The shaper's limits: the emergency brake's (``replan.emergency_accel_m_s2``,
        ``emergency_jerk_m_s3``, pole ``EMERGENCY_OMEGA_RAD_S``) or the normal ones."""
        self.emergency = on
        c = self.cfg
        if on:
            self.shaper.set_limits(*c.emergency_limits(), omega_rad_s=EMERGENCY_OMEGA_RAD_S)
        else:
            self.shaper.set_limits(c.accel_m_s2, c.jerk_m_s3)

    def _least_room(self, path) -> float:
        """Least (distance - the guard's clearance) (m) along (M, 3) points, over every surface."""
        d = self.guard.distances(path)
        return min(float(np.min(d[k])) - self.guard.required_m(k) for k in d)

    def _give_way(self, P, pts) -> np.ndarray:
        """Velocity (ENU, m/s) of a stop: zero, or backing away (level) from an obstacle
        that comes closer than the vehicle could stop for (``companion.replan.closing``)."""
        w = self.closing.approach_m_s(getattr(self, "_t_s", None))
        if not len(pts) or w <= 0.0:
            self._fleeing = False
            return np.zeros(3)
        cap = give_way_speed_m_s(self.speed_m_s, w)
        dist = np.linalg.norm(pts - P, axis=1)
        v = self._govern(P, np.zeros(3), pts, dist)
        if math.hypot(v[0], v[1]) == 0.0 and not self._fleeing:
            return np.zeros(3)                             # the mover is still beyond its stopping room
        # once the mover is inside the stopping distance of its closing speed, the vehicle
        # backs away at the whole give-way speed while the approach is measured: the
        # governor's deficit alone (w - v_stop(room)) starts from zero there and a vehicle
        # that tracks it with lag let a walker close to 0.39 m (mix flight 84)
        self._fleeing = True
        u = self._leg_frame(self._avoid_leg)[2]            # along the corridor only: not into a row
        along = self._give_way_side(P, u, float(v[:2] @ u[:2])) * cap
        v = along * np.array([u[0], u[1], 0.0])
        v = self._govern_rows(P, v)
        # backing away from a mover never closes on anything faster than the stopping law
        # allows a still obstacle (the guard's rule): a give-way toward a post behind at
        # 0.70 m/s where 0.57 m/s was allowed ended a flight (obstacles-wide scenario 1)
        v = self._govern(P, v, pts, dist, scale_only=True, movers=False)
        # ... nor nearer to another unknown obstacle than to the mover (``_govern_others``)
        v = self._govern_others(P, v, pts)
        # ... nor on what the guard knows beyond these points (the cells a re-route added, the
        # terrain): the guard's own speed law, along the command (a give-way at the whole
        # give-way speed, on a false 2.1 m/s mover, closed on a re-routed obstacle at 1.48 m/s
        # where 0.95 m/s was allowed and the gate refused the sample: mix flight 0)
        h = math.sqrt(float(v @ v))
        if self.guard is not None and h > 1e-9:
            lim = float(self.guard.speed_limits(P, v / h)[0])
            if h > lim:
                v = v * (lim / h)
        return v

    def _govern_others(self, P, v, pts) -> np.ndarray:
        """A give-way's command (level, m/s) shortened so that it brings the vehicle no nearer
        to any other unknown obstacle than it is to the mover it backs away from: an obstacle
        not seen moving may be a worker who starts walking, and backing away from one threat
        to come nearer another is no safer. The approach to each point the command closes on
        (not the mover's own: within ``closing.MATCH_M`` and its returns' spread of where it
        was measured) is held to the stopping law's speed for its excess distance (level,
        its distance less the mover's), none where it is nearer than the mover. Twice a false
        approach 2-5 m behind the vehicle (a wide beam's edge sweeping over a box or a row's
        end as the vehicle pitched) sent the give-way at 0.8-1.3 m/s toward a worker 3.5-4 m
        ahead it had stopped to watch, and the worker walked into it (mix seed 20261200,
        flight 71; fresh seed 20261226, flight 0)."""
        at = self.closing.mover_at(getattr(self, "_t_s", None))
        if at is None or not len(pts):
            return v
        off = pts[:, :2] - P[:2]
        d = np.maximum(np.hypot(off[:, 0], off[:, 1]), 1e-9)
        approach = (off @ v[:2]) / d                           # closing speed on each point
        closing_on = (approach > 0.0) & (np.hypot(pts[:, 0] - at[0], pts[:, 1] - at[1]) > MATCH_M + at[2])
        if not closing_on.any():
            return v
        room = np.maximum(0.0, d[closing_on] - math.hypot(P[0] - at[0], P[1] - at[1]))
        k = float(np.min(self._allowed_speed(room) / approach[closing_on]))
        return v * min(1.0, k)

    def _give_way_side(self, P, u, lean: float) -> float:
        """The side (+1: along the leg, -1: back) a give-way backs away to along the corridor:
        away from where the mover was last measured (``ClosingSpeed.mover_at``), once it lies
        farther along the corridor from the vehicle than its return's spread across the beam
        (``MOVER_GAP_MIN_M`` at least). Backing away along the corridor faster than the
        mover's own speed along it (the give-way speed outpaces the approach) then only
        widens that gap, whichever way the mover walks: across the corridor it passes
        behind (or ahead of) the vehicle, along it the vehicle leads it. The governor's
        lean away from the points (``lean``) took the side before: with a worker crossing
        1.06 m ahead it leaned under 0.01 m/s, forward, into the worker's line (mix seed
        20261200, flight 194: walked into). Nearer than that, the side chosen before in
        this stop stays (a crossing mover's returns from beam to beam flipped the lean from
        frame to frame: fresh seed 20261151, flight 3), the first time the lean's."""
        at = self.closing.mover_at(getattr(self, "_t_s", None))
        if at is not None:
            gap = (P[0] - at[0]) * u[0] + (P[1] - at[1]) * u[1]
            if abs(gap) > max(MOVER_GAP_MIN_M, at[2]):
                self._give_way_sign = math.copysign(1.0, gap)
        if self._give_way_sign is None:
            self._give_way_sign = math.copysign(1.0, lean) if lean != 0.0 else 1.0
        return self._give_way_sign

    def _enter_stop(self, tau: float, events: list, then: str, detail: str) -> RefSample:
        """Brake to rest (the ``stop`` event says ``detail``), then ``then``: ``look`` (give
        way) or ``reroute``. Nothing stops into a bare hold: a hold comes only from a
        re-route that finds no route, with the independent route check's words (``_hold``)."""
        if then not in STOP_THEN:
            raise ValueError(f"a stop ends in one of {STOP_THEN}, not {then!r}")
        self.mode = "stop"
        self._stop_then = then
        self._give_way_sign = None
        self._fleeing = False
        pts = self._points()
        P = np.array(self.shaper.p)
        self._event(events, "stop", self._nearest(np.linalg.norm(pts - P, axis=1)), detail)
        return self._stop(tau, 0.0, events)

    def _stop(self, tau: float, dt: float, events: list) -> RefSample:
        P = np.array(self.shaper.p)
        pts = self._points()
        # a mover coming closer is given way to at the emergency limits: a stop is not enough
        # when it walks on into the vehicle, and at the normal limits the vehicle cannot get
        # out of its path in time (fresh seed 20261155 of obstacles-wide, flight 2: a worker
        # walking at 1.3 m/s straight at the stopped vehicle, first seen 2.6 m away)
        self._evading = len(pts) > 0 and self.closing.approach_m_s(getattr(self, "_t_s", None)) > 0.0
        if self._evading and not self.emergency:
            self._set_emergency(True)
            self.n_emergency_brakes += 1
            self._emergency_why = "cannot give way to a mover in time"
        v = self._give_way(P, pts)
        st = self._shape(dt, v.tolist())
        self._deviation(st.p)
        at_rest = math.sqrt(sum(x * x for x in st.v)) < REST_V_M_S and \
            math.sqrt(sum(x * x for x in st.a)) < REST_A_M_S2
        if self._stop_then == "look":
            return self._look(tau, st, at_rest, events)
        if not at_rest:
            return self._ref(st.p, st.v, st.a, st.jerk, st.snap)
        dist = np.linalg.norm(pts - P, axis=1) if len(pts) else np.zeros(0)
        if self._stop_then == "reroute":
            near = pts[dist <= self.cfg.influence_range_m + 1.0] if len(pts) else pts
            # only what cannot be climbed over blocks the corridor (a low obstacle
            # beside a tall one is climbed when the new route meets it)
            conf = self._confirmed()[dist <= self.cfg.influence_range_m + 1.0] if len(pts) else None
            blocking = unpassable_points(near, self.known.ground_z, self.cfg.ceiling_agl_m, self._keep_m,
                                         confirmed=conf)
            if len(blocking) == 0:
                blocking = near
            travel = self._leg_frame(self._avoid_leg)[2]       # the leg the avoidance was on
            # planned round every obstacle known at the route's height; when that finds no
            # route (a 2-D route cannot go over the low ones), round those too tall to be
            # lifted over, then round the blocking one only, and the guard judges the
            # candidate against the rest (docs/replan.md "Pacing")
            known0, over = self.known, self._over()
            tiers = [self._at_route_height(), self._too_tall_to_lift()]
            if not 0 < len(tiers[1]) < len(tiers[0]):
                tiers.pop()               # the same columns as a tier beside it: the same route
            # stopped inside a clearance (the map grew round the vehicle), every route leaves
            # it first, straight out, and starts from there (docs/replan.md "Candidates that
            # start inside"): from inside, a route that closes on anything is refused
            # (judged on the map the route is flown on: the blocking obstacle's cells, columns
            # of unknown height, can put a vehicle stopped over its side inside their clearance)
            for others in (*tiers, None):
                conflict = np.zeros((0, 3))
                for _ in range(MAX_REPAIRS + 1):
                    # a route the guard refuses for what its own polyline passes (the search did
                    # not see it so) is searched again with that conflict among its obstacles
                    seen_others = others if not len(conflict) else (
                        conflict if others is None else np.vstack([others, conflict]))
                    res = reroute(self.plan, known0, st, tau, self._wp_leave, blocking, travel,
                                  self.cfg.obstacle_depth_m, self.cfg.vertical_speed_m_s,
                                  self._keep_m + ROUTE_MARGIN_M, seen_others, over, voxel_m=self.cfg.voxel_m)
                    # the guard reads the map the route is flown on: the obstacle added (its cells)
                    self.known = res.known
                    exit_leg = self._exit_leg(st.p)
                    if exit_leg is not None:
                        scene = RouteScene(res.known, self.memory, self._keep_m, self.cfg.floor_agl_m,
                                           self.cfg.ceiling_agl_m, guard=self.guard)
                        res = reroute_3d(self.plan, scene, exit_leg[1:], st, tau, self._wp_leave, blocking,
                                         travel, self.cfg.obstacle_depth_m, self.cfg.vertical_speed_m_s,
                                         self._keep_m + ROUTE_MARGIN_M, seen_others, over,
                                         route=Route3D(exit_leg, 0, float(np.linalg.norm(exit_leg[1] - exit_leg[0]))),
                                         voxel_m=self.cfg.voxel_m)
                        self.known = res.known
                    if res.plan is None:
                        plan, verdict, added, note, more = None, None, 0.0, "", None
                        break
                    plan, verdict, added, note, more = self._checked(res.plan, st)
                    if plan is not None or more is None or not len(more):
                        break
                    conflict = np.vstack([conflict, more])
                if plan is not None:
                    break
            via = ""
            if plan is None:
                # no 2-D start reaches the coverage left: leave in 3-D (over a row's canopy,
                # over a low obstacle at the ceiling) to the nearest coverage end a 3-D route
                # reaches, and re-route from there (``reroute3d``)
                # (the lattice keeps the clearance and body plus a margin, the route's where it
                # can, else the governor's, and last none: the independent check's own question,
                # so that "no route" is the check's answer too; what the stopping law leaves a
                # route on the clearance itself the guard judges, and refuses if nothing)
                goals = self._coverage_goals(st.p)
                # the search reads the guard's picture: the blocking obstacle's columns added
                seen = with_blocking(known0, blocking, st.p, travel, self.cfg.obstacle_depth_m,
                                     self._keep_m + ROUTE_MARGIN_M, self.cfg.voxel_m)
                for margin in LEAVE_MARGINS_M if len(goals) else ():
                    scene = RouteScene(seen, self.memory, self._keep_m + margin, self.cfg.floor_agl_m,
                                       self.cfg.ceiling_agl_m, guard=self.guard)
                    # from inside a clearance, out first (the lattice route starts where the leg ends)
                    start = np.asarray(st.p, float) if exit_leg is None else exit_leg[1]
                    route = find_route(scene, start, goals)   # one lattice search per margin
                    if route is None:
                        continue              # no 3-D route to any coverage end with this margin
                    if exit_leg is not None:
                        route = Route3D(np.vstack([exit_leg[:1], route.path_enu_m]), route.goal_index,
                                        route.length_m + float(np.linalg.norm(exit_leg[1] - exit_leg[0])))
                    for others in (*tiers, None):
                        res3 = reroute_3d(self.plan, scene, goals, st, tau, self._wp_leave, blocking, travel,
                                          self.cfg.obstacle_depth_m, self.cfg.vertical_speed_m_s,
                                          self._keep_m + ROUTE_MARGIN_M, others, over, route=route,
                                          voxel_m=self.cfg.voxel_m)
                        if res3.plan is not None:
                            self.known = res3.known
                            plan3, v3, add3, note3, _ = self._checked(res3.plan, st)
                            if plan3 is not None:
                                res, plan, verdict, added, via = res3, plan3, v3, add3, ", leaving in 3-D"
                                note = note3
                                break
                            res, verdict, note = res3, v3, note3
                    if plan is not None:
                        break
            if plan is not None:
                self._set_plan(plan)
                self._dev_leg = None
                self.mode = "reroute"
                self._mode_until = float(plan.t_s[1]) if len(plan.t_s) > 1 else tau
                paced = f", paced +{added:.1f} s" if added > 0.0 else ""
                fixed = f", {note}" if note else ""
                self._event(events, "reroute", self._nearest(dist),
                            f"{res.n_pieces} coverage pieces left, {res.n_skipped} unreachable{paced}{via}{fixed}")
                for gap in res.skipped:
                    self._skip(events, *gap)
                s = self._cursor.sample(tau)
                return RefSample(s.p, s.v, s.a, s.jerk, s.snap, _pointing(s.p, self._target))
            why = res.reason if res.plan is None else \
                f"guard refused the re-route: {verdict.detail}" + (f" ({note})" if note else "")
            return self._hold(st.p, dist, events, why)
        raise AssertionError(f"stop then {self._stop_then!r}")     # ``_enter_stop`` admits no other

    def _hold(self, p, dist: np.ndarray, events: list, why: str) -> RefSample:
        """The one way into ``hold``: at rest at ``p``, the ``hold`` event saying ``why`` the
        re-route found no route and what the independent route check (``_route_check``)
        finds on the same map. (A climb's timeout once held here bare: "escape not through
        in 20 s", no re-route tried, nothing checked; 4 of 8 holds of obstacles-wide seed
        20261128.)"""
        self.mode = "hold"
        self._static = self._rest(p)
        self._event(events, "hold", self._nearest(dist), f"{why}; {self._route_check(p)}")
        return self._static

    def _exit_leg(self, p):
        """(2, 3) the straight leg out of the guard's clearances from ``p`` (``margin_exit``),
        to the route's margin where one reaches it, else the governor's; None when ``p``
        keeps them (or there is no guard, or no way out)."""
        if self.guard is None:
            return None
        ground = self.known.ground_z(float(p[0]), float(p[1]))
        lo = ground + self.cfg.floor_agl_m + WALL_MARGIN_M
        hi = ground + self.cfg.ceiling_agl_m - WALL_MARGIN_M
        if margin_exit(self.guard, p, lo, hi, 0.0) is None:
            return None                   # not inside any clearance
        for margin in (ROUTE_MARGIN_M, GOVERNOR_MARGIN_M):
            leg = margin_exit(self.guard, p, lo, hi, margin)
            if leg is not None:
                return leg
        return None

    def _look(self, tau: float, st, at_rest: bool, events: list) -> RefSample:
        """The look (``give_way``): at rest, with the vehicle still, for ``LOOK_S`` with no
        motion seen, then the avoidance of the obstacle as a still one. While something
        moves the vehicle gives way (``_give_way``) and the look starts again when it is
        at rest: it waits for a worker to cross. (Flying on toward a crossing worker read
        as still, the vehicle was walked into: campaign obstacles-wide scenario 7.)"""
        v = self._vel
        self._still = at_rest and math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2) < STILL_M_S
        moving = self.closing.approach_m_s(self._t_s) > 0.0
        if not self._still or moving:
            self._look_since = None
        elif self._look_since is None:
            self._look_since = tau
        if self._look_since is None or tau - self._look_since < LOOK_S:
            return self._ref(st.p, st.v, st.a, st.jerk, st.snap)
        self._look_since = None
        self._still = False
        self.mode = "avoid"
        self._t_avoid = self._t_progress = tau
        A, B, u, n = self._leg_frame(self._avoid_leg)
        self._progress = float((np.asarray(st.p[:2]) - A[:2]) @ u)
        pts = self._points()
        self._event(events, "avoid", self._nearest(np.linalg.norm(pts - np.asarray(st.p), axis=1)),
                    f"no motion seen in {LOOK_S:g} s: avoiding it as still")
        return self._ref(st.p, st.v, st.a, st.jerk, st.snap)

    def _over(self) -> Over:
        """What a re-route is lifted over (``lift``): every voxel of the map, kept from by
        the clearance and body plus the governor's and the climb's margins (the height a
        climb passes at), ramps at the vertical over the cruise speed, under the ceiling."""
        return Over(self.memory.points(), float(self.cfg.voxel_m), self._keep_m,
                    GOVERNOR_MARGIN_M + PASS_MARGIN_M, self.cfg.vertical_speed_m_s / max(self.speed_m_s, 1e-3),
                    float(self.cfg.ceiling_agl_m))

    def _at_route_height(self) -> np.ndarray:
        """(j, 3) the map's occupied voxels whose column (obstacles stand on the ground)
        reaches within the clearance and body of the height a re-route flies at (the plan's
        height above the terrain): the 2-D re-route keeps clear of them all, not only of
        the obstacle that stopped the vehicle; what lies lower it flies over (``_over``)."""
        pts = self.memory.points()
        if not len(pts):
            return pts
        ground = self._ground_under(pts)
        z = ground + float(self.plan.flight.height_agl_m)
        return pts[pts[:, 2] >= z - self._keep_m - 0.5 * self.cfg.voxel_m]

    def _ground_under(self, pts: np.ndarray) -> np.ndarray:
        """(k,) the terrain height (m) under each of the (k, 3) points."""
        return np.array([self.known.ground_z(float(x), float(y)) for x, y in pts[:, :2]])

    def _too_tall_to_lift(self) -> np.ndarray:
        """(j, 3) the map's occupied voxels whose top, plus the clearance and body, stands
        above the highest a route flies there (``lift``: the ceiling less its wall margin):
        no lift goes over them, a 2-D route must go round."""
        pts = self.memory.points()
        if not len(pts):
            return pts
        ground = self._ground_under(pts)
        top = pts[:, 2] + 0.5 * self.cfg.voxel_m
        return pts[top + self._keep_m > ground + self.cfg.ceiling_agl_m - LIFT_WALL_MARGIN_M]

    def _coverage_goals(self, p) -> np.ndarray:
        """(k, 3) the ends of the coverage left nearest ``p`` (``ROUTE_CHECK_GOALS`` within
        ``ROUTE_CHECK_RADIUS_M``, else the nearest), at the plan's height: the far end of
        the segment being flown (the re-route flies its rest from there), and both ends
        of every segment not yet started. (The segment before those, already flown, once
        counted too: a vehicle stopped at its end "reached" it, and every hold there read
        "independent check DISAGREES".)"""
        plan = self.plan
        current, nxt = plan.segment_at(self._wp_leave)
        ends = ([plan.segments[current].end_xy] if current is not None else []) + \
            [q for seg in plan.segments[nxt:] for q in (seg.start_xy, seg.end_xy)]
        if not ends:
            return np.zeros((0, 3))
        P = np.asarray(p, dtype=float)
        xy = np.asarray(ends, dtype=float)
        d = np.hypot(*(xy - P[:2]).T)
        order = [i for i in np.argsort(d) if d[i] <= ROUTE_CHECK_RADIUS_M][:ROUTE_CHECK_GOALS] or [int(np.argmin(d))]
        return np.array([(x, y, self.known.ground_z(x, y) + plan.flight.height_agl_m)
                         for x, y in xy[order].tolist()])

    def _route_check(self, p) -> str:
        """The independent 3-D route check (``routecheck``) from ``p`` to the ends of the
        coverage left (the ``ROUTE_CHECK_GOALS`` nearest within ``ROUTE_CHECK_RADIUS_M``), on
        the rows, the terrain and the obstacle map: the words a hold reports."""
        goals = self._coverage_goals(p)
        if not len(goals):
            return "no coverage left to reach"
        P = np.asarray(p, dtype=float)
        scene = RouteScene(self.known, self.memory, self._keep_m, self.cfg.floor_agl_m, self.cfg.ceiling_agl_m)
        found = route_exists(scene, P, goals)
        if not any(found):
            return "no route (independent check agrees)"
        return f"independent check DISAGREES: a 3-D route reaches {sum(found)} of {len(goals)} coverage ends"

    def _calm(self) -> bool:
        """The reference is not manoeuvring hard (a rejoin from a hard manoeuvre overshoots)."""
        a, j = self.shaper.a, self.shaper.j
        return max(abs(x) for x in a) <= CALM_FRACTION * self.cfg.accel_m_s2 and \
            max(abs(x) for x in j) <= CALM_FRACTION * self.cfg.jerk_m_s3

    def _on_free_cell(self, x: float, y: float) -> bool:
        """(x, y) (ENU m) is over a free cell of the map (not a row, not unknown, not off the map)."""
        cell = self.known.cell_of(x, y)
        return cell is not None and bool(self.known.free.free[cell])

    def _ceiling_z(self, x: float, y: float) -> float:
        return self.known.ground_z(x, y) + self.cfg.ceiling_agl_m

    def _floor_z(self, x: float, y: float) -> float:
        """Lowest a rejoin candidate may go: the airframe's radius above the terrain."""
        return self.known.ground_z(x, y) + (self.cfg.body_radius_m or 0.0)

    def _try_rejoin(self, tau: float, events: list) -> RefSample | None:
        st = self.shaper.state()
        plan = self.plan
        P = np.asarray(st.p)
        A, B, u, n = self._leg_frame(self._avoid_leg)
        # way-points of earlier legs are behind, whatever their projection on this one:
        # from the visit of this leg's start corner that this passage made (searching
        # from the leave way-point matched a re-route's later back-track through the
        # same corner and skipped 12 way-points, a whole corridor, unreported)
        start = max(self._wp_leave, self._leg_wp)
        first = first_waypoint_ahead(plan, start, P, u, self.speed_m_s, self.cfg.vertical_speed_m_s)
        res = rejoin(plan, st, tau, first, self.memory.points(), self._keep_m,
                     self.cfg.jerk_m_s3, self.cfg.vertical_speed_m_s, self._ceiling_z, self._on_free_cell,
                     self._floor_z, self.cfg.lateral_limit_m)
        paced, _, added = (None, None, 0.0) if res.plan is None else self._paced(res.plan, st, plan)
        if paced is None or self._retriggers(paced, tau):
            self._next_rejoin = tau + REJOIN_RETRY_S
            return None
        res = replace(res, plan=paced)
        self._set_plan(res.plan)
        # the lateral deviation of the rejoin: from the avoidance's legs, and from its
        # own chord when the first way-point kept lies off them (the plan's end, in a
        # headland after a re-route: 1.5 m off the legs, not a swerve)
        w = np.asarray(res.plan.p_enu_m[1][:2], dtype=float)
        if self._dev_leg is None or min(_segment_distance(w, a, b) for a, b in self._dev_leg) > GOAL_REACHED_M:
            chord = (P[:2].copy(), w.copy())
            if self._dev_leg is None:
                self._dev_avoided = 0
            self._dev_leg = (chord,) if self._dev_leg is None else (*self._dev_leg, chord)
        self.mode = "rejoin"
        self._mode_until = float(res.plan.t_s[1])
        paced = f", paced +{added:.1f} s" if added > 0.0 else ""
        self._event(events, "rejoin", None, f"LQR re-solved through {len(res.plan.t_s) - 1} way-points{paced}")
        skip = rejoin_skip(plan, start, first, P, u)
        if skip is not None:
            self._skip(events, *skip, "rejoin")
        s = self._cursor.sample(tau)
        return RefSample(s.p, s.v, s.a, s.jerk, s.snap, _pointing(s.p, self._target))

    def _retriggers(self, plan: GlobalPlan, tau: float) -> bool:
        """The follow mode's trigger, exactly as ``_follow`` will apply it to ``plan`` (its
        samples, its legs), fires within its first ``REJOIN_QUIET_S``. Such a rejoin would be
        an avoidance again at once: the admission's own test looked along the avoided leg,
        while follow looks along the new plan's (fresh seed 20261152 of obstacles-wide, flight
        0: at rest, the leg nearest was the next one, run the other way, so the post ahead
        was "behind"; the rejoin stepped toward it, follow stopped for it, and the two
        alternated for 116 s)."""
        cur = TrajectoryCursor(plan.trajectory)
        for k in range(int(round(REJOIN_QUIET_S / REJOIN_CHECK_DT_S)) + 1):
            s = cur.sample(min(tau + k * REJOIN_CHECK_DT_S, cur.tf))
            if self._threat(s.p, s.v, lambda s=s: plan.leg_frame(plan.leg_near(s.p, s.v[:2]))[2]) is not None:
                return True
        return False

    # --- statistics ---------------------------------------------------------------------

    def _deviation(self, p) -> None:
        if self._dev_leg is None:
            return
        lat = lateral_offset(p, self._dev_leg, self._dev_avoided)
        if lat > self._max_lat:
            self._max_lat = lat
        agl = p[2] - self.known.ground_z(p[0], p[1])
        if self._max_agl is None or agl > self._max_agl:
            self._max_agl = float(agl)

    def _max_climb(self) -> float:
        """The reference's largest height above the planned flight height while avoiding and
        rejoining (0 when it never rose above it; every plan, re-routes too, flies one height)."""
        return 0.0 if self._max_agl is None else max(0.0, self._max_agl - self.plan.flight.height_agl_m)

    def _account(self, ref: RefSample) -> None:
        p = ref.p
        q = self._p_prev
        if q is not None:
            self._flown += math.sqrt((p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2 + (p[2] - q[2]) ** 2)
        self._p_prev = p
        pts = self._points()
        if len(pts) and (self._min_range is None or self.memory.points_lower_bound(p) < self._min_range):
            d = float(np.sqrt(np.min(np.einsum("ki,ki->k", pts - p, pts - p))))
            if self._min_range is None or d < self._min_range:
                self._min_range = d
