"""The campaign's summary: outcome rates with Wilson 95 % intervals, distributions
of the key figures, the worst flights; ``summary.md``, PNG figures and one
self-contained ``summary.html`` (figures inline as ``data:`` URIs, no network).
"""

from __future__ import annotations

import base64
import html
import math
from pathlib import Path

import numpy as np

from .results import OUTCOMES

#: two-sided 95 % normal quantile, scipy.stats.norm.ppf(0.975)
Z95 = 1.959963984540054

#: (column, label, unit scale, unit) of the distributions
FIGURES = (
    ("min_clearance_m", "true min clearance", 1.0, "m"),
    ("tracking_max_error_m", "tracking max error", 1e3, "mm"),
    ("tracking_rms_error_m", "tracking RMS error", 1e3, "mm"),
    ("max_lateral_deviation_m", "max lateral deviation", 1.0, "m"),
    ("extra_path_m", "extra path", 1.0, "m"),
    ("ceiling_margin_m", "avoiding reference under the ceiling", 1.0, "m"),
)


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion k/n (Wilson 1927; Agresti & Coull 1998, eq. 2).

    ``(p + z^2/2n -+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n)``; with k = 0 the
    upper bound is z^2 / (n + z^2) (about 3.84/n: the "rule of three")."""
    if n <= 0:
        return (0.0, 1.0)
    p = k / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z / den * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return (max(0.0, centre - half), min(1.0, centre + half))


def _values(rows, col, scale=1.0):
    return np.array([r[col] * scale for r in rows if r.get(col) is not None and math.isfinite(r[col])], float)


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def outcome_table(rows: list[dict]) -> list[tuple[str, int, float, float, float]]:
    """(outcome, count, rate, Wilson low, Wilson high) for each outcome."""
    n = len(rows)
    out = []
    for k in OUTCOMES:
        c = sum(1 for r in rows if r["outcome"] == k)
        lo, hi = wilson_interval(c, n)
        out.append((k, c, c / n if n else 0.0, lo, hi))
    return out


def distribution_table(rows: list[dict]) -> list[tuple[str, str, int, list[float]]]:
    """(label, unit, n, [min, p5, median, p95, max]) of each figure."""
    out = []
    for col, label, scale, unit in FIGURES:
        v = _values(rows, col, scale)
        q = [float(x) for x in np.percentile(v, [0, 5, 50, 95, 100])] if len(v) else []
        out.append((label, unit, len(v), q))
    return out


def worst(rows: list[dict], n: int = 5) -> list[dict]:
    """Flights that did not complete first (crashed, failed, held), then the lowest clearances."""
    rank = {"crashed": 0, "failed": 1, "held": 2, "completed": 3}
    key = (lambda r: (rank[r["outcome"]], r["min_clearance_m"] if r.get("min_clearance_m") is not None
                      else math.inf, -(r.get("tracking_max_error_m") or 0.0)))
    return sorted(rows, key=key)[:n]


def reproduce_command(row: dict, out: Path) -> str:
    return f"companion demo --scenario {out / 'scenarios' / (str(row['scenario']).zfill(4) + '.yaml')}"


def sight_note(row: dict) -> str:
    """How long the mover that came closest had been in sight (``campaign.sight``), for a
    flight with movers; "" otherwise. A mover hidden until it was within the vehicle's
    stopping distance could not have been avoided."""
    s = row.get("mover_in_sight_s")
    if s is None:
        return ""
    m = row.get("mover_sighted_m")
    return "nearest mover hidden (no line of sight)" if m is None else \
        f"nearest mover in sight {s:.1f} s, first at {m:.2f} m"


def markdown(name: str, rows: list[dict], out: Path, wall_s: float | None, figures: list[Path]) -> str:
    n = len(rows)
    lines = [f"# Campaign {name}", "",
             f"{n} flights" + (f", {wall_s:.0f} s wall" if wall_s is not None else "")
             + (f", median {np.median(_values(rows, 'wall_s')):.1f} s per flight" if n else "") + ".", "",
             "## Outcomes (Wilson 95 % interval)", "",
             "| outcome | flights | rate | 95 % interval |", "|---|---|---|---|"]
    for k, c, p, lo, hi in outcome_table(rows):
        lines.append(f"| {k} | {c} | {_pct(p)} | {_pct(lo)} - {_pct(hi)} |")
    lines += ["", "## Distributions", "", "| figure | flights | min | 5 % | median | 95 % | max |",
              "|---|---|---|---|---|---|---|"]
    for label, unit, m, q in distribution_table(rows):
        cells = " | ".join(f"{x:.3g} {unit}" for x in q) if q else " | ".join(["n/a"] * 5)
        lines.append(f"| {label} | {m} | {cells} |")
    lines += ["", "## Worst flights", "", "| scenario | outcome | clearance | tracking max | reason | reproduce |",
              "|---|---|---|---|---|---|"]
    for r in worst(rows):
        c = "n/a" if r.get("min_clearance_m") is None else f"{r['min_clearance_m']:.3f} m"
        t = "n/a" if r.get("tracking_max_error_m") is None else f"{r['tracking_max_error_m'] * 1e3:.1f} mm"
        reason = "; ".join(x for x in ((r.get("reason") or "")[:80], sight_note(r)) if x).replace("|", "/")
        lines.append(f"| {r['scenario']} | {r['outcome']} | {c} | {t} | {reason} | "
                     f"`{reproduce_command(r, out)}` |")
    if figures:
        lines += ["", "## Figures", ""] + [f"![{f.stem}]({f.name})" for f in figures]
    return "\n".join(lines) + "\n"


def write_figures(rows: list[dict], out: Path, fields: dict | None = None) -> list[Path]:
    """Histograms of the figures and, per base mission, a map of its field with where each
    failure happened (PNG; ``fields``: mission reference -> ``scenarios.Field`` or None)."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return []
    paths = []
    for col, label, scale, unit in FIGURES:
        v = _values(rows, col, scale)
        if not len(v):
            continue
        fig, ax = plt.subplots(figsize=(5, 3.2))
        ax.hist(v, bins=min(30, max(5, len(v) // 3)), color="#4477aa")
        ax.set_xlabel(f"{label} ({unit})")
        ax.set_ylabel("flights")
        fig.tight_layout()
        p = out / f"hist_{col}.png"
        fig.savefig(p, dpi=100)
        plt.close(fig)
        paths.append(p)
    for name, field, mine in map_groups(rows, fields):
        paths.append(_failure_map(plt, out / name, field, mine))
    return paths


def _mission_slug(ref: str) -> str:
    """A file-name part for a mission reference (a bundled name, or a path: its folder's name)."""
    p = Path(ref)
    stem = p.parent.name if p.suffix in (".yaml", ".yml") else p.name
    return "".join(c if c.isalnum() or c in "-_" else "-" for c in stem) or "mission"


def map_groups(rows: list[dict], fields: dict | None) -> list[tuple[str, object, list[dict]]]:
    """(file name, Field or None, the rows flown on it) of each failure map: one map per base
    mission, since the missions' fields have their own frames (``map_failures.png`` when there
    is one, ``map_failures_<mission>.png`` each when there are several); a flight's point is
    drawn on its own mission's map only."""
    fields = fields or {}
    names = list(dict.fromkeys([*fields, *(r.get("mission") for r in rows if r.get("mission"))]))
    if len(names) <= 1:
        return [("map_failures.png", fields.get(names[0]) if names else None, list(rows))]
    return [(f"map_failures_{_mission_slug(n)}.png", fields.get(n), [r for r in rows if r.get("mission") == n])
            for n in names]


def _failure_map(plt, p: Path, field, rows: list[dict]) -> Path:
    """One field's map (its grid and flown plan: the whole trajectory where some flights fly it)
    with where each of ``rows`` that did not complete ended (PNG at ``p``)."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    if field is not None:
        g = field.grid
        rows_, cols_ = g.shape
        x0, y0 = g.origin_xy_m
        ax.imshow(~g.free, origin="lower", cmap="Greys", alpha=0.4,
                  extent=(x0, x0 + cols_ * g.resolution_m, y0, y0 + rows_ * g.resolution_m))
        whole = getattr(field, "whole", None)
        path = field.path if whole is None else whole.path
        ax.plot(path[:, 0], path[:, 1], "-", color="#4477aa", lw=0.8,
                label="flown plan" if whole is None else "flown plan (whole)")
    colours = {"crashed": "#cc3311", "failed": "#ee7733", "held": "#ccbb44"}
    for k, c in colours.items():
        pts = [(r["crash_x_m"] if r.get("crash_x_m") is not None else r.get("event_x_m"),
                r["crash_y_m"] if r.get("crash_y_m") is not None else r.get("event_y_m"))
               for r in rows if r["outcome"] == k]
        pts = [q for q in pts if q[0] is not None]
        if pts:
            a = np.array(pts)
            ax.scatter(a[:, 0], a[:, 1], s=30, color=c, label=f"{k} ({len(pts)})", zorder=3)
    ax.set_aspect("equal")
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    ax.set_title("where flights did not complete" + (f": {p.stem[len('map_failures_'):]}"
                                                     if p.stem.startswith("map_failures_") else ""))
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(p, dpi=100)
    plt.close(fig)
    return p


def html_page(name: str, rows: list[dict], out: Path, wall_s: float | None, figures: list[Path]) -> str:
    """One self-contained page: the tables of summary.md and the figures as data: URIs."""
    e = html.escape
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>Campaign {e(name)}</title>",
             "<style>body{font-family:sans-serif;max-width:70em;margin:2em auto}table{border-collapse:collapse}"
             "td,th{border:1px solid #ccc;padding:3px 8px;text-align:left}code{font-size:85%}</style></head><body>",
             f"<h1>Campaign {e(name)}</h1><p>{len(rows)} flights"
             + (f", {wall_s:.0f} s wall" if wall_s is not None else "") + ".</p>",
             "<h2>Outcomes (Wilson 95 % interval)</h2><table><tr><th>outcome</th><th>flights</th><th>rate</th>"
             "<th>95 % interval</th></tr>"]
    for k, c, p, lo, hi in outcome_table(rows):
        parts.append(f"<tr><td>{k}</td><td>{c}</td><td>{_pct(p)}</td><td>{_pct(lo)} - {_pct(hi)}</td></tr>")
    parts.append("</table><h2>Distributions</h2><table><tr><th>figure</th><th>flights</th><th>min</th><th>5 %</th>"
                 "<th>median</th><th>95 %</th><th>max</th></tr>")
    for label, unit, m, q in distribution_table(rows):
        cells = "".join(f"<td>{x:.3g} {unit}</td>" for x in q) if q else "<td>n/a</td>" * 5
        parts.append(f"<tr><td>{e(label)}</td><td>{m}</td>{cells}</tr>")
    parts.append("</table><h2>Worst flights</h2><table><tr><th>scenario</th><th>outcome</th><th>clearance (m)</th>"
                 "<th>reason</th><th>reproduce</th></tr>")
    for r in worst(rows):
        c = "n/a" if r.get("min_clearance_m") is None else f"{r['min_clearance_m']:.3f}"
        parts.append(f"<tr><td>{r['scenario']}</td><td>{r['outcome']}</td><td>{c}</td>"
                     f"<td>{e('; '.join(x for x in ((r.get('reason') or '')[:120], sight_note(r)) if x))}</td>"
                     f"<td><code>{e(reproduce_command(r, out))}</code></td></tr>")
    parts.append("</table>")
    for f in figures:
        data = base64.b64encode(f.read_bytes()).decode("ascii")
        parts.append(f"<h3>{e(f.stem)}</h3><img alt='{e(f.stem)}' src='data:image/png;base64,{data}'>")
    parts.append("</body></html>\n")
    return "".join(parts)


def write_summary(name: str, rows: list[dict], out: Path, wall_s: float | None = None,
                  fields: dict | None = None) -> list[Path]:
    """summary.md, the figures and summary.html in ``out``; returns the files written
    (``fields``: mission reference -> ``scenarios.Field``, for the maps)."""
    figures = write_figures(rows, out, fields)
    (out / "summary.md").write_text(markdown(name, rows, out, wall_s, figures), encoding="utf-8")
    (out / "summary.html").write_text(html_page(name, rows, out, wall_s, figures), encoding="utf-8")
    return [out / "summary.md", out / "summary.html", *figures]
