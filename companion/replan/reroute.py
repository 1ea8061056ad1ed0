"""Re-route around an obstacle the vehicle cannot pass (issue 8: stop, add the
obstacle to the map, fly the rest of the blocked corridor from its other
end, re-plan the remaining coverage from the current state).

Steps of ``reroute`` (pure: maps, plan and state in, a new plan out):

1. The obstacle's points (the face the sensors saw, extended by the assumed
   depth along the direction of travel) are added to the map (the map
   returned); the route is planned on that map with every other obstacle
   the vehicle knows at the route's height added too (``others_enu_m``: the
   route is planned in 2-D at that height, and the guard checks it in 3-D
   against the same obstacles). The eroded free space loses every cell
   within ``keep_m`` (the clearance plus the vehicle's body radius, at least
   the map's own erosion threshold) of them. The others stay out of the
   returned map: the avoidance goes on reacting to them in flight.
2. What is left to cover: the rest of the current main segment beyond the
   obstacle (its free runs past the vehicle, each at least the minimum
   segment length) flown *from the segment's far end back toward the
   obstacle*, then the main segments not yet started, in their planned
   order, each cut into its free runs in the updated map and entered by
   its end nearer to where the previous one ended (straight line): the
   planned directions were chosen for the planned order, which the
   re-route has broken, and the connection would otherwise often fly the
   whole piece once to reach its far end.
3. The route: from the vehicle straight back along its track (or, when
   that finds no free space, or the leg would pass closer to the obstacle
   than the vehicle is, straight away from the obstacle, or else to the
   nearest free cell such a leg reaches) to the first point of the eroded
   free space (the vehicle stopped within the margin of the obstacle) *in a
   component of it that holds a piece left to cover* (in a headland the
   obstacle's margin and the field boundary's can close a small pocket of
   free space around the vehicle: starting there, no piece is reachable
   although the track it came along is open), then
   an auxiliary connection (``coverage.gridpath.aux_path``:
   straight where clear, else the shortest grid path) to each piece in
   turn, in the free space eroded by ``CONNECTION_MARGIN_M`` more where
   that connects (a shortest connection grazes the eroded space's edge at a
   row's end, and the LQR's soft corners cut it by millimetres), else in the
   eroded free space itself; a piece that cannot be reached is skipped
   (counted).
4. The route's height: the plan's above the terrain, lifted over the known
   obstacles it passes (``over``, ``lift``: a way back over a low crate the
   vehicle climbed flies over it again); then way-points along the route
   (``coverage.waypoints.waypoints_along``), the
   first one replaced by the current reference position (the vehicle may
   have climbed: the first interval is stretched for the descent at the
   vertical speed), and the LQR from the current state (``initial_state``).

No piece reachable while some are left, or no free space to back off into:
no route (the caller holds and reports).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage

from ..coverage.freespace import dilate_runs, disk_half_widths, grid_to_world, lookup, world_to_grid
from ..coverage.gridpath import aux_path
from ..coverage.waypoints import waypoints_along
from mavcore.errors import InputError
from ..trajectory import generate_trajectory
from .globalplan import GlobalPlan
from .knownmap import KnownMap
from .lift import Over, lift

#: Farthest (m) the route may back off along the track to reach free space.
MAX_BACK_OFF_M = 5.0
#: Connections between pieces keep this much (m) more from the rows and obstacles where they can.
CONNECTION_MARGIN_M = 0.1
#: Route points closer than this (m) are merged.
_MERGE_M = 0.05
_QUINTIC_PEAK_V = 1.875


@dataclass(frozen=True)
class RerouteResult:
    """Outcome of ``reroute``.

    Attributes
    ----------
    plan : GlobalPlan or None
        The re-planned coverage (None: no route).
    known : KnownMap
        The map with the obstacle added (also when there is no route).
    reason : str
        "" on success, else why there is no route.
    n_pieces : int
        Coverage pieces in the new plan.
    n_skipped : int
        Pieces left out because they cannot be reached.
    path_xy_m : (m, 2) array
        The new route's turning points (ENU m; empty without a route).
    skipped : tuple of (from_s, to_s, length_m, reason)
        Coverage of the plan left out (``coverage_skipped`` in report.json): the
        stretches of the remaining main segments outside the pieces flown (the
        obstacle's footprint and its margin, runs shorter than the minimum
        segment: ``"blocked"``) and the pieces that cannot be reached
        (``"unreachable"``); times on the plan's clock, linear along each
        segment between its end way-points.
    """

    plan: GlobalPlan | None
    known: KnownMap
    reason: str
    n_pieces: int
    n_skipped: int
    path_xy_m: np.ndarray
    skipped: tuple = ()


def obstacle_footprint(points_enu_m: np.ndarray, travel_xy: np.ndarray, depth_m: float,
                       step_m: float) -> np.ndarray:
    """(m, 2) the points' xy plus copies every ``step_m`` up to ``depth_m`` further
    along the unit direction of travel ``travel_xy`` (the unseen back of the obstacle)."""
    xy = np.asarray(points_enu_m, dtype=float).reshape(-1, 3)[:, :2]
    steps = np.arange(0.0, depth_m + 1e-9, step_m)
    u = np.asarray(travel_xy, dtype=float)
    return (xy[:, None, :] + steps[None, :, None] * u[None, None, :]).reshape(-1, 2)


def with_blocking(known: KnownMap, obstacle_enu_m: np.ndarray, seen_from_xy, travel_xy, depth_m: float,
                  keep_m: float | None = None, voxel_m: float | None = None) -> KnownMap:
    """``known`` with the blocking obstacle added (step 1 of the module doc): the cells
    under its points and under their copies up to ``depth_m`` further along the
    direction from ``seen_from_xy`` (where the vehicle saw it from) to its nearest point
    (``travel_xy`` when that is undefined). Each column's top is the upper face of the
    map voxel (``voxel_m``) holding the point it comes from, the obstacle as the
    obstacle map and the 3-D route search hold it; without ``voxel_m`` unknown (+inf).
    (Seen from the 3-D route's far end, the assumed depth once grew toward the vehicle
    and the columns, of any height, stood under a vehicle stopped over the obstacle's
    top: the guard refused every route from there, "contact" at its first sample.)"""
    obs = np.asarray(obstacle_enu_m, dtype=float).reshape(-1, 3)
    toward = np.asarray(travel_xy, dtype=float)
    toward = toward / max(float(np.hypot(*toward)), 1e-12)
    p = np.asarray(seen_from_xy, dtype=float)[:2]
    if len(obs):
        d = obs[np.argmin(np.hypot(*(obs[:, :2] - p).T)), :2] - p
        if np.hypot(*d) > 1e-6:
            toward = d / np.hypot(*d)
    step = 0.5 * known.free.resolution_m
    foot = obstacle_footprint(obs, toward, depth_m, step)
    tops = None
    if voxel_m is not None and len(obs):
        n = len(foot) // len(obs)
        tops = np.repeat((np.floor(obs[:, 2] / voxel_m) + 1.0) * voxel_m, n)
    return known.with_obstacle(foot, keep_m, tops)


def free_runs(known: KnownMap, a_xy, b_xy) -> list[tuple[float, float]]:
    """Runs [s0, s1] (m from ``a_xy``) of the segment a-b inside the eroded free space.

    The segment is sampled every half cell; a run spans its free samples.
    """
    a, b = np.asarray(a_xy, dtype=float), np.asarray(b_xy, dtype=float)
    L = float(np.hypot(*(b - a)))
    h = known.free.resolution_m
    n = max(2, int(np.ceil(L / (0.5 * h))) + 1)
    s = np.linspace(0.0, L, n)
    pts = a + (s / max(L, 1e-12))[:, None] * (b - a)
    g = world_to_grid(known.grid, pts)
    ok = lookup(known.free.eroded, h, g[:, 0], g[:, 1])
    runs = []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    for i0, i1 in zip(edges[0::2], edges[1::2]):
        runs.append((float(s[i0]), float(s[i1 - 1])))
    return runs


def _labels_at(known: KnownMap, labels: np.ndarray, pts_xy: np.ndarray) -> np.ndarray:
    """Component label of the eroded cell under each point (0: not eroded free or off the map)."""
    g = world_to_grid(known.grid, np.asarray(pts_xy, dtype=float).reshape(-1, 2))
    return lookup(labels, known.free.resolution_m, g[:, 0], g[:, 1])


def back_off(known: KnownMap, p_xy, direction_xy, max_m: float = MAX_BACK_OFF_M,
             labels: np.ndarray | None = None, wanted=None) -> np.ndarray | None:
    """First point of the eroded free space from ``p_xy`` along ``-direction_xy`` (ENU m), or None.

    With ``labels`` (the eroded space's components) and ``wanted`` (a set of
    labels), only points of those components count."""
    p = np.asarray(p_xy, dtype=float)
    u = np.asarray(direction_xy, dtype=float)
    h = known.free.resolution_m
    s = np.arange(0.0, max_m + 1e-9, 0.5 * h)
    pts = p - s[:, None] * u
    g = world_to_grid(known.grid, pts)
    free = lookup(known.free.eroded, h, g[:, 0], g[:, 1])
    if labels is not None and wanted:
        free &= np.isin(_labels_at(known, labels, pts), list(wanted))
    ok = np.flatnonzero(free)
    if len(ok) == 0:
        return None
    # one more half cell inside when it is free too, so the connection starts well in free space
    k = int(ok[0])
    return pts[k + 1] if k + 1 < len(s) and free[k + 1] else pts[k]


def nearest_free(known: KnownMap, p_xy, points_xy: np.ndarray, keep_m: float,
                 max_m: float = MAX_BACK_OFF_M, tries: int = 400, labels: np.ndarray | None = None,
                 wanted=None) -> np.ndarray | None:
    """The nearest centre of an eroded free cell within ``max_m`` of ``p_xy`` (ENU m)
    reached by a straight leg clear of the obstacle points (``_segment_clear_of``)
    and over the map's free cells (no row crossed); with ``labels``/``wanted``
    only cells of those components. None if none of the ``tries`` nearest is."""
    grid = known.grid
    h = known.free.resolution_m
    rc = known.cell_of(float(p_xy[0]), float(p_xy[1]))
    if rc is None:
        return None
    k = int(np.ceil(max_m / h))
    r0, c0 = max(0, rc[0] - k), max(0, rc[1] - k)
    win = known.free.eroded[r0:rc[0] + k + 1, c0:rc[1] + k + 1]
    rows, cols = np.nonzero(win)
    if len(rows) == 0:
        return None
    if labels is not None and wanted:
        keep = np.isin(labels[rows + r0, cols + c0], list(wanted))
        rows, cols = rows[keep], cols[keep]
    x, y = grid.cell_to_world(rows + r0, cols + c0)
    cand = np.column_stack([x, y])
    d = np.hypot(*(cand - np.asarray(p_xy, dtype=float)).T)
    for i in np.argsort(d)[:tries]:
        if d[i] > max_m:
            break
        if _segment_clear_of(p_xy, cand[i], points_xy, keep_m) and _over_free_cells(known, p_xy, cand[i]):
            return cand[i]
    return None


def _over_free_cells(known: KnownMap, a, b) -> bool:
    """The straight leg a-b (ENU xy) stays over free (non-row, known) cells of the map,
    sampled every half cell; the cell under ``a`` is not asked (the vehicle is there)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    h = known.free.resolution_m
    n = max(2, int(np.ceil(np.hypot(*(b - a)) / (0.5 * h))) + 1)
    pts = a + np.linspace(0.0, 1.0, n)[1:, None] * (b - a)
    g = world_to_grid(known.grid, pts)
    return bool(lookup(known.free.free, h, g[:, 0], g[:, 1]).all())


