"""ISOA coverage plan of an occupancy grid (paper Section 2.2).

Pipeline of :func:`plan_coverage` (after Horvath, Pozna & Precup, "Robot
Coverage Path Planning Based on Iterative Structured Orientation", Acta
Polytechnica Hungarica 15(2), 2018):

1. erode the free space by the safety margin (:mod:`freespace`);
2. find the vine rows (:mod:`rows`); the line spacing is the configured one
   or, if unset, the detected row spacing;
3. choose the beam orientation (rule below) and the beam phase that puts
   the lines mid corridor (:mod:`beam`);
4. cut the beam lines into main segments (:mod:`beam`);
5. join them into one boustrophedon path with auxiliary connections
   (:mod:`boustrophedon`, :mod:`gridpath`);
6. measure the corridor coverage (:mod:`corridors`).

Unreachable segments
    Main segments lie in the connected components of the eroded free space
    (:mod:`blockgraph`). The route can only join segments of one component:
    the one holding the most main-segment length is flown, and the segments
    of every other component (a pocket closed off by the safety margin, an
    island of free space) are dropped with a warning naming where they are
    (``CoveragePlan.warnings``, ``dropped_segments``). The plan goes on; its
    coverage fraction shows what is missing.

Orientation rule
    * ``coverage.orientation_deg`` set: that direction, no sweep
      (``orientation_source = "config"``).
    * Otherwise the ISOA sweep always runs and its best direction and score
      are reported (``isoa_orientation_deg``, ``isoa_score_m``). Then, if
      vine rows were detected and the line spacing matches the row spacing
      (given or detected, within ``SPACING_MATCH_REL`` = 5 %), the beam runs
      along the rows' direction (``orientation_source = "rows"``) and its
      phase is taken from the corridor centres: each corridor is then flown
      once, along its whole length, in its middle. ISOA alone cannot
      guarantee that: a beam tilted by a degree or two is cut no more often
      inside a long corridor (the score has a plateau there) yet drifts
      ``L tan(err)`` across it. ``orientation_score_m`` is the ISOA score of
      the flown direction, for comparison with ``isoa_score_m``.
    * With rows but another line spacing, the rows' direction is still
      taken when its score is within 1 % of the sweep's best (inside the
      plateau it is the exact, symmetric choice); otherwise the sweep's
      direction (``orientation_source = "isoa"``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mavcore.errors import PlanError
from mavcore.maps.grid import OccupancyGrid
from mavcore.mission.schema import CoverageConfig
from .beam import beam_phase, corridor_phase, full_scores, isoa_sweep, main_segments
from .boustrophedon import join_segments
from .corridors import coverage_fraction, find_corridors
from .freespace import erode_free_space, grid_to_world
from .rows import WRAP_TOL_DEG, detect_rows

#: relative tolerance within which the line spacing counts as the row spacing
SPACING_MATCH_REL = 0.05
#: the rows' direction is kept (spacing mismatch) when it scores within this share of the best
_ROW_SCORE_REL = 0.99
#: places named in the unreachable-segments warning
_MAX_PLACES = 5


@dataclass(frozen=True, eq=False)
class CoveragePlan:
    """A continuous coverage path over a map, in the map's world ENU frame.

    Attributes
    ----------
    path_xy_m : (N, 2) float
        The boustrophedon path (ENU, m) as a polyline through its turning points.
    orientation_deg : float
        Beam (main line) direction, ENU degrees from east, CCW, in [0, 180).
    line_spacing_m : float
        Distance between beam lines (m): configured, or the detected row spacing.
    main_segments : list of ((x0, y0), (x1, y1))
        Main segments (ENU, m) in flight order, each from its entry to its exit.
    aux_paths : list of (k, 2) float arrays
        Auxiliary connections (ENU, m) in flight order; ``aux_paths[i]`` joins
        the end of main segment i to the start of main segment i + 1.
    free_eroded : (rows, cols) bool
        Free space eroded by the safety margin (grid array convention, row 0 south).
    coverage_fraction : float
        Share of the corridors' centre-line length flown (see :mod:`corridors`).
    path_length_m : float
        Length of ``path_xy_m`` (m).
    row_spacing_m : float or None
        Detected row spacing (m), None if the map shows no periodic rows.
    corridors_xy_m : (k, 2, 2) float
        Corridor centre lines (ENU, m) used by the coverage measure.
    orientation_source : str
        Why ``orientation_deg`` was flown: ``"config"``, ``"rows"`` or
        ``"isoa"`` (module doc, orientation rule).
    isoa_orientation_deg : float or None
        Best direction of the ISOA sweep (ENU deg, [0, 180)); None if forced.
    isoa_score_m : float or None
        ISOA score S (m, :mod:`beam`) of that direction at full resolution.
    orientation_score_m : float or None
        ISOA score of the flown direction; None if forced.
    row_orientation_deg : float or None
        Detected row direction (ENU deg, [0, 180)), None without rows.
    dropped_segments : list of ((x0, y0), (x1, y1))
        Main segments (ENU, m) left out because no path reaches them (module doc).
    warnings : tuple of str
        One line per group of dropped segments, naming where they are.
    free_space : FreeSpace or None
        The eroded free space itself (with its cached rasters and block graph),
        for later connections (sortie transits).
    """

    path_xy_m: np.ndarray
    orientation_deg: float
    line_spacing_m: float
    main_segments: list
    aux_paths: list
    free_eroded: np.ndarray
    coverage_fraction: float
    path_length_m: float
    row_spacing_m: float | None = None
    corridors_xy_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    orientation_source: str = "isoa"
    isoa_orientation_deg: float | None = None
    isoa_score_m: float | None = None
    orientation_score_m: float | None = None
    row_orientation_deg: float | None = None
    dropped_segments: list = field(default_factory=list)
    warnings: tuple[str, ...] = ()
    free_space: object = None


def _enu_deg(alpha_g_rad: float, yaw_rad: float) -> float:
    """Direction in G (rad) -> ENU degrees from east in [0, 180) (``WRAP_TOL_DEG`` below 180 -> 0)."""
    deg = float(np.rad2deg(alpha_g_rad + yaw_rad) % 180.0)
    return 0.0 if deg >= 180.0 - WRAP_TOL_DEG else deg


def plan_coverage(grid: OccupancyGrid, cfg: CoverageConfig, airframe_radius_m: float = 0.0) -> CoveragePlan:
    """Plan the ISOA coverage path of ``grid`` (module doc).

    Parameters
    ----------
    grid : OccupancyGrid
    cfg : CoverageConfig
        Line spacing (None: the detected row spacing), safety margin,
        orientation step (<= 1 deg), optional forced orientation, minimum
        main-segment length.
    airframe_radius_m : float
        Radius of the vehicle (m): the free space is eroded by it plus the
        safety margin, so the margin is kept from the airframe's surface
        (``companion.margins``; the mission planner passes it, 0 keeps the
        margin from the centre).

    Raises
    ------
    PlanError
        Naming the map when there is no free space left after erosion, no
        row spacing can be detected while none is configured, or a main
        segment cannot be reached.
    """
    clearance = float(airframe_radius_m) + cfg.safety_margin_m
    free = erode_free_space(grid, clearance)
    if not free.eroded.any():
        raise PlanError(grid.source, f"no free space left after eroding by the airframe radius "
                                     f"{airframe_radius_m:g} m + the safety margin {cfg.safety_margin_m:g} m")
    rows = detect_rows(grid)
    has_rows = rows is not None and len(rows.offsets_m) >= 2
    if cfg.line_spacing_m is not None:
        spacing = float(cfg.line_spacing_m)
    elif has_rows:
        spacing = rows.spacing_m
    else:
        raise PlanError(grid.source, "cannot detect vine rows to derive the line spacing; "
                                     "set coverage.line_spacing_m")
    yaw = grid.origin_yaw_rad
    corr = find_corridors(rows)
    sweep = score_flown = None
    if cfg.orientation_deg is not None:
        alpha, source = float(np.deg2rad(cfg.orientation_deg) - yaw) % np.pi, "config"
    else:
        sweep = isoa_sweep(free, spacing, cfg.min_segment_m, cfg.orientation_step_deg)
        alpha, source, score_flown = sweep.alpha_rad, "isoa", sweep.score_m
        if has_rows:
            score_rows = float(full_scores(free, rows.angle_g_rad, spacing, cfg.min_segment_m)[0])
            matched = abs(spacing - rows.spacing_m) <= SPACING_MATCH_REL * rows.spacing_m
            if matched or score_rows >= _ROW_SCORE_REL * sweep.score_m:
                alpha, source, score_flown = rows.angle_g_rad, "rows", score_rows
    if source == "rows" and corr is not None:
        phase = corridor_phase(corr.offset_m, spacing)
    else:
        phase = beam_phase(free, alpha, spacing)
    seg = main_segments(free, alpha, spacing, phase, cfg.min_segment_m)
    if len(seg.line) == 0:
        raise PlanError(grid.source, f"no main segment of at least {cfg.min_segment_m} m fits "
                                     "in the eroded free space")
    starts, ends = seg.endpoints_g(alpha)
    keep, warnings = reachable_segments(grid, free, starts, ends, clearance)
    dropped = [(tuple(map(float, p)), tuple(map(float, q)))
               for p, q in zip(grid_to_world(grid, starts[~keep]), grid_to_world(grid, ends[~keep]))]
    starts, ends = starts[keep], ends[keep]
    route = join_segments(free, starts, ends, seg.line[keep], grid.source)
    frac = coverage_fraction(corr, free, route.main_g, spacing)
    path = grid_to_world(grid, route.vertices_g)
    main_w = grid_to_world(grid, route.main_g)
    return CoveragePlan(
        path_xy_m=path,
        orientation_deg=_enu_deg(alpha, yaw),
        line_spacing_m=spacing,
        main_segments=[(tuple(map(float, m[0])), tuple(map(float, m[1]))) for m in main_w],
        aux_paths=[grid_to_world(grid, a) for a in route.aux_g],
        free_eroded=free.eroded,
        coverage_fraction=frac,
        path_length_m=float(np.sum(np.hypot(*np.diff(path, axis=0).T))),
        row_spacing_m=None if rows is None else rows.spacing_m,
        corridors_xy_m=np.zeros((0, 2, 2)) if corr is None else grid_to_world(grid, corr.centre_lines_g()),
        orientation_source=source,
        isoa_orientation_deg=None if sweep is None else _enu_deg(sweep.alpha_rad, yaw),
        isoa_score_m=None if sweep is None else sweep.score_m,
        orientation_score_m=score_flown,
        row_orientation_deg=rows.orientation_deg if has_rows else None,
        dropped_segments=dropped,
        warnings=warnings,
        free_space=free,
    )


def reachable_segments(grid: OccupancyGrid, free, starts_g: np.ndarray, ends_g: np.ndarray,
                       margin_m: float) -> tuple[np.ndarray, tuple[str, ...]]:
    """Which main segments (G, m) the route can join, and a warning per dropped group.

    Keeps the segments of the eroded-space component holding the most
    main-segment length (module doc, "Unreachable segments").

    Returns
    -------
    keep : (k,) bool
    warnings : tuple of str
        Empty, or one line: how many segments were dropped, their length and
        where (ENU centroid of each unreachable component's segment mid-points, m).
    """
    h = free.resolution_m
    bg = free.block_graph()
    mid = 0.5 * (starts_g + ends_g)
    comp = bg.components_of(np.floor(starts_g[:, 1] / h).astype(np.int64),
                            np.floor(starts_g[:, 0] / h).astype(np.int64))
    length = np.hypot(*(ends_g - starts_g).T)
    ids, inv = np.unique(comp, return_inverse=True)
    total = np.bincount(inv, length)
    best = int(np.argmax(total))
    keep = inv == best
    others = [j for j in np.argsort(-total) if j != best]
    if not others:
        return keep, ()
    where = []
    for j in others[:_MAX_PLACES]:
        cx, cy = grid_to_world(grid, mid[inv == j].mean(axis=0))
        where.append(f"({cx:.1f}, {cy:.1f})")
    more = f" and {len(others) - _MAX_PLACES} more places" if len(others) > _MAX_PLACES else ""
    n_seg = int(np.count_nonzero(~keep))
    warnings = [f"{grid.source}: {n_seg} main segment(s), {float(length[~keep].sum()):.1f} m, around "
                f"{', '.join(where)} m{more} cannot be reached from the rest of the field in the free "
                f"space eroded by {margin_m:g} m (airframe radius + safety margin): not flown"]
    return keep, tuple(warnings)
