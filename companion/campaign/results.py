"""One row per flight: outcome classification, the row, and the table (Parquet + CSV).

Outcome (the rules of ``benchmarks/bench_obstacles_sitl.py``), from report.json:

- ``crashed``: ``crashed`` true (the SITL's ground truth);
- ``completed``: ``completed`` true (no violation, landed and disarmed);
- ``held``: the replanner found no route, held and reported (``violation.kind`` ``no_route``);
- ``failed``: anything else (another violation, no report, an error, a worker that died twice).
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

from .scenarios import scenario_hash, scenario_params

OUTCOMES = ("completed", "held", "crashed", "failed")

#: (column, pyarrow type name) of the results table, in order
COLUMNS = (
    ("scenario", "int64"), ("hash", "string"), ("campaign", "string"), ("mission", "string"),
    ("control", "string"), ("seed", "int64"), ("cut_s", "float64"),
    ("n_obstacles", "int64"), ("max_obstacle_height_m", "float64"), ("obstacles", "string"),
    ("wind_east_m_s", "float64"), ("wind_north_m_s", "float64"), ("wind_speed_m_s", "float64"),
    ("gust_std_m_s", "float64"), ("sensor_profile", "string"), ("velocity_std_m_s", "float64"),
    ("position_std_m", "float64"), ("gyro_bias_rad_s", "float64"), ("range_std_m", "float64"),
    ("range_dropout_probability", "float64"), ("link_loss", "float64"), ("link_delay_min_ms", "float64"),
    ("link_delay_max_ms", "float64"), ("start_x_m", "float64"), ("start_y_m", "float64"),
    ("outcome", "string"), ("reason", "string"), ("violation_kind", "string"),
    ("crash_x_m", "float64"), ("crash_y_m", "float64"), ("event_x_m", "float64"), ("event_y_m", "float64"),
    ("min_clearance_m", "float64"), ("tracking_max_error_m", "float64"), ("tracking_rms_error_m", "float64"),
    ("max_lateral_deviation_m", "float64"), ("extra_path_m", "float64"), ("replan_events", "int64"),
    ("coverage_fraction", "float64"), ("path_flown_fraction", "float64"), ("sim_time_s", "float64"),
    ("ceiling_margin_m", "float64"), ("mover_in_sight_s", "float64"), ("mover_sighted_m", "float64"),
    ("wall_s", "float64"), ("kept", "string"),
)
#: wall-clock columns: not reproducible, left out when two tables are compared
WALL_COLUMNS = ("wall_s",)


def classify(report: dict | None, error: str | None = None) -> tuple[str, str | None]:
    """(outcome, reason) of one flight from its report.json dict (None: no report)."""
    if report is None:
        return "failed", error or "no report.json"
    v = report.get("violation") or {}
    if report.get("crashed"):
        crash = report.get("crash") or {}
        return "crashed", crash.get("text") or v.get("detail") or "crashed"
    if report.get("completed"):
        return "completed", None
    if v.get("kind") == "no_route":
        return "held", v.get("detail") or "no route"
    return "failed", report.get("error") or v.get("detail") or report.get("phase") or error or "not completed"


def _where(report: dict) -> tuple[float | None, float | None]:
    """Where the flight went wrong (ENU m): the last replanning event's position, else None."""
    events = (report.get("replanning") or {}).get("event_list") or []
    for e in reversed(events):
        p = e.get("pos_enu_m")
        if p and all(c is not None for c in p[:2]):
            return float(p[0]), float(p[1])
    return None, None


def _ceiling_margin(rp: dict) -> float | None:
    """How far (m) the avoiding reference stayed under the replan ceiling above the terrain
    (negative: above it); None when it never avoided or the report predates the figure."""
    h, c = rp.get("max_height_agl_m"), rp.get("ceiling_agl_m")
    if h is None or c is None or not math.isfinite(c):
        return None
    return float(c) - float(h)


def make_row(scenario: dict, report: dict | None, error: str | None, wall_s: float, kept: str | None = None,
             crash_xy: tuple[float, float] | None = None, sight: dict | None = None) -> dict:
    """The table row of one flight (plain types: it travels back from a worker as a small dict).
    ``sight``: the line-of-sight columns of a flight with movers (``campaign.sight``)."""
    outcome, reason = classify(report, error)
    r = report or {}
    rp = r.get("replanning") or {}
    tr = r.get("tracking") or {}
    ex, ey = _where(r)
    row = {"scenario": scenario["scenario"], "hash": scenario_hash(scenario), "campaign": scenario["campaign"],
           "mission": scenario["mission"], "control": scenario["control"], "seed": scenario["seed"],
           "cut_s": scenario.get("cut_s"), **scenario_params(scenario),
           "outcome": outcome, "reason": reason, "violation_kind": (r.get("violation") or {}).get("kind"),
           "crash_x_m": None if crash_xy is None else crash_xy[0],
           "crash_y_m": None if crash_xy is None else crash_xy[1],
           "event_x_m": ex, "event_y_m": ey,
           "min_clearance_m": rp.get("min_clearance_m"), "tracking_max_error_m": tr.get("max_error_m"),
           "tracking_rms_error_m": tr.get("rms_error_m"),
           "max_lateral_deviation_m": rp.get("max_lateral_deviation_m"), "extra_path_m": rp.get("extra_path_m"),
           "replan_events": rp.get("events"), "coverage_fraction": r.get("coverage_fraction"),
           "path_flown_fraction": r.get("path_flown_fraction"), "sim_time_s": r.get("sim_time_s"),
           "ceiling_margin_m": _ceiling_margin(rp),
           "wall_s": round(float(wall_s), 3), "kept": kept, **(sight or {})}
    return {name: row.get(name) for name, _ in COLUMNS}


def write_result(results_dir: Path, row: dict) -> Path:
    """``results_dir/<hash>.json``, written atomically (a crash never leaves half a result)."""
    results_dir.mkdir(parents=True, exist_ok=True)
    p = results_dir / f"{row['hash']}.json"
    tmp = p.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(row, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(tmp, p)
    return p


def read_results(results_dir: Path) -> dict[str, dict]:
    """hash -> row of every finished flight."""
    out = {}
    if results_dir.is_dir():
        for p in sorted(results_dir.glob("*.json")):
            row = json.loads(p.read_text(encoding="utf-8"))
            out[row["hash"]] = row
    return out


def table(rows: list[dict]):
    """The rows as a ``pyarrow.Table`` sorted by scenario index, with the fixed schema ``COLUMNS``."""
    import pyarrow as pa

    schema = pa.schema([(n, getattr(pa, t)()) for n, t in COLUMNS])
    rows = sorted(rows, key=lambda r: (r["scenario"], r["hash"]))
    return pa.Table.from_pylist([{n: r.get(n) for n, _ in COLUMNS} for r in rows], schema=schema)


def write_table(rows: list[dict], out: Path) -> tuple[Path, Path]:
    """``out/results.parquet`` and ``out/results.csv``."""
    import pyarrow.csv as pcsv
    import pyarrow.parquet as pq

    t = table(rows)
    pq.write_table(t, out / "results.parquet")
    pcsv.write_csv(t, out / "results.csv")
    return out / "results.parquet", out / "results.csv"
