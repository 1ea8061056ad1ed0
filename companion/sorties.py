"""Battery-sized sorties from and back to a launch point (pure).

The coverage route is a chain ``m_0, c_0, m_1, c_1, ..., m_{k-1}`` of main
segments (corridors) and auxiliary connections. A sortie flies a run of
consecutive main segments ``m_s .. m_e`` with the connections between them,
reached from the launch point ``L`` by a transit in the eroded free space
(``coverage.transit``: one shortest-path tree from ``L`` serves every
transit; it never crosses a vine row) at ``flight.transit_speed_m_s``, and
closed by the transit back to ``L``. The way out of a sortie that starts
where the previous one ended is that sortie's way back, reversed, plus the
route's own connection to the next corridor. Sorties therefore split the route at corridor
ends, and every corridor is flown whole in exactly one sortie.

Greedy split: from the first unflown segment, add segments while the
sortie's estimated energy stays within the usable battery
(``energy.usable_wh``) and its mission within ``energy.max_mission_items``.
The estimate times every straight run as the way-points will
(``coverage.waypoints.run_duration_s``) at the cruise power of
``mavcore.energy``, and the transits by their length in the transit
tree plus ``_TRANSIT_STOPS`` stops. Then
the sortie's real path is built, its way-points placed and its energy
computed exactly (``energy.flight_energy``); if that breaks a limit the
sortie gives back its last segment and is rebuilt.

Each sortie's mission is ``SORTIE_OVERHEAD_ITEMS`` items (take-off, speed,
ROI, return) plus its way-points (``companion.mission_items``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from .coverage.freespace import grid_to_world, world_to_grid
from .coverage.transit import build_transit_tree
from .coverage.waypoints import Waypoints, run_duration_s, run_waypoints, waypoints_along
from mavcore.energy import EnergyConfig, EnergyEstimate, cruise_power_w, flight_energy, leg_energy_j
from mavcore.errors import PlanError
from mavcore.maps.grid import mask_centroid_rc
from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig

#: Mission items of a sortie besides its way-points: take-off, ROI, return and the
#: three speed changes (transit, coverage, transit).
SORTIE_OVERHEAD_ITEMS = 6
#: stops (corners) assumed for the two transits of a sortie in the estimate (they have
#: about nine vertices each on the 10 ha benchmark field)
_TRANSIT_STOPS = 16


@dataclass(frozen=True, eq=False)
class Sortie:
    """One battery's flight.

    Attributes
    ----------
    index : int
        1-based.
    segments : (first, last)
        Main segments flown (indices in flight order, inclusive).
    path_xy_m : (K, 2)
        ENU polyline: launch -> transit -> corridors -> transit -> launch.
    waypoints : Waypoints
        Its way-points (times from 0).
    energy : EnergyEstimate
    n_items : int
        Mission items (way-points + ``SORTIE_OVERHEAD_ITEMS``).
    speed_changes : tuple of (way-point index, speed m/s)
        Where the cruise speed changes: the transit speed from way-point 0,
        the coverage speed from the first corridor's start, the transit speed
        again from the last corridor's end.
    """

    index: int
    segments: tuple[int, int]
    path_xy_m: np.ndarray
    waypoints: Waypoints
    energy: EnergyEstimate
    n_items: int
    speed_changes: tuple = ()


@dataclass(frozen=True, eq=False)
class SortiePlan:
    """All sorties of a plan, their launch point and totals."""

    sorties: tuple[Sortie, ...]
    launch_xy_m: np.ndarray
    total_energy_wh: float
    total_duration_s: float


def _join_runs(parts: list[tuple[np.ndarray, float]], tol_m: float = 1e-6):
    """Concatenate polylines (each with its speed) into one path and per-run speeds,
    dropping zero-length runs; also the vertex index where each part starts."""
    pts = [parts[0][0][0]]
    speeds: list[float] = []
    starts = []
    for poly, v in parts:
        starts.append(len(pts) - 1)
        for q in poly[1:]:
            if np.hypot(*(q - pts[-1])) > tol_m:
                pts.append(q)
                speeds.append(v)
    return np.array(pts), np.array(speeds), starts


def _polyline_time_s(path: np.ndarray, flight, speed_m_s: float | None = None) -> float:
    seg = np.hypot(*np.diff(path, axis=0).T)
    seg = seg[seg > 1e-9]
    return float(np.sum(run_duration_s(seg, flight, speed_m_s=speed_m_s)))


def _polyline_items(path: np.ndarray, flight) -> int:
    seg = np.hypot(*np.diff(path, axis=0).T)
    seg = seg[seg > 1e-9]
    return int(np.sum(run_waypoints(seg, flight)))


def _pooled_room(free):
    """The pooled transit cells of ``free`` (``coverage.transit``'s ``min_pool`` of the eroded
    bounding box by ``POOL_M`` blocks): (pooled, p, (r0, r1, c0, c1))."""
    from .coverage.freespace import min_pool
    from .coverage.transit import POOL_M

    p = max(1, int(round(POOL_M / free.resolution_m)))
    r0, r1, c0, c1 = free.bbox_cells
    pooled = min_pool(free.eroded[r0:r1, c0:c1], p) if r1 > r0 else np.zeros((0, 0), dtype=bool)
    return pooled, p, (r0, r1, c0, c1)


def _room_window(pooled_room, a0: int, a1: int, b0: int, b1: int) -> np.ndarray:
    """Rows ``a0:a1``, columns ``b0:b1`` of :func:`transit_room`, from :func:`_pooled_room`
    (each cell reads its pooled block; no full-resolution copy of the grid)."""
    pooled, p, (r0, r1, c0, c1) = pooled_room
    rr, cc = np.arange(a0, a1), np.arange(b0, b1)
    in_r, in_c = (rr >= r0) & (rr < r1), (cc >= c0) & (cc < c1)
    out = np.zeros((len(rr), len(cc)), dtype=bool)
    if pooled.size and in_r.any() and in_c.any():
        pr, pc = (rr[in_r] - r0) // p, (cc[in_c] - c0) // p
        out[np.ix_(in_r, in_c)] = pooled[np.ix_(pr, pc)]
    return out


def transit_room(free) -> np.ndarray:
    """(rows, cols) bool: eroded cells whose pooled transit cell is wholly eroded
    (``coverage.transit``: the blocks of ``POOL_M`` the transit tree is built on,
    aligned on the eroded space's bounding box), so a transit can start there."""
    rows, cols = free.eroded.shape
    return _room_window(_pooled_room(free), 0, rows, 0, cols)


def central_launch_xy(grid, free, bg, route_start_g: np.ndarray) -> np.ndarray:
    """Default launch point (ENU, m): the centre of the eroded cell nearest to the
    centroid of the free cells, in the component of the route (so every corridor
    is at most about half the field away), among the cells a transit can start
    from (:func:`transit_room`; any eroded cell when none has room)."""
    h = free.resolution_m
    rc = np.array(mask_centroid_rc(grid.free))
    comp = bg.components_of(np.array([int(route_start_g[1] // h)]), np.array([int(route_start_g[0] // h)]))[0]
    pooled_room = _pooled_room(free)
    if pooled_room[0].any():        # the room of the window searched, read from the pooled cells
        def room(a0, a1, b0, b1):
            return _room_window(pooled_room, a0, a1, b0, b1)
    else:
        def room(a0, a1, b0, b1):
            return free.eroded[a0:a1, b0:b1]
    rows, cols = free.eroded.shape
    rad = 16
    while True:
        r0, r1 = max(0, int(rc[0]) - rad), min(rows, int(rc[0]) + rad + 1)
        c0, c1 = max(0, int(rc[1]) - rad), min(cols, int(rc[1]) + rad + 1)
        er, ec = np.nonzero(room(r0, r1, c0, c1))
        er, ec = er + r0, ec + c0
        ok = bg.components_of(er, ec) == comp
        if ok.any():
            d2 = (er[ok] - rc[0]) ** 2 + (ec[ok] - rc[1]) ** 2
            i = int(np.argmin(d2))
            # the nearest one found is the nearest overall once the window reaches its distance
            if np.sqrt(d2[i]) <= rad or (r0 == 0 and c0 == 0 and r1 == rows and c1 == cols):
                g = np.array([(ec[ok][i] + 0.5) * h, (er[ok][i] + 0.5) * h])
                return grid_to_world(grid, g)
        if r0 == 0 and c0 == 0 and r1 == rows and c1 == cols:
            return grid_to_world(grid, route_start_g)
        rad *= 2


def _concat(parts: list[Waypoints]) -> Waypoints:
    """Way-point lists joined end to start (each next one starts where the last ended,
    at rest): the shared point kept once, times shifted to follow on."""
    t, p, v, a, c = [parts[0].t_s], [parts[0].p_enu_m], [parts[0].v_enu_m_s], [parts[0].a_enu_m_s2], [parts[0].corner]
    t_end = parts[0].t_s[-1]
    for w in parts[1:]:
        t.append(w.t_s[1:] - w.t_s[0] + t_end)
        p.append(w.p_enu_m[1:])
        v.append(w.v_enu_m_s[1:])
        a.append(w.a_enu_m_s2[1:])
        c.append(w.corner[1:])
        t_end = t[-1][-1] if len(t[-1]) else t_end
    return Waypoints(t_s=np.concatenate(t), p_enu_m=np.vstack(p), v_enu_m_s=np.vstack(v),
                     a_enu_m_s2=np.vstack(a), corner=np.concatenate(c))


def _slice(w: Waypoints, i0: int, i1: int) -> Waypoints:
    return Waypoints(t_s=w.t_s[i0: i1 + 1] - w.t_s[i0], p_enu_m=w.p_enu_m[i0: i1 + 1],
                     v_enu_m_s=w.v_enu_m_s[i0: i1 + 1], a_enu_m_s2=w.a_enu_m_s2[i0: i1 + 1],
                     corner=w.corner[i0: i1 + 1])


def _corner_indices(w: Waypoints, points_xy: np.ndarray) -> np.ndarray:
    """Index of the corner way-point at each point (ENU xy), -1 where there is none
    (a segment end merged into a straight run).

    The corners are sorted by x and each point looks only at those within the
    1 um tolerance in x: the same corners as a nearest-neighbour query
    (``scipy.spatial.cKDTree``, whose import alone is 0.2 s of ``companion plan``).
    """
    tol = 1e-6
    corners = np.flatnonzero(w.corner)
    c = w.p_enu_m[corners, :2]
    order = np.argsort(c[:, 0], kind="stable")
    xs = c[order, 0]
    pts = np.asarray(points_xy, float).reshape(-1, 2)
    lo = np.searchsorted(xs, pts[:, 0] - tol, side="left")
    hi = np.searchsorted(xs, pts[:, 0] + tol, side="right")
    out = np.full(len(pts), -1, dtype=np.int64)
    for k in np.flatnonzero(hi > lo):
        cand = order[lo[k]: hi[k]]
        diff = c[cand] - pts[k]
        d = np.sqrt(np.sum(diff * diff, axis=1))
        best = int(np.argmin(d))
        if d[best] < tol:
            out[k] = corners[cand[best]]
    return out


def plan_sorties(coverage, waypoints: Waypoints, dem, flight, vehicle: VehicleConfig, cfg: EnergyConfig,
                 grid, source: str = "<mission>", launch_key: str = "energy.launch_xy_m") -> SortiePlan:
    """Split a coverage plan into sorties (module doc).

    Parameters
    ----------
    coverage : CoveragePlan
        With ``main_segments``, ``aux_paths`` (world ENU) and ``free_space``.
    waypoints : Waypoints
        The whole route's way-points: a sortie's corridors are a slice of them.
    dem, flight, vehicle, cfg, grid
        Terrain, flight settings, vehicle, energy settings, occupancy grid.
    source : str
        The mission file (messages name its keys).
    launch_key : str
        The mission key that gave ``cfg.launch_xy_m`` (``launch`` or ``energy.launch_xy_m``).

    Raises
    ------
    PlanError
        The launch point is not in the eroded free space (or cannot reach the
        corridors), or a single corridor needs more energy or mission items
        than one sortie allows.
    """
    free = coverage.free_space
    h = free.resolution_m
    mains = [np.asarray(m, dtype=float) for m in coverage.main_segments]
    auxs = [np.asarray(a, dtype=float) for a in coverage.aux_paths]
    k = len(mains)
    bg = free.block_graph()
    if cfg.launch_xy_m is None:
        launch = central_launch_xy(grid, free, bg, world_to_grid(grid, mains[0][0]))
    else:
        launch = np.asarray(cfg.launch_xy_m, dtype=float)
    key = f"{source}: key '{launch_key}'"
    lg = world_to_grid(grid, launch)
    if bg.sub_at(int(lg[1] // h), int(lg[0] // h)) == 0:
        raise PlanError(key, f"({launch[0]:.2f}, {launch[1]:.2f}) m is not in the free space "
                             f"eroded by the airframe radius + the safety margin")
    tree = build_transit_tree(free, lg, source)
    if tree.distance_m(lg) == np.inf:
        raise PlanError(key, f"({launch[0]:.2f}, {launch[1]:.2f}) m has no room around it in the eroded "
                             f"free space for a transit")

    def transit_estimates(p_world: np.ndarray) -> np.ndarray:
        d = tree.distances_m(world_to_grid(grid, p_world))
        for j, p in enumerate(p_world):
            if not np.isfinite(d[j]):     # a narrow passage: the exact search will find it
                d[j] = float(np.hypot(*(p - launch))) * 2.0
        return np.array(d)

    V, Vt = flight.speed_m_s, flight.transit_speed_m_s
    p_transit = float(cruise_power_w(Vt, vehicle, cfg))
    t_acc_t = 1.875 * Vt / 0.5
    i_start = _corner_indices(waypoints, np.array([m[0] for m in mains]))
    i_end = _corner_indices(waypoints, np.array([m[-1] for m in mains]))
    e_cum = np.concatenate([[0.0], np.cumsum(leg_energy_j(waypoints.t_s, waypoints.p_enu_m, vehicle, cfg))])
    out_d = transit_estimates(np.array([m[0] for m in mains]))
    back_d = transit_estimates(np.array([m[-1] for m in mains]))
    weight = vehicle.mass_kg * GRAVITY_M_S2
    vertical_j = (2 * flight.height_agl_m / cfg.climb_speed_m_s * float(cruise_power_w(0.0, vehicle, cfg))
                  + weight * flight.height_agl_m / cfg.drive_efficiency)
    budget_j = cfg.usable_wh * 3600.0
    limit = cfg.max_mission_items - SORTIE_OVERHEAD_ITEMS
    n_wp = np.arange(len(waypoints.t_s))

    def coverage_part(s: int, e: int) -> tuple[float, int]:
        """Exact energy (J) and way-points of the corridors s..e, from the route's way-points."""
        a, b = i_start[s], i_end[e]
        if a < 0 or b < 0 or b < a:
            t = sum(_polyline_time_s(m, flight) for m in mains[s: e + 1]) + \
                sum(_polyline_time_s(x, flight) for x in auxs[s:e])
            n = sum(_polyline_items(m, flight) for m in mains[s: e + 1]) + \
                sum(_polyline_items(x, flight) for x in auxs[s:e])
            return float(cruise_power_w(V, vehicle, cfg)) * t, int(n)
        return float(e_cum[b] - e_cum[a]), int(n_wp[b] - n_wp[a] + 1)

    def estimate(s: int, e: int) -> tuple[float, int]:
        j, n = coverage_part(s, e)
        # the transits: their length at the transit speed, and their stops (each costs t_acc)
        j += p_transit * ((out_d[s] + back_d[e]) / Vt + _TRANSIT_STOPS * t_acc_t) + vertical_j
        n += int((out_d[s] + back_d[e]) / (Vt * flight.waypoint_interval_s)) + 8
        return j, n

    def grow(s: int) -> int:
        """Last segment of the sortie from segment s by the estimate (greedy split)."""
        e = s
        while e + 1 < k:
            j, n = estimate(s, e + 1)
            if j > budget_j or n > limit:
                break
            e += 1
        return e

    # The transits the split will most likely need (by the estimate alone: the first way
    # out and each sortie's way back), string-pulled together in lock step; any other
    # one (a sortie that gives back a segment) is searched when asked for.
    if cfg.split == "none":
        ends = [k - 1]
    else:
        ends, s = [], 0
        while s < k:
            ends.append(grow(s))
            s = ends[-1] + 1
    want = [("out", 0)] + [("back", e) for e in ends]
    pulled = tree.paths_to([world_to_grid(grid, mains[i][0] if kind == "out" else mains[i][-1])
                            for kind, i in want])
    prefetched = dict(zip(want, pulled))
    cache: dict[tuple[str, int], Waypoints] = {}

    def transit(kind: str, i: int) -> tuple[np.ndarray, Waypoints]:
        if (kind, i) not in cache:
            if kind == "out" and ("back", i - 1) in cache:
                # the previous sortie came back from the end of segment i - 1: the way out
                # is that way reversed plus the route's own connection to segment i (no search)
                back_path = cache[("back", i - 1)][0]
                path = np.vstack([back_path[::-1], auxs[i - 1][1:]])
            else:
                path_g = prefetched.pop((kind, i), None)
                if path_g is None:
                    q = mains[i][0] if kind == "out" else mains[i][-1]
                    path_g = tree.path_to(world_to_grid(grid, q))
                path = grid_to_world(grid, path_g)
                path = path if kind == "out" else path[::-1]
            path, _, _ = _join_runs([(path, Vt)])
            if len(path) < 2:
                path = np.vstack([path, path[-1:] + 1e-3])      # launch at the corridor end itself
            cache[(kind, i)] = (path, waypoints_along(path, dem, flight, speeds_m_s=np.full(len(path) - 1, Vt)))
        return cache[(kind, i)]

    def build(s: int, e: int, index: int) -> Sortie:
        (out_p, out_w), (back_p, back_w) = transit("out", s), transit("back", e)
        a, b = i_start[s], i_end[e]
        if a >= 0 and b >= a:
            mid_w = _slice(waypoints, a, b)
            mid_p = None
        else:
            parts = []
            for i in range(s, e + 1):
                parts.append((mains[i], V))
                if i < e:
                    parts.append((auxs[i], V))
            mid_p, speeds, _ = _join_runs(parts)
            mid_w = waypoints_along(mid_p, dem, flight, speeds_m_s=speeds)
        wp = _concat([out_w, mid_w, back_w])
        path = np.vstack([out_p, (mid_w.p_enu_m[mid_w.corner, :2] if mid_p is None else mid_p)[1:], back_p[1:]])
        en = flight_energy(wp.t_s, wp.p_enu_m, flight.height_agl_m, vehicle, cfg)
        n_out, n_mid = len(out_w.t_s), len(mid_w.t_s)
        changes = ((0, Vt), (n_out - 1, V), (n_out + n_mid - 2, Vt))
        return Sortie(index=index, segments=(s, e), path_xy_m=path, waypoints=wp, energy=en,
                      n_items=len(wp.t_s) + SORTIE_OVERHEAD_ITEMS, speed_changes=changes)

    if cfg.split == "none":
        sortie = build(0, k - 1, 1)
        return SortiePlan((sortie,), launch, sortie.energy.energy_wh, sortie.energy.duration_s)

    sorties: list[Sortie] = []
    s = 0
    while s < k:
        e = grow(s)
        while True:
            sortie = build(s, e, len(sorties) + 1)
            if sortie.energy.energy_wh <= cfg.usable_wh and sortie.n_items <= cfg.max_mission_items:
                break
            if e == s:
                what = (f"{sortie.energy.energy_wh:.1f} Wh of {cfg.usable_wh:.1f} Wh usable"
                        if sortie.energy.energy_wh > cfg.usable_wh
                        else f"{sortie.n_items} mission items of {cfg.max_mission_items}")
                raise PlanError(f"{source}: key 'energy'",
                                f"main segment {s} alone needs {what} (with its transits from and back "
                                f"to the launch point): a bigger battery or fewer way-points are needed")
            e -= 1       # the estimate was short: give back the last segment
        sorties.append(sortie)
        s = e + 1
    return SortiePlan(tuple(sorties), launch, float(sum(x.energy.energy_wh for x in sorties)),
                      float(sum(x.energy.duration_s for x in sorties)))
