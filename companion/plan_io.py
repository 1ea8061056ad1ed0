"""Plan files: plan.json (docs/plan-json.md), QGroundControl ``.plan`` and "QGC WPL 110".

All three are produced as text in memory (the CLI writes them atomically).

plan.json
    ENU metres in the map frame, SI units. Keys: ``format_version``
    (``PLAN_FORMAT_VERSION``; docs/schemas/plan.schema.json), ``frame`` ("ENU"),
    ``origin`` {lat, lon, alt_m} (the mission home = map frame origin),
    ``path``, ``waypoints`` [{t, p, v, a, corner}], ``trajectory`` (2.x: the
    exact polynomial pieces, as knot states or coefficients in base64 float64;
    1.x: samples),
    ``stats``, ``timings_s``; plus ``name``, ``target_enu_m`` (S_p of eq. 21),
    ``trajectory_weights`` (the LQR weights used) and, on request, ``samples``
    (the trajectory sampled at ``samples.hz``). ``load_plan`` reads 2.x and 1.x.

QGroundControl exports
    The flight-ready mission of ``companion.mission_items`` (take-off, speed,
    ROI at S_p, the way-points with yaw toward S_p, RTL; AMSL altitudes in
    MAV_FRAME_GLOBAL, which do not depend on where the vehicle arms; the
    inclusion fence in the .plan), latitude/longitude through
    ``mavcore.frames.enu2geodetic`` about the mission home. The home
    position is written with its AMSL altitude (``plannedHomePosition``;
    item 0 of the WPL file, frame 0 = MAV_FRAME_GLOBAL).
"""

from __future__ import annotations

import base64
import binascii
import dataclasses
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import orjson

from mavcore.config import to_dict
from mavcore.errors import PlanError
from .format_version import check_format_version
from mavcore.inputs import brief, decode_text, parse_json, read_bytes
from mavcore.mission import Mission

MAV_CMD_NAV_WAYPOINT = 16
MAV_FRAME_GLOBAL = 0
MAV_FRAME_GLOBAL_RELATIVE_ALT = 3
#: QGroundControl's AltitudeMode for MAV_FRAME_GLOBAL (QGroundControlQmlGlobal::AltitudeModeAbsolute)
QGC_ALTITUDE_MODE_ABSOLUTE = 2
MAV_AUTOPILOT_PX4 = 12
MAV_TYPE_QUADROTOR = 2

#: plan.json format written here ("MAJOR.MINOR", docs/README.md "Versions");
#: ``load_plan`` reads every file of this major version and of ``LEGACY_PLAN_MAJOR``.
#: 2.0: ``trajectory`` holds the polynomial pieces instead of samples; the samples,
#: now optional, moved to ``samples``; ``timings_s`` gained ``write`` and ``wall``;
#: ``margins`` (clearances from the airframe surface, acceptance radius, fence margin) added.
PLAN_FORMAT_VERSION = "2.1"
PLAN_FORMAT_MAJOR = int(PLAN_FORMAT_VERSION.split(".")[0])
#: The previous major version, still read (its ``trajectory`` is samples only:
#: ``companion fly`` re-solves the LQR through its way-points).
LEGACY_PLAN_MAJOR = 1

STATS_KEYS = ("coverage_fraction", "path_length_m", "duration_s", "n_waypoints", "orientation_deg",
              "max_speed_m_s", "max_accel_m_s2", "waypoint_residual_m")
TIMING_KEYS = ("load", "coverage", "trajectory", "total")
#: ``timings_s`` keys added by ``companion plan`` when it writes the file (2.0).
WRITE_TIMING_KEYS = ("write", "wall")
#: Most trajectory samples plan.json may hold (a 10 ha field at 10 Hz needs ~4e5):
#: beyond it --samples is a typo and the document would not fit in memory.
MAX_SAMPLES = 2_000_000
#: ``trajectory.form`` of format 2.x: the knot states (Q = 0: degree-7 pieces,
#: half the numbers) or the position coefficients of every piece (any Q).
FORM_KNOT_STATES = "knot-states"
FORM_POLYNOMIAL = "polynomial"
#: dtype of ``trajectory.values`` (little-endian IEEE float64).
VALUES_DTYPE = "<f8"

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