def _snap(known: KnownMap, xy) -> np.ndarray:
    """The centre of the eroded cell holding ``xy`` (ENU m), or ``xy`` if that cell is
    not eroded: a point sampled on a run's boundary may fall on either side
    of a cell edge by rounding, and the connection search wants eroded ends."""
    xy = np.asarray(xy, dtype=float)
    cell = known.cell_of(float(xy[0]), float(xy[1]))
    if cell is None or not known.free.eroded[cell]:
        return xy
    x, y = known.grid.cell_to_world(cell[0], cell[1])
    return np.array([float(x), float(y)])


def _connect(frees: list, grid, a_xy, b_xy) -> np.ndarray:
    """The connection from a to b (ENU m) in the first of ``frees`` that holds one
    (``aux_path``); InputError when none does."""
    err = None
    for free in frees:
        try:
            return aux_path(free, world_to_grid(grid, a_xy), world_to_grid(grid, b_xy))
        except InputError as exc:
            err = exc
    raise err


def _narrowed(free, margin_m: float):
    """``free`` with its eroded space eroded by ``margin_m`` more (the closed disk of
    ``ceil(margin_m / h)`` cells: for integer offsets the open disk of ``freespace``'s
    ``disk_half_widths`` with radius ``sqrt(r^2 + 1)``; off the grid counts as blocked)."""
    r = int(np.ceil(margin_m / free.resolution_m - 1e-9))
    if r <= 0:
        return free
    blocked = dilate_runs(~free.eroded, disk_half_widths(math.sqrt(r * r + 1)), outside=True)
    return replace(free, eroded=free.eroded & ~blocked)


