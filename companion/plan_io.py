"""Plan files: plan.json (docs/plan-json.md), QGroundControl ``.plan`` and "QGC WPL 110".

All three are produced as text in memory (the CLI writes them atomically).

plan.json
    ENU metres in the map frame, SI units. Keys: ``format_version``
    (``PLAN_FORMAT_VERSION``; docs/schemas/plan.schema.json), ``frame`` ("ENU"),
    ``origin`` {lat, lon, alt_m} (the mission home = map frame origin),
    ``path``, ``waypoints`` [{t, p, v, a, corner}], ``trajectory`` {t, p, v,
    a, pointing} sampled at ``sample_hz``, ``stats``, ``timings_s``; plus
    ``name``, ``sample_hz``, ``target_enu_m`` (S_p of eq. 21) and
    ``trajectory_weights`` (the LQR weights used).

QGroundControl exports
    The flight-ready mission of ``companion.mission_items`` (take-off, speed,
    ROI at S_p, the way-points with yaw toward S_p, RTL; AMSL altitudes in
    MAV_FRAME_GLOBAL, which do not depend on where the vehicle arms; the
    inclusion fence in the .plan), latitude/longitude through
    ``companion.frames.enu2geodetic`` about the mission home. The home
    position is written with its AMSL altitude (``plannedHomePosition``;
    item 0 of the WPL file, frame 0 = MAV_FRAME_GLOBAL).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .config import to_dict
from .errors import PlanError
from .format_version import check_format_version
from .inputs import brief, parse_json, read_text
from .mission import Mission

MAV_CMD_NAV_WAYPOINT = 16
MAV_FRAME_GLOBAL = 0
MAV_FRAME_GLOBAL_RELATIVE_ALT = 3
#: QGroundControl's AltitudeMode for MAV_FRAME_GLOBAL (QGroundControlQmlGlobal::AltitudeModeAbsolute)
QGC_ALTITUDE_MODE_ABSOLUTE = 2
MAV_AUTOPILOT_PX4 = 12
MAV_TYPE_QUADROTOR = 2

#: plan.json format written here ("MAJOR.MINOR", docs/README.md "Versions");
#: ``load_plan`` reads every file of the same major version.
PLAN_FORMAT_VERSION = "1.0"
PLAN_FORMAT_MAJOR = int(PLAN_FORMAT_VERSION.split(".")[0])

STATS_KEYS = ("coverage_fraction", "path_length_m", "duration_s", "n_waypoints", "orientation_deg",
              "max_speed_m_s", "max_accel_m_s2", "waypoint_residual_m")
TIMING_KEYS = ("load", "coverage", "trajectory", "total")
#: Most trajectory samples plan.json may hold (a 10 ha field at 10 Hz needs ~4e5):
#: beyond it --sample-hz is a typo and the document would not fit in memory.
MAX_SAMPLES = 2_000_000


def _rows(a) -> list:
    return np.asarray(a, dtype=float).tolist()


def sample_times(t0: float, tf: float, sample_hz: float) -> np.ndarray:
    """t0, t0 + 1/hz, ... up to tf, with tf itself always the last sample (s)."""
    n = int(math.floor((tf - t0) * sample_hz + 1e-9))
    t = t0 + np.arange(n + 1) / sample_hz
    if tf - t[-1] > 1e-9:
        t = np.append(t, tf)
    else:
        t[-1] = tf      # rounding: end exactly on the last way-point's time
    return t


def plan_to_json_dict(plan, mission: Mission, sample_hz: float) -> dict:
    """The plan.json document (docs/plan-json.md) as plain JSON types.

    Parameters
    ----------
    plan : companion.planner.Plan
    mission : Mission
        For the name, origin (home) and weights.
    sample_hz : float
        Trajectory sampling rate (Hz), > 0.
    """
    if not (sample_hz > 0 and math.isfinite(sample_hz)):
        raise PlanError("--sample-hz", f"must be a positive number, got {sample_hz}")
    traj = plan.trajectory
    n_samples = (traj.tf - traj.t0) * sample_hz
    if n_samples > MAX_SAMPLES:
        raise PlanError("--sample-hz", f"{sample_hz:g} Hz over {traj.tf - traj.t0:.1f} s would be "
                        f"{n_samples:.3g} samples (at most {MAX_SAMPLES}); use a lower rate")
    wp = plan.waypoints
    t = sample_times(traj.t0, traj.tf, sample_hz)
    s = traj.sample(t)
    home = mission.home
    return {
        "format_version": PLAN_FORMAT_VERSION,
        "name": mission.name,
        "frame": "ENU",
        "origin": {"lat": home.lat, "lon": home.lon, "alt_m": home.alt_m},
        "path": _rows(plan.coverage.path_xy_m),
        "waypoints": _waypoints_json(wp),
        "sample_hz": float(sample_hz),
        "trajectory": {"t": _rows(t), "p": _rows(s.p), "v": _rows(s.v), "a": _rows(s.a),
                       "pointing": _rows(s.pointing)},
        "target_enu_m": _rows(plan.target_enu_m),
        "trajectory_weights": to_dict(mission.trajectory),
        "stats": {k: getattr(plan.stats, k) for k in STATS_KEYS},
        "timings_s": {k: getattr(plan.timings_s, k) for k in TIMING_KEYS},
        "warnings": list(plan.warnings),
        **sorties_json(plan, mission),
    }


def _waypoints_json(w) -> list:
    return [{"t": float(ti), "p": _rows(p), "v": _rows(v), "a": _rows(a), "corner": bool(c)}
            for ti, p, v, a, c in zip(w.t_s, w.p_enu_m, w.v_enu_m_s, w.a_enu_m_s2, w.corner)]


def sorties_json(plan, mission: Mission) -> dict:
    """plan.json's ``energy`` summary and ``sorties`` (``companion.sorties``)."""
    from .energy import cruise_power_w, hover_power_w

    sp = plan.sorties
    if sp is None:
        return {}
    cfg = mission.energy
    return {
        "energy": {"hover_power_w": hover_power_w(mission.vehicle, cfg),
                   "cruise_power_w": float(cruise_power_w(mission.flight.speed_m_s, mission.vehicle, cfg)),
                   "transit_power_w": float(cruise_power_w(mission.flight.transit_speed_m_s, mission.vehicle, cfg)),
                   "battery_wh": cfg.battery_wh, "usable_wh": cfg.usable_wh,
                   "total_energy_wh": sp.total_energy_wh, "total_duration_s": sp.total_duration_s,
                   "max_mission_items": cfg.max_mission_items},
        "launch_enu_m": _rows(sp.launch_xy_m),
        "sorties": [{"index": s.index, "segments": list(s.segments), "energy_wh": s.energy.energy_wh,
                     "duration_s": s.energy.duration_s, "n_items": s.n_items,
                     "speed_changes": [[int(i), float(v)] for i, v in s.speed_changes],
                     "path": _rows(s.path_xy_m), "waypoints": _waypoints_json(s.waypoints)}
                    for s in sp.sorties],
    }