def trajectory_json(traj) -> dict:
    """plan.json's ``trajectory`` (2.x): the knot times and, exactly (float64,
    little-endian, base64), the numbers that fix every piece.

    With Q = 0 (``FORM_KNOT_STATES``) the optimal p is a degree-7 polynomial on
    each knot interval, fixed by [p, v, a, jerk] at its two ends: ``values``
    are the (M + 1, 4, 3) knot states
    (``companion.trajectory.sampling.hermite_position_coefficients``).
    Otherwise (``FORM_POLYNOMIAL``) they are the (M, D + 1, 3) position
    coefficients c: on piece m, s = (t - t[m]) / (t[m + 1] - t[m]) and
    p(t) = sum_j c[m, j] s^j. v, a, jerk and snap are p's derivatives.
    """
    degree = int(traj.coefficients.shape[1] - 1)
    if degree == 7 and not any(traj.config.q_diag):
        form, values = FORM_KNOT_STATES, traj.knot_states
    else:
        form, values = FORM_POLYNOMIAL, traj.position_coefficients
    v = np.ascontiguousarray(values, dtype=VALUES_DTYPE)
    return {"form": form, "degree": degree, "t": _rows(traj.knot_times_s),
            "values": {"dtype": VALUES_DTYPE, "shape": list(v.shape),
                       "base64": base64.b64encode(v.tobytes()).decode("ascii")}}


def samples_json(traj, sample_hz: float) -> dict:
    """plan.json's optional ``samples``: the trajectory at ``sample_times`` (``--samples HZ``)."""
    if not (sample_hz > 0 and math.isfinite(sample_hz)):
        raise PlanError("--samples", f"must be a positive number of Hz, got {sample_hz}")
    n_samples = (traj.tf - traj.t0) * sample_hz
    if n_samples > MAX_SAMPLES:
        raise PlanError("--samples", f"{sample_hz:g} Hz over {traj.tf - traj.t0:.1f} s would be "
                        f"{n_samples:.3g} samples (at most {MAX_SAMPLES}); use a lower rate")
    t = sample_times(traj.t0, traj.tf, sample_hz)
    s = traj.sample(t)
    return {"hz": float(sample_hz), "t": _rows(t), "p": _rows(s.p), "v": _rows(s.v), "a": _rows(s.a),
            "pointing": _rows(s.pointing)}


def plan_to_json_dict(plan, mission: Mission, sample_hz: float | None = None) -> dict:
    """The plan.json document (docs/plan-json.md) as plain JSON types.

    Parameters
    ----------
    plan : companion.planner.Plan
    mission : Mission
        For the name, origin (home) and weights.
    sample_hz : float, optional
        Also store the trajectory sampled at this rate (Hz, > 0) as ``samples``.
    """
    traj = plan.trajectory
    samples = None if sample_hz is None else samples_json(traj, sample_hz)
    home = mission.home
    doc = {
        "format_version": PLAN_FORMAT_VERSION,
        "name": mission.name,
        "frame": "ENU",
        "origin": {"lat": home.lat, "lon": home.lon, "alt_m": home.alt_m},
        "path": _rows(plan.coverage.path_xy_m),
        "waypoints": _waypoints_json(plan.waypoints),
        "trajectory": trajectory_json(traj),
        "target_enu_m": _rows(plan.target_enu_m),
        "trajectory_weights": to_dict(mission.trajectory),
        "stats": {k: getattr(plan.stats, k) for k in STATS_KEYS},
        "timings_s": {k: getattr(plan.timings_s, k) for k in TIMING_KEYS},
        "warnings": list(plan.warnings),
        **sorties_json(plan, mission),
        **margins_json(plan),
    }
    if samples is not None:
        doc["samples"] = samples
    return doc


def margins_json(plan) -> dict:
    """plan.json's ``margins`` (``companion.margins.PlanMargins``), when the plan has them."""
    m = getattr(plan, "margins", None)
    return {} if m is None else {"margins": {k: float(v) for k, v in dataclasses.asdict(m).items()}}