def _min_keep(keep_m: float | None, known: KnownMap) -> float:
    """What the back-off leg must keep from the obstacle: half the route's margin
    (the vehicle stopped within it; it must not go closer)."""
    return 0.5 * (keep_m if keep_m is not None else known.free.threshold_m)


def _segment_clear_of(a, b, points_xy: np.ndarray, keep_m: float) -> bool:
    """True when the straight segment a-b (ENU xy) keeps ``keep_m`` from every point,
    or gets no closer to them than ``a`` is."""
    if len(points_xy) == 0:
        return True
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    ab = b - a
    L2 = max(float(ab @ ab), 1e-18)
    t = np.clip(((points_xy - a) @ ab) / L2, 0.0, 1.0)
    d = np.hypot(*(a + t[:, None] * ab - points_xy).T)
    return bool(d.min() >= min(keep_m, float(np.hypot(*(points_xy - a).T).min()) - 1e-9))


def _merge(points: list) -> np.ndarray:
    out = [np.asarray(points[0], dtype=float)]
    for q in points[1:]:
        q = np.asarray(q, dtype=float)
        if np.hypot(*(q - out[-1])) > _MERGE_M:
            out.append(q)
    return np.array(out)


#: Stretches of a segment left out shorter than this (m) are not reported (sampling: half a cell).
GAP_REPORT_M = 0.3