def plan_json_text(doc: dict) -> str:
    """Serialise a plan.json document (NaN/inf are a bug, not output)."""
    return json.dumps(doc, allow_nan=False, separators=(",", ":")) + "\n"


# --- reading plan.json ----------------------------------------------------------

@dataclass(frozen=True, eq=False)
class PlanFile:
    """A validated plan.json (ENU metres, SI).

    Attributes
    ----------
    origin : (lat_deg, lon_deg, alt_m)
    path_xy_m : (K, 2)
    waypoint_t_s : (N,), waypoint_p_enu_m, waypoint_v_enu_m_s, waypoint_a_enu_m_s2 : (N, 3), waypoint_corner : (N,) bool
    t_s : (n,) ; p_enu_m, v_enu_m_s, a_enu_m_s2, pointing_enu : (n, 3)
        The sampled trajectory.
    target_enu_m : (3,) or None
    stats, timings_s : dict
    data : dict
        The whole document.
    source : str
    sorties : list of dict
        Per sortie: ``waypoint_t_s``, ``waypoint_p_enu_m``, ``waypoint_v_enu_m_s``,
        ``waypoint_a_enu_m_s2`` arrays (empty list for a plan.json without sorties).
    """

    origin: tuple[float, float, float]
    path_xy_m: np.ndarray
    waypoint_t_s: np.ndarray
    waypoint_p_enu_m: np.ndarray
    waypoint_v_enu_m_s: np.ndarray
    waypoint_a_enu_m_s2: np.ndarray
    waypoint_corner: np.ndarray
    t_s: np.ndarray
    p_enu_m: np.ndarray
    v_enu_m_s: np.ndarray
    a_enu_m_s2: np.ndarray
    pointing_enu: np.ndarray
    target_enu_m: np.ndarray | None
    stats: dict
    timings_s: dict
    data: dict
    source: str
    sorties: list = dataclasses.field(default_factory=list)