def _waypoints_json(w) -> list:
    # whole-array tolist (one call per array, not one per way-point: 10 ha has ~1.6e4)
    cols = [np.asarray(x, dtype=float).tolist() for x in (w.t_s, w.p_enu_m, w.v_enu_m_s, w.a_enu_m_s2)]
    corner = np.asarray(w.corner, dtype=bool).tolist()
    return [{"t": ti, "p": p, "v": v, "a": a, "corner": c} for ti, p, v, a, c in zip(*cols, corner)]


def sorties_json(plan, mission: Mission) -> dict:
    """plan.json's ``energy`` summary and ``sorties`` (``companion.sorties``)."""
    from mavcore.energy import cruise_power_w, hover_power_w

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


def _all_finite(value) -> bool:
    """False if ``value`` (JSON data: dicts, lists, numbers, ...) holds a NaN or an
    infinity. A list of numbers is summed in C: the sum of finite numbers is
    finite unless it overflows, and only then are its items looked at one by one."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, dict):
        return all(map(_all_finite, value.values()))
    if isinstance(value, (list, tuple)):
        try:
            if math.isfinite(sum(value)):
                return True
        except (TypeError, OverflowError):
            pass
        return all(map(_all_finite, value))
    return True


def _dumps(value) -> str:
    """Compact JSON of ``value``; NaN and infinities raise ``ValueError``.

    orjson writes the same values as ``json.dumps(value, allow_nan=False,
    separators=(",", ":"))`` (floats in their shortest round-trip form, non-ASCII
    as UTF-8 rather than ``\\u`` escapes) about 20 x faster: 0.3 s of the
    10 ha plan. What orjson does not take (numpy scalars, huge integers,
    non-string keys) and every non-finite number go through ``json``: orjson
    writes those numbers as ``null``, so a text without ``null`` has none, and
    only a text with one is checked value by value.
    """
    try:
        text = orjson.dumps(value)
    except TypeError:
        text = None
    if text is None or (b"null" in text and not _all_finite(value)):
        return json.dumps(value, allow_nan=False, separators=(",", ":"))
    return text.decode("utf-8")


def plan_json_text(doc: dict, render_start_s: float | None = None) -> str:
    """Serialise a plan.json document (NaN/inf are a bug, not output).

    Parameters
    ----------
    doc : dict
    render_start_s : float, optional
        ``time.perf_counter()`` when the rendering of the outputs began. Then
        ``timings_s`` gains ``write`` (since then) and ``wall`` (since the
        process started, ``companion.process_clock``), taken after every other
        key has been encoded so that they include the encoding; ``doc`` is
        updated with them. The text is compact JSON (:func:`_dumps`).
    """
    parts = {k: _dumps(v) for k, v in doc.items() if render_start_s is None or k != "timings_s"}
    if render_start_s is not None:
        from .process_clock import process_wall_s

        doc["timings_s"] = dict(doc["timings_s"], write=time.perf_counter() - render_start_s,
                                wall=process_wall_s())
        parts["timings_s"] = _dumps(doc["timings_s"])
    return "{" + ",".join(f"{_dumps(k)}:{parts[k]}" for k in doc) + "}\n"


# --- reading plan.json ----------------------------------------------------------

@dataclass(frozen=True, eq=False)
class PlanFile:
    """A validated plan.json (ENU metres, SI).

    Attributes
    ----------
    origin : (lat_deg, lon_deg, alt_m)
    path_xy_m : (K, 2)
    waypoint_t_s : (N,), waypoint_p_enu_m, waypoint_v_enu_m_s, waypoint_a_enu_m_s2 : (N, 3), waypoint_corner : (N,) bool
    t_s : (n,) or None ; p_enu_m, v_enu_m_s, a_enu_m_s2, pointing_enu : (n, 3) or None
        The sampled trajectory: 2.x ``samples`` (None without it), 1.x ``trajectory``.
    target_enu_m : (3,) or None
    stats, timings_s : dict
    data : dict
        The whole document (read from its binary twin, ``companion.plan_twin``:
        the document without the arrays the twin holds).
    source : str
    sorties : list of dict
        Per sortie: ``waypoint_t_s``, ``waypoint_p_enu_m``, ``waypoint_v_enu_m_s``,
        ``waypoint_a_enu_m_s2`` arrays (empty list for a plan.json without sorties).
    trajectory : Trajectory or None
        2.x: the trajectory rebuilt from its pieces (exact, carrying
        ``target_enu_m``); None for a 1.x plan (re-solve through the way-points),
        or when ``load_plan`` was asked not to rebuild it (its pieces checked all the same).
    format_major : int
    """

    origin: tuple[float, float, float]
    path_xy_m: np.ndarray
    waypoint_t_s: np.ndarray
    waypoint_p_enu_m: np.ndarray
    waypoint_v_enu_m_s: np.ndarray
    waypoint_a_enu_m_s2: np.ndarray
    waypoint_corner: np.ndarray
    t_s: np.ndarray | None
    p_enu_m: np.ndarray | None
    v_enu_m_s: np.ndarray | None
    a_enu_m_s2: np.ndarray | None
    pointing_enu: np.ndarray | None
    target_enu_m: np.ndarray | None
    stats: dict
    timings_s: dict
    data: dict
    source: str
    sorties: list = dataclasses.field(default_factory=list)
    trajectory: object = None
    format_major: int = PLAN_FORMAT_MAJOR
    #: SHA-256 (hex) of the plan.json bytes read (the flight's setup record names the plan by it).
    sha256_hex: str | None = None


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


def _waypoint_columns(wps, src: str, prefix: str) -> dict:
    """``t``, ``p``, ``v``, ``a`` arrays of a way-point list (checked, times increasing)."""
    if not isinstance(wps, list) or len(wps) < 2:
        raise PlanError(f"{src}: key '{prefix}'", "expected a list of at least 2 way-points")
    cols = {}
    for k in ("t", "p", "v", "a"):
        try:
            cols[k] = [w[k] for w in wps]          # fast path; the slow one names the bad way-point
        except (KeyError, TypeError):
            cols[k] = [_get(w, k, src, f"{prefix}[{i}]") for i, w in enumerate(wps)]
    return _checked_columns(cols, src, prefix)


def _checked_columns(cols: dict, src: str, prefix: str) -> dict:
    """The way-point columns ``t`` (N,), ``p``, ``v``, ``a`` (N, 3) as float arrays: numbers,
    finite, of one length N >= 2, times strictly increasing (the JSON's list or the twin's)."""
    out = {k: _num_array(cols[k], tail, src, f"{prefix}[].{k}") for k, tail in (("t", ()), ("p", (3,)),
                                                                               ("v", (3,)), ("a", (3,)))}
    n = out["t"].shape[0]
    if n < 2:
        raise PlanError(f"{src}: key '{prefix}'", "expected a list of at least 2 way-points")
    for k, a in out.items():
        if a.shape[0] != n:
            raise PlanError(f"{src}: key '{prefix}[].{k}'", f"{a.shape[0]} values for {n} way-points")
    if np.any(np.diff(out["t"]) <= 0):
        raise PlanError(f"{src}: key '{prefix}[].t'", "times must be strictly increasing")
    return out


def _samples(tr, src: str, key: str) -> dict:
    """``t``, ``p``, ``v``, ``a``, ``pointing`` arrays of sampled trajectory ``key`` (checked)."""
    t = _num_array(_get(tr, "t", src, key), (), src, f"{key}.t")
    arrays = {k: _num_array(_get(tr, k, src, key), (3,), src, f"{key}.{k}")
              for k in ("p", "v", "a", "pointing")}
    for k, arr in arrays.items():
        if arr.shape[0] != t.shape[0]:
            raise PlanError(f"{src}: key '{key}.{k}'", f"{arr.shape[0]} samples for {t.shape[0]} times")
    if t.shape[0] < 2 or np.any(np.diff(t) <= 0):
        raise PlanError(f"{src}: key '{key}.t'", "expected at least 2 strictly increasing times")
    return dict(arrays, t=t)


def _trajectory(data: dict, wp_t: np.ndarray, wp_targets: np.ndarray, target, src: str, arrays=None,
                rebuild: bool = True):
    """The 2.x ``trajectory`` as a ``Trajectory``, checked against the way-points.
    ``arrays``: the twin's (``companion.plan_twin``): its knots and decoded values.
    ``rebuild=False``: checked only, None returned."""
    from .trajectory import Trajectory
    from mavcore.mission.trajectory import TrajectoryConfig
    from .trajectory.sampling import hermite_position_coefficients

    tr = _get(data, "trajectory", src)
    form = _get(tr, "form", src, "trajectory")
    if form not in (FORM_KNOT_STATES, FORM_POLYNOMIAL):
        raise PlanError(f"{src}: key 'trajectory.form'",
                        f"expected {FORM_KNOT_STATES!r} or {FORM_POLYNOMIAL!r}, got {form!r}")
    degree = _get(tr, "degree", src, "trajectory")
    if (not isinstance(degree, int) or isinstance(degree, bool) or not 4 <= degree <= 64
            or (form == FORM_KNOT_STATES and degree != 7)):
        raise PlanError(f"{src}: key 'trajectory.degree'",
                        f"expected {'7' if form == FORM_KNOT_STATES else 'an integer in [4, 64]'}, got {degree!r}")
    knots = _num_array(arrays["traj_t"] if arrays is not None else _get(tr, "t", src, "trajectory"), (), src,
                       "trajectory.t")
    if knots.shape[0] < 2 or np.any(np.diff(knots) <= 0):
        raise PlanError(f"{src}: key 'trajectory.t'", "expected at least 2 strictly increasing knot times")
    n = knots.shape[0]
    want = [n, 4, 3] if form == FORM_KNOT_STATES else [n - 1, degree + 1, 3]
    va = _get(tr, "values", src, "trajectory")
    if _get(va, "dtype", src, "trajectory.values") != VALUES_DTYPE:
        raise PlanError(f"{src}: key 'trajectory.values.dtype'", f"expected {VALUES_DTYPE!r}")
    if _get(va, "shape", src, "trajectory.values") != want:
        what = "knots, [p, v, a, jerk], axes" if form == FORM_KNOT_STATES else "pieces, degree + 1, axes"
        raise PlanError(f"{src}: key 'trajectory.values.shape'", f"expected {want} ({what}), got {va['shape']!r}")
    count = want[0] * want[1] * want[2]
    if arrays is not None:
        values = arrays["traj_values"]
        if values.dtype != np.float64 or list(values.shape) != want:
            raise PlanError(f"{src}: key 'trajectory.values'", f"the twin's values are not {count} float64 numbers")
    else:
        b64 = _get(va, "base64", src, "trajectory.values")
        try:
            raw = base64.b64decode(b64, validate=True) if isinstance(b64, str) else None
        except (binascii.Error, ValueError):
            raw = None
        if raw is None or len(raw) != 8 * count:
            raise PlanError(f"{src}: key 'trajectory.values.base64'", f"expected base64 of {count} float64 numbers")
        values = np.frombuffer(raw, dtype=VALUES_DTYPE).astype(float).reshape(want)
    if not np.all(np.isfinite(values)):
        raise PlanError(f"{src}: key 'trajectory.values'", "non-finite value")
    wk = np.minimum(np.searchsorted(knots, wp_t), n - 1)
    if knots[0] != wp_t[0] or knots[-1] != wp_t[-1] or not np.array_equal(knots[wk], wp_t):
        raise PlanError(f"{src}: key 'trajectory.t'", "the way-point times are not knots of the trajectory")
    weights = _get(data, "trajectory_weights", src)
    if not isinstance(weights, dict):
        raise PlanError(f"{src}: key 'trajectory_weights'", "expected a mapping")
    try:
        config = TrajectoryConfig(**weights)
    except (TypeError, ValueError) as exc:
        raise PlanError(f"{src}: key 'trajectory_weights'", str(exc)) from None
    if form == FORM_KNOT_STATES:
        if any(config.q_diag):
            raise PlanError(f"{src}: key 'trajectory.form'",
                            f"{FORM_KNOT_STATES!r} needs q_* = 0 in trajectory_weights (degree-7 pieces)")
        if not rebuild:
            return None
        return Trajectory.from_pieces(knots, hermite_position_coefficients(knots, values), wk, wp_targets,
                                      config, target, knot_states=values)
    return Trajectory.from_pieces(knots, values, wk, wp_targets, config, target) if rebuild else None


def load_plan(path: str | Path, rebuild_trajectory: bool = True) -> PlanFile:
    """Read and validate a plan.json written by ``companion plan`` (format 2.x or 1.x).
    ``rebuild_trajectory=False``: the whole route's trajectory is checked but not rebuilt
    (``PlanFile.trajectory`` None; a sortie flight solves its own, ``companion fly --sortie``).

    Raises
    ------
    PlanError
        Missing/unreadable file, not JSON, a ``format_version`` of another
        major version, or a missing/malformed key (the message names the
        file and the key). A file without ``format_version`` is read as 1.0.
    """
    from .plan_twin import digest, read_twin

    p = Path(path)
    src = str(p)
    raw = read_bytes(p, PlanError, "plan.json", cap="plan_bytes")
    sha = digest(raw)             # the twin's stamp is checked against it, and the flight names the plan by it
    twin = read_twin(p, raw, json_digest=sha)
    if twin is None:
        data, arrays = parse_json(decode_text(raw, p, PlanError), src, PlanError), None
    else:
        (header, arrays), raw = twin, None
        data = parse_json(header, src, PlanError)
    del raw
    if not isinstance(data, dict):
        raise PlanError(src, "expected a JSON object")
    major = check_format_version(data, (PLAN_FORMAT_MAJOR, LEGACY_PLAN_MAJOR), src, PlanError).major
    if _get(data, "frame", src) != "ENU":
        raise PlanError(f"{src}: key 'frame'", f"expected 'ENU', got {brief(data['frame'])}")
    origin = _get(data, "origin", src)
    o = tuple(float(_num_array([_get(origin, k, src, "origin")], (), src, f"origin.{k}")[0])
              for k in ("lat", "lon", "alt_m"))
    if arrays is not None:
        path_xy = _num_array(arrays["path"], (2,), src, "path")
        cols = _checked_columns({k: arrays["wp_" + k] for k in ("t", "p", "v", "a")}, src, "waypoints")
        corner = arrays["wp_corner"]
        if corner.dtype != bool or corner.shape != cols["t"].shape:
            raise PlanError(f"{src}: key 'waypoints[].corner'", "expected true or false")
    else:
        path_xy = _num_array(_get(data, "path", src), (2,), src, "path")
        wps = _get(data, "waypoints", src)
        cols = _waypoint_columns(wps, src, "waypoints")
        try:
            corner = [w["corner"] for w in wps]
        except (KeyError, TypeError):
            corner = [_get(w, "corner", src, f"waypoints[{i}]") for i, w in enumerate(wps)]
        if not all(isinstance(c, bool) for c in corner):
            raise PlanError(f"{src}: key 'waypoints[].corner'", "expected true or false")
    stats = _get(data, "stats", src)
    for k in STATS_KEYS:
        _num_array([_get(stats, k, src, "stats")], (), src, f"stats.{k}")
    timings = _get(data, "timings_s", src)
    for k in TIMING_KEYS:
        _num_array([_get(timings, k, src, "timings_s")], (), src, f"timings_s.{k}")
    target = None
    if major == LEGACY_PLAN_MAJOR:
        samples = _samples(_get(data, "trajectory", src), src, "trajectory")
        if "target_enu_m" in data:
            target = _num_array([data["target_enu_m"]], (3,), src, "target_enu_m")[0]
        trajectory = None
    else:
        samples = _samples(data["samples"], src, "samples") if "samples" in data else {}
        target = _num_array([_get(data, "target_enu_m", src)], (3,), src, "target_enu_m")[0]
        wp_targets = np.stack([cols["p"], cols["v"], cols["a"]], axis=1)
        trajectory = _trajectory(data, cols["t"], wp_targets, target, src, arrays, rebuild_trajectory)
    sorties = []
    raw_sorties = data.get("sorties", [])
    if not isinstance(raw_sorties, list):
        raise PlanError(f"{src}: key 'sorties'", "expected a list")
    if arrays is not None:
        counts = arrays["so_count"]
        if counts.dtype != np.int64 or counts.shape != (len(raw_sorties),) or np.any(counts < 0) \
                or int(counts.sum()) != len(arrays["so_t"]):
            raise PlanError(f"{src}: key 'sorties'", "the twin's sortie way-point counts do not match")
        ends = np.cumsum(counts).tolist()
    for j, so in enumerate(raw_sorties):
        if arrays is not None:
            b, e = ends[j] - int(counts[j]), ends[j]
            cols_s = _checked_columns({k: arrays["so_" + k][b:e] for k in ("t", "p", "v", "a")}, src,
                                      f"sorties[{j}].waypoints")
        else:
            cols_s = _waypoint_columns(_get(so, "waypoints", src, f"sorties[{j}]"), src, f"sorties[{j}].waypoints")
        sorties.append({"waypoint_t_s": cols_s["t"], "waypoint_p_enu_m": cols_s["p"],
                        "waypoint_v_enu_m_s": cols_s["v"], "waypoint_a_enu_m_s2": cols_s["a"]})
    return PlanFile(origin=o, path_xy_m=path_xy, waypoint_t_s=cols["t"], waypoint_p_enu_m=cols["p"],
                    waypoint_v_enu_m_s=cols["v"], waypoint_a_enu_m_s2=cols["a"],
                    waypoint_corner=np.array(corner, dtype=bool), t_s=samples.get("t"),
                    p_enu_m=samples.get("p"), v_enu_m_s=samples.get("v"), a_enu_m_s2=samples.get("a"),
                    pointing_enu=samples.get("pointing"), target_enu_m=target, stats=dict(stats),
                    timings_s=dict(timings), data=data, source=src, sorties=sorties,
                    trajectory=trajectory, format_major=major, sha256_hex=sha.tobytes().hex())


# --- QGroundControl exports ------------------------------------------------------

def _plan_margins(plan, mission: Mission):
    from .margins import plan_margins

    m = getattr(plan, "margins", None)
    return m if m is not None else plan_margins(mission, plan.grid, plan.coverage)


def flight_items(plan, mission: Mission, sortie=None, fence_enu_m: np.ndarray | None = None):
    """The flight-ready items (``companion.mission_items``) of one sortie of a plan
    (``plan.sorties.sorties[i]``; default: the whole route, launched under its first
    way-point), with the inclusion fence around the field (:func:`field_fence`) and
    the way-points' acceptance radius (``companion.margins``)."""
    from .mission_items import build_flight_items

    h = mission.home
    fence = field_fence(plan, mission) if fence_enu_m is None else fence_enu_m
    acc = _plan_margins(plan, mission).acceptance_radius_m
    if sortie is None:
        return build_flight_items(plan.waypoints.p_enu_m, plan.target_enu_m, (h.lat, h.lon, h.alt_m),
                                  mission.flight.speed_m_s, fence_enu_m=fence, acceptance_radius_m=acc)
    return build_flight_items(sortie.waypoints.p_enu_m, plan.target_enu_m, (h.lat, h.lon, h.alt_m),
                              mission.flight.speed_m_s, launch_enu_m=plan.sorties.launch_xy_m,
                              fence_enu_m=fence, speed_changes=sortie.speed_changes, acceptance_radius_m=acc)


def field_fence(plan, mission: Mission) -> np.ndarray:
    """(K, 2) ENU inclusion fence around the field (``coverage.boundary``), grown so
    that the path keeps the fence margin (``companion.margins``) inside it: the path
    keeps the planning clearance (less half a cell) from the field's edge, so the
    field is grown by the rest, plus two cells for the raster's slack
    (``field_boundary`` keeps ``grow - h`` from the field's cells)."""
    from .coverage.boundary import field_boundary

    m = _plan_margins(plan, mission)
    h = plan.grid.resolution_m
    grow = max(0.0, m.fence_margin_m - m.clearance_m) + 2.0 * h
    return field_boundary(plan.grid, h, grow_m=grow)


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