def _segment_frame(plan: GlobalPlan, seg):
    """(start (2,), unit direction (2,), length, s -> plan time) of a main segment."""
    a, b = np.asarray(seg.start_xy, dtype=float), np.asarray(seg.end_xy, dtype=float)
    L = max(float(np.hypot(*(b - a))), 1e-12)
    t_a, t_b = float(plan.t_s[seg.first_wp]), float(plan.t_s[seg.last_wp])
    return a, (b - a) / L, L, lambda s: t_a + (t_b - t_a) * min(max(s / L, 0.0), 1.0)


def _gaps(s_from: float, L: float, runs, at) -> list[tuple]:
    """The stretches of [s_from, L] outside ``runs`` ((s0, s1) pairs), as
    (from_s, to_s, length_m, "blocked"), those of at least ``GAP_REPORT_M``."""
    out, cur = [], s_from
    for s0, s1 in sorted(runs) + [(L, L)]:
        if s0 - cur >= GAP_REPORT_M:
            out.append((at(cur), at(s0), float(s0 - cur), "blocked"))
        cur = max(cur, s1)
    return out


def reroute(plan: GlobalPlan, known: KnownMap, state, t_now_s: float, wp_index: int,
            obstacle_enu_m: np.ndarray, travel_xy, depth_m: float, vertical_speed_m_s: float,
            keep_m: float | None = None, others_enu_m: np.ndarray | None = None,
            over: Over | None = None, seen_from_xy=None, voxel_m: float | None = None) -> RerouteResult:
    """Re-plan the remaining coverage around a blocking obstacle (module doc).

    Parameters
    ----------
    plan : GlobalPlan
        The plan being flown when the vehicle left it.
    known : KnownMap
    state : object with p, v, a, jerk (ENU 3-sequences)
        The reference state (at rest after the stop).
    t_now_s : float
        Plan-clock time the new plan starts.
    wp_index : int
        Last way-point of ``plan`` passed when the vehicle left it.
    obstacle_enu_m : (k, 3) array
        Points of the blocking obstacle.
    travel_xy : (2,) unit direction of travel when the obstacle stopped the vehicle
        (ENU): the route backs off the other way (the track it came along) or,
        when that finds no free space clear of the obstacle, away from the
        obstacle; the assumed depth extends from the vehicle through the obstacle.
    depth_m : float
        Assumed depth of the obstacle behind the seen face (m).
    vertical_speed_m_s : float
        Speed allotted to a descent on the first interval.
    keep_m : float, optional
        Distance the route keeps from the obstacle (m; the replanner's
        clearance plus the body radius); default the map's erosion threshold.
    others_enu_m : (j, 3) array, optional
        The other known obstacle points at the route's height (kept from as far,
        without the assumed depth).
    over : lift.Over, optional
        The known obstacles the route is lifted over where it passes them (``lift``).
    seen_from_xy : (2,) optional
        Where the vehicle saw the obstacle from (default ``state.p``): the assumed
        depth extends away from it (``with_blocking``).
    voxel_m : float, optional
        The obstacle map's voxel: the added columns' tops (``with_blocking``).
    """
    travel = np.asarray(travel_xy, dtype=float)
    travel = travel / max(float(np.hypot(*travel)), 1e-12)
    p = np.asarray(state.p, dtype=float)
    obs = np.asarray(obstacle_enu_m, dtype=float).reshape(-1, 3)
    toward = travel                 # from the route's start to the obstacle: the way to back off from it
    if len(obs):
        d = obs[np.argmin(np.hypot(*(obs[:, :2] - p[:2]).T)), :2] - p[:2]
        if np.hypot(*d) > 1e-6:
            toward = d / np.hypot(*d)
    seen = p[:2] if seen_from_xy is None else seen_from_xy
    known_out = with_blocking(known, obs, seen, travel, depth_m, keep_m, voxel_m)
    new_known = known_out           # the map the route is planned on: with the other obstacles too
    if others_enu_m is not None and len(others_enu_m):
        new_known = known_out.with_obstacle(np.asarray(others_enu_m, dtype=float).reshape(-1, 3)[:, :2], keep_m)

    def fail(reason: str) -> RerouteResult:
        return RerouteResult(None, known_out, reason, 0, 0, np.zeros((0, 2)))

    # what is left to cover, in flight order: (entry, exit) pairs (ENU xy), their plan times
    pieces: list[tuple[np.ndarray, np.ndarray]] = []
    times: list[tuple[float, float]] = []
    gaps: list[tuple] = []
    min_len = plan.min_segment_m
    current, nxt = plan.segment_at(wp_index)
    if current is not None:
        seg = plan.segments[current]
        a, u, L, at = _segment_frame(plan, seg)
        s_v = min(max(float((p[:2] - a) @ u), 0.0), L)
        beyond = [(s0, s1) for s0, s1 in free_runs(new_known, a, a + L * u) if s0 > s_v and s1 - s0 >= min_len]
        gaps += _gaps(s_v, L, beyond, at)
        for s0, s1 in sorted(beyond, reverse=True):       # from the far end back toward the obstacle
            pieces.append((a + s1 * u, a + s0 * u))
            times.append((at(s0), at(s1)))
    n_forced = len(pieces)
    for seg in plan.segments[nxt:]:
        a, u, L, at = _segment_frame(plan, seg)
        runs = [(s0, s1) for s0, s1 in free_runs(new_known, a, a + L * u) if s1 - s0 >= min_len]
        gaps += _gaps(0.0, L, runs, at)
        for s0, s1 in runs:
            pieces.append((a + s0 * u, a + s1 * u))
            times.append((at(s0), at(s1)))

    # the start: in a component of the eroded free space that holds a piece left
    labels, _ = ndimage.label(new_known.free.eroded)
    ends = [np.asarray(q, dtype=float) for piece in pieces for q in piece]
    wanted = set(int(x) for x in _labels_at(new_known, labels, np.array(ends).reshape(-1, 2))) - {0} if ends else set()
    start = None
    keep_back = _min_keep(keep_m, new_known)
    for direction in (travel, toward):
        cand = back_off(new_known, p[:2], direction, labels=labels, wanted=wanted)
        if cand is not None and _segment_clear_of(p[:2], cand, obs[:, :2], keep_back) \
                and _over_free_cells(new_known, p[:2], cand):
            start = cand
            break
    if start is None:
        start = nearest_free(new_known, p[:2], obs[:, :2], keep_back, labels=labels, wanted=wanted,
                             tries=2000)
    if start is None and wanted:
        return fail(f"none of the {len(pieces)} coverage pieces left can be reached: no free space "
                    f"connected to them within {MAX_BACK_OFF_M:g} m of the vehicle")
    if start is None:
        return fail(f"no free space within {MAX_BACK_OFF_M:g} m behind the vehicle or away from the obstacle")

    grid = new_known.grid
    frees = [_narrowed(new_known.free, CONNECTION_MARGIN_M), new_known.free]
    route = [p[:2], start]
    cur = start
    flown = []
    skipped = 0
    cur = _snap(new_known, cur)
    for k, (entry, exit_) in enumerate(pieces):
        if k >= n_forced and np.hypot(*(exit_ - cur)) < np.hypot(*(entry - cur)):
            entry, exit_ = exit_, entry           # enter a free piece by its nearer end
        entry, exit_ = _snap(new_known, entry), _snap(new_known, exit_)
        try:
            conn = _connect(frees, grid, cur, entry)
        except InputError:
            skipped += 1
            t0, t1 = sorted(times[k])
            gaps.append((t0, t1, float(np.hypot(*(exit_ - entry))), "unreachable"))
            continue
        route.extend(grid_to_world(grid, conn)[1:])
        route.append(exit_)
        flown.append((entry, exit_))
        cur = exit_
    if pieces and not flown:
        return fail(f"none of the {len(pieces)} coverage pieces left can be reached")
    path = _merge(route)
    if len(path) < 2:
        path = np.array([p[:2], p[:2] - 0.1 * travel])      # nothing left: settle just behind
    terrain = new_known.dem
    if over is not None:
        lifted = lift(path, terrain, plan.flight.height_agl_m, over)
        if lifted is None:
            return fail("the route would have to fly above the ceiling over a known obstacle")
        path, terrain = lifted
    try:
        wps = waypoints_along(path, terrain, plan.flight)
        t = wps.t_s.copy()
        P = wps.p_enu_m.copy()
        dz = abs(float(P[0, 2] - p[2]))
        extra = max(0.0, _QUINTIC_PEAK_V * dz / vertical_speed_m_s - t[1])
        t[1:] += extra
        P[0] = p
        x0 = np.array([state.p, state.v, state.a, state.jerk], dtype=float)
        traj = generate_trajectory(t + t_now_s, P, wps.v_enu_m_s, wps.a_enu_m_s2, plan.trajectory_config,
                                   initial_state=x0, target_enu_m=plan.target_enu_m)
    except InputError as exc:
        return fail(f"re-planning failed: {exc}")
    segs = np.array([[e, x] for e, x in flown], dtype=float).reshape(-1, 2, 2)
    new_plan = GlobalPlan.from_waypoints(traj, t + t_now_s, P, wps.v_enu_m_s, wps.a_enu_m_s2, wps.corner, segs,
                                         plan.target_enu_m, plan.flight, plan.trajectory_config,
                                         plan.min_segment_m, tuple(path[-1]))
    return RerouteResult(new_plan, known_out, "", len(flown), skipped, path, tuple(sorted(gaps)))