def _num_array(value, shape_tail: tuple[int, ...], src: str, key: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise PlanError(f"{src}: key '{key}'", "expected numbers") from None
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != shape_tail:
        want = "(n" + "".join(f", {d}" for d in shape_tail) + ")"
        raise PlanError(f"{src}: key '{key}'", f"expected an array of shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise PlanError(f"{src}: key '{key}'", "non-finite value")
    return arr


def _get(d, key: str, src: str, prefix: str = ""):
    if not isinstance(d, dict):
        raise PlanError(f"{src}: key '{prefix}'", "expected a mapping")
    if key not in d:
        raise PlanError(f"{src}: key '{prefix + '.' if prefix else ''}{key}'", "missing")
    return d[key]


def load_plan(path: str | Path) -> PlanFile:
    """Read and validate a plan.json written by ``companion plan``.

    Raises
    ------
    PlanError
        Missing/unreadable file, not JSON, a ``format_version`` of another
        major version, or a missing/malformed key (the message names the
        file and the key). A file without ``format_version`` is read as 1.0.
    """
    p = Path(path)
    src = str(p)
    data = parse_json(read_text(p, PlanError, "plan.json", cap="plan_bytes"), src, PlanError)
    if not isinstance(data, dict):
        raise PlanError(src, "expected a JSON object")
    check_format_version(data, PLAN_FORMAT_MAJOR, src, PlanError)
    if _get(data, "frame", src) != "ENU":
        raise PlanError(f"{src}: key 'frame'", f"expected 'ENU', got {brief(data['frame'])}")
    origin = _get(data, "origin", src)
    o = tuple(float(_num_array([_get(origin, k, src, "origin")], (), src, f"origin.{k}")[0])
              for k in ("lat", "lon", "alt_m"))
    path_xy = _num_array(_get(data, "path", src), (2,), src, "path")
    wps = _get(data, "waypoints", src)
    if not isinstance(wps, list) or len(wps) < 2:
        raise PlanError(f"{src}: key 'waypoints'", "expected a list of at least 2 way-points")
    cols = {}
    for k, tail in (("t", ()), ("p", (3,)), ("v", (3,)), ("a", (3,))):
        cols[k] = _num_array([_get(w, k, src, f"waypoints[{i}]") for i, w in enumerate(wps)],
                             tail, src, f"waypoints[].{k}")
    corner = [_get(w, "corner", src, f"waypoints[{i}]") for i, w in enumerate(wps)]
    if not all(isinstance(c, bool) for c in corner):
        raise PlanError(f"{src}: key 'waypoints[].corner'", "expected true or false")
    if np.any(np.diff(cols["t"]) <= 0):
        raise PlanError(f"{src}: key 'waypoints[].t'", "times must be strictly increasing")
    tr = _get(data, "trajectory", src)
    t = _num_array(_get(tr, "t", src, "trajectory"), (), src, "trajectory.t")
    arrays = {k: _num_array(_get(tr, k, src, "trajectory"), (3,), src, f"trajectory.{k}")
              for k in ("p", "v", "a", "pointing")}
    for k, arr in arrays.items():
        if arr.shape[0] != t.shape[0]:
            raise PlanError(f"{src}: key 'trajectory.{k}'", f"{arr.shape[0]} samples for {t.shape[0]} times")
    if t.shape[0] < 2 or np.any(np.diff(t) <= 0):
        raise PlanError(f"{src}: key 'trajectory.t'", "expected at least 2 strictly increasing times")
    stats = _get(data, "stats", src)
    for k in STATS_KEYS:
        _num_array([_get(stats, k, src, "stats")], (), src, f"stats.{k}")
    timings = _get(data, "timings_s", src)
    for k in TIMING_KEYS:
        _num_array([_get(timings, k, src, "timings_s")], (), src, f"timings_s.{k}")
    target = None
    if "target_enu_m" in data:
        target = _num_array([data["target_enu_m"]], (3,), src, "target_enu_m")[0]
    sorties = []
    raw_sorties = data.get("sorties", [])
    if not isinstance(raw_sorties, list):
        raise PlanError(f"{src}: key 'sorties'", "expected a list")
    for j, so in enumerate(raw_sorties):
        ws = _get(so, "waypoints", src, f"sorties[{j}]")
        if not isinstance(ws, list) or len(ws) < 2:
            raise PlanError(f"{src}: key 'sorties[{j}].waypoints'", "expected a list of at least 2 way-points")
        cols_s = {}
        for k_, tail in (("t", ()), ("p", (3,)), ("v", (3,)), ("a", (3,))):
            cols_s[k_] = _num_array([_get(w, k_, src, f"sorties[{j}].waypoints[{i}]") for i, w in enumerate(ws)],
                                    tail, src, f"sorties[{j}].waypoints[].{k_}")
        if np.any(np.diff(cols_s["t"]) <= 0):
            raise PlanError(f"{src}: key 'sorties[{j}].waypoints[].t'", "times must be strictly increasing")
        sorties.append({"waypoint_t_s": cols_s["t"], "waypoint_p_enu_m": cols_s["p"],
                        "waypoint_v_enu_m_s": cols_s["v"], "waypoint_a_enu_m_s2": cols_s["a"]})
    return PlanFile(origin=o, path_xy_m=path_xy, waypoint_t_s=cols["t"], waypoint_p_enu_m=cols["p"],
                    waypoint_v_enu_m_s=cols["v"], waypoint_a_enu_m_s2=cols["a"],
                    waypoint_corner=np.array(corner, dtype=bool), t_s=t, p_enu_m=arrays["p"],
                    v_enu_m_s=arrays["v"], a_enu_m_s2=arrays["a"], pointing_enu=arrays["pointing"],
                    target_enu_m=target, stats=dict(stats), timings_s=dict(timings), data=data, source=src,
                    sorties=sorties)


# --- QGroundControl exports ------------------------------------------------------

def flight_items(plan, mission: Mission, sortie=None, fence_enu_m: np.ndarray | None = None):
    """The flight-ready items (``companion.mission_items``) of one sortie of a plan
    (``plan.sorties.sorties[i]``; default: the whole route, launched under its first
    way-point), with the inclusion fence around the field (simplified to half the
    safety margin, so the path keeps at least half the margin from the fence)."""
    from .mission_items import build_flight_items

    h = mission.home
    fence = field_fence(plan, mission) if fence_enu_m is None else fence_enu_m
    if sortie is None:
        return build_flight_items(plan.waypoints.p_enu_m, plan.target_enu_m, (h.lat, h.lon, h.alt_m),
                                  mission.flight.speed_m_s, fence_enu_m=fence)
    return build_flight_items(sortie.waypoints.p_enu_m, plan.target_enu_m, (h.lat, h.lon, h.alt_m),
                              mission.flight.speed_m_s, launch_enu_m=plan.sorties.launch_xy_m,
                              fence_enu_m=fence, speed_changes=sortie.speed_changes)


def field_fence(plan, mission: Mission) -> np.ndarray:
    """(K, 2) ENU inclusion fence around the field (``coverage.boundary``)."""
    from .coverage.boundary import field_boundary

    return field_boundary(plan.grid, max(0.5 * mission.coverage.safety_margin_m, plan.grid.resolution_m))


def sortie_file(path: str, index: int, count: int) -> str:
    """The export file of sortie ``index`` (1-based): ``path`` itself for a single
    sortie, else ``<stem>-sortie<index><suffix>`` beside it."""
    if count == 1:
        return path
    p = Path(path)
    return str(p.with_name(f"{p.stem}-sortie{index}{p.suffix}"))


def _json_num(v: float):
    return None if isinstance(v, float) and math.isnan(v) else v


def qgc_plan_dict(items, speed_m_s: float) -> dict:
    """QGroundControl ``.plan`` (JSON, fileType "Plan", version 1): one SimpleItem per
    mission item (AMSL altitudes, QGC AltitudeMode 2), the inclusion fence in
    ``geoFence.polygons`` (module doc of ``companion.mission_items``)."""
    out = []
    for i, it in enumerate(items.mission):
        positional = it.frame == MAV_FRAME_GLOBAL
        out.append({
            "type": "SimpleItem",
            "autoContinue": bool(it.autocontinue),
            "command": it.command,
            "doJumpId": i + 1,
            "frame": it.frame,
            "params": [_json_num(float(v)) for v in it.params] + [it.lat_deg, it.lon_deg, it.alt_m],
            "Altitude": it.alt_m if positional else 0,
            "AltitudeMode": QGC_ALTITUDE_MODE_ABSOLUTE,
            "AMSLAltAboveTerrain": None,
        })
    fence = []
    if len(items.fence_latlon_deg):
        fence = [{"inclusion": True, "polygon": [[float(a), float(b)] for a, b in items.fence_latlon_deg],
                  "version": 1}]
    lat, lon, alt = items.home
    return {
        "fileType": "Plan",
        "version": 1,
        "groundStation": "QGroundControl",
        "geoFence": {"circles": [], "polygons": fence, "version": 2},
        "rallyPoints": {"points": [], "version": 2},
        "mission": {
            "version": 2,
            "firmwareType": MAV_AUTOPILOT_PX4,
            "vehicleType": MAV_TYPE_QUADROTOR,
            "cruiseSpeed": speed_m_s,
            "hoverSpeed": speed_m_s,
            "globalPlanAltitudeMode": QGC_ALTITUDE_MODE_ABSOLUTE,
            "plannedHomePosition": [lat, lon, alt],
            "items": out,
        },
    }


def qgc_plan_text(items, speed_m_s: float) -> str:
    return json.dumps(qgc_plan_dict(items, speed_m_s), indent=2, allow_nan=False) + "\n"


def _wpl_num(v: float) -> str:
    return "nan" if math.isnan(v) else f"{v:.8g}"


def qgc_wpl_text(items) -> str:
    """"QGC WPL 110" text: tab-separated ``index current frame command p1 p2 p3 p4
    lat lon alt autocontinue``; line 0 is the planned home (frame 0, AMSL), then
    the mission items (AMSL altitudes). The format has no fence."""
    lat0, lon0, alt0 = items.home
    lines = ["QGC WPL 110",
             f"0\t1\t{MAV_FRAME_GLOBAL}\t{MAV_CMD_NAV_WAYPOINT}\t0\t0\t0\t0\t{lat0:.10f}\t{lon0:.10f}\t{alt0:.4f}\t1"]
    for i, it in enumerate(items.mission, start=1):
        p = "\t".join(_wpl_num(float(v)) for v in it.params)
        lines.append(f"{i}\t0\t{it.frame}\t{it.command}\t{p}\t{it.lat_deg:.10f}\t{it.lon_deg:.10f}\t"
                     f"{it.alt_m:.4f}\t{1 if it.autocontinue else 0}")
    return "\n".join(lines) + "\n"
