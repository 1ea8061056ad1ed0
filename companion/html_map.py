"""A self-contained HTML map of a plan or a flight: inline SVG, a few lines of JS (pure).

One file, no network: no tiles, no external script, style or font. The page
carries a strict Content-Security-Policy (``CSP``): anything it tried to
fetch would be blocked, and every blocked attempt is counted in the body's
``data-csp-violations`` attribute (the tests read it back). North is up;
the ENU map frame is drawn by ``MapView`` (one scale for x and y). Layers,
bottom to top: fence, vine rows, obstacles, the route (a wide band), the
sorties (one colour each), the flown track (a triangle at its take-off), the
sorties' launch point; check boxes
under the map hide and show them, and the pointer's ENU position is shown.
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass

import numpy as np

from .map_layers import LAYER_COLOURS, MapLayers, sortie_colour, sortie_legend

#: The page's Content-Security-Policy: nothing from the network, inline style and script only.
CSP = "default-src 'none'; style-src 'unsafe-inline'; script-src 'unsafe-inline'; img-src data:"
#: Size of the map drawing (CSS px) at the page's top-left corner, and its margin.
WIDTH_PX, HEIGHT_PX, MARGIN_PX = 1200, 760, 30
#: Width (px) of the route's band; the sorties are drawn on it at ``SORTIE_WIDTH_PX``.
PATH_WIDTH_PX, SORTIE_WIDTH_PX = 9.0, 2.5


@dataclass(frozen=True)
class MapView:
    """ENU (m) -> SVG pixels: the extent fitted into the drawing, centred, north up.

    ``scale = min((W - 2 m) / (x_max - x_min), (H - 2 m) / (y_max - y_min))`` px/m;
    the extent's centre goes to the drawing's centre.
    """

    x_min: float
    x_max: float
    y_min: float
    y_max: float
    width_px: float = WIDTH_PX
    height_px: float = HEIGHT_PX
    margin_px: float = MARGIN_PX

    @classmethod
    def fit(cls, xy: np.ndarray, **kw) -> "MapView":
        """The view of the points ``xy`` ((P, 2) ENU m); a degenerate extent is widened to 1 m."""
        lo, hi = np.min(xy, axis=0), np.max(xy, axis=0)
        c, half = 0.5 * (lo + hi), np.maximum(0.5 * (hi - lo), 0.5)
        return cls(float(c[0] - half[0]), float(c[0] + half[0]), float(c[1] - half[1]), float(c[1] + half[1]), **kw)

    @property
    def scale_px_m(self) -> float:
        return min((self.width_px - 2 * self.margin_px) / (self.x_max - self.x_min),
                   (self.height_px - 2 * self.margin_px) / (self.y_max - self.y_min))

    def to_px(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Pixel (column, row) of ENU points (m), from the drawing's top-left corner."""
        s = self.scale_px_m
        col = 0.5 * self.width_px + (np.asarray(x, float) - 0.5 * (self.x_min + self.x_max)) * s
        row = 0.5 * self.height_px - (np.asarray(y, float) - 0.5 * (self.y_min + self.y_max)) * s
        return col, row


def _points(view: MapView, xy: np.ndarray) -> str:
    c, r = view.to_px(xy[:, 0], xy[:, 1])
    return " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(c, r))


def _scale_bar_m(view: MapView) -> float:
    """A round length (1, 2 or 5 x 10^k m) about a sixth of the drawing's width."""
    target = (view.width_px / 6) / view.scale_px_m
    k = 10 ** math.floor(math.log10(target))
    return max(m * k for m in (1, 2, 5) if m * k <= target)


def html_map_text(layers: MapLayers, title: str = "") -> str:
    """The HTML page of ``layers`` (module doc)."""
    view = MapView.fit(layers.all_xy_m())
    esc = html.escape
    svg = []

    def group(gid: str, items: list[str]):
        svg.append(f'<g id="layer-{gid}">' + "".join(items) + "</g>")

    if len(layers.fence_xy_m) >= 3:
        group("fence", [f'<polygon points="{_points(view, np.asarray(layers.fence_xy_m, float))}" fill="none" '
                        f'stroke="{LAYER_COLOURS["fence"]}" stroke-width="1.5" stroke-dasharray="6 4"/>'])
    group("rows", [f'<polyline points="{_points(view, r)}" stroke="{LAYER_COLOURS["rows"]}" stroke-width="1.5"/>'
                   for r in np.asarray(layers.rows_xy_m, float).reshape(-1, 2, 2)])
    if layers.obstacles:
        group("obstacles", [f'<polygon points="{_points(view, np.asarray(o.ring_xy_m, float))}" '
                            f'fill="{LAYER_COLOURS["obstacles"]}" fill-opacity="0.75"><title>{esc(o.label)}</title>'
                            f'</polygon>' for o in layers.obstacles])
    group("path", [f'<polyline points="{_points(view, np.asarray(layers.path_enu_m, float))}" '
                   f'stroke="{LAYER_COLOURS["path"]}" stroke-width="{PATH_WIDTH_PX:g}" stroke-linejoin="round" '
                   f'stroke-linecap="round"/>'])
    group("sorties", [f'<polyline points="{_points(view, np.asarray(s.p_enu_m, float))}" '
                      f'stroke="{sortie_colour(s.index)}" stroke-width="{SORTIE_WIDTH_PX:g}" '
                      f'stroke-linejoin="round"><title>sortie {s.index}: {s.energy_wh:.1f} Wh, '
                      f'{s.duration_s / 60:.1f} min</title></polyline>' for s in layers.sorties])
    if layers.flown_enu_m is not None and len(layers.flown_enu_m):
        f = np.asarray(layers.flown_enu_m, float)
        c0, r0 = view.to_px(f[0, 0], f[0, 1])
        group("flown", [f'<polyline points="{_points(view, f)}" stroke="{LAYER_COLOURS["flown"]}" stroke-width="2"/>',
                        f'<path d="M{c0:.1f},{r0 - 8:.1f} l7,13 h-14 z" fill="{LAYER_COLOURS["flown"]}" '
                        f'stroke="#000"><title>take-off</title></path>'])
    if layers.launch_enu_m is not None:
        c, r = view.to_px(layers.launch_enu_m[0], layers.launch_enu_m[1])
        group("launch", [f'<circle cx="{c:.1f}" cy="{r:.1f}" r="7" fill="{LAYER_COLOURS["launch"]}" '
                         f'stroke="#000" stroke-width="1.5"><title>launch</title></circle>'])
    bar = _scale_bar_m(view)
    bx, by = MARGIN_PX, HEIGHT_PX - 12
    svg.append(f'<g id="scale"><line x1="{bx}" y1="{by}" x2="{bx + bar * view.scale_px_m:.1f}" y2="{by}" '
               f'stroke="#000" stroke-width="3"/><text x="{bx}" y="{by - 6}" font-size="12">{bar:g} m</text></g>'
               f'<g id="north"><path d="M{WIDTH_PX - 30},14 l-8,20 h16 z" fill="#000"/>'
               f'<text x="{WIDTH_PX - 34}" y="48" font-size="12">N</text></g>')

    legend = [("path", "route (way-points)", LAYER_COLOURS["path"]), ("rows", "vine rows", LAYER_COLOURS["rows"]),
              ("fence", "inclusion fence", LAYER_COLOURS["fence"])]
    legend += [("sorties", label, sortie_colour(i) if i else "linear-gradient(90deg, #9467bd, #bcbd22, #e377c2)")
               for i, label in sortie_legend([s.index for s in layers.sorties])]
    if layers.launch_enu_m is not None:
        legend.append(("launch", "launch point", LAYER_COLOURS["launch"]))
    if layers.flown_enu_m is not None and len(layers.flown_enu_m):
        legend.append(("flown", "flown track (triangle: take-off)", LAYER_COLOURS["flown"]))
    if layers.obstacles:
        legend.append(("obstacles", "obstacles", LAYER_COLOURS["obstacles"]))
    seen, boxes = set(), []
    for gid, label, colour in legend:
        box = "" if gid in seen else f'<input type="checkbox" checked data-layer="{gid}"> '
        seen.add(gid)
        boxes.append(f'<label>{box}<span class="sw" style="background:{colour}"></span>{esc(label)}</label>')
    lat, lon, alt = layers.home
    heading = esc(title or layers.name)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta http-equiv="Content-Security-Policy" content="{CSP}">
<title>{heading}</title>
<script>
var CSPV = 0;
document.addEventListener("securitypolicyviolation", function () {{
  CSPV += 1;
  if (document.body) document.body.dataset.cspViolations = String(CSPV);
}});
</script>
<style>
body {{ margin: 0; font: 13px sans-serif; background: #fff; }}
#map {{ position: absolute; left: 0; top: 0; background: #fff; }}
#map polyline {{ fill: none; }}
#panel {{ position: absolute; left: {MARGIN_PX}px; top: {HEIGHT_PX + 4}px; width: {WIDTH_PX - 2 * MARGIN_PX}px; }}
#panel label {{ margin-right: 14px; white-space: nowrap; }}
.sw {{ display: inline-block; width: 18px; height: 8px; margin-right: 4px; vertical-align: middle; }}
</style></head>
<body data-ready="0" data-csp-violations="0">
<svg id="map" width="{WIDTH_PX}" height="{HEIGHT_PX}" viewBox="0 0 {WIDTH_PX} {HEIGHT_PX}">{"".join(svg)}</svg>
<div id="panel"><b>{heading}</b> &mdash; home {lat:.7f}, {lon:.7f}, {alt:.1f} m AMSL; ENU metres, north up.
<span id="pos"></span><br>{"".join(boxes)}</div>
<script>
var V = {{s: {view.scale_px_m!r}, cx: {0.5 * (view.x_min + view.x_max)!r}, cy: {0.5 * (view.y_min + view.y_max)!r},
  w: {WIDTH_PX}, h: {HEIGHT_PX}}};
document.querySelectorAll("input[data-layer]").forEach(function (box) {{
  box.addEventListener("change", function () {{
    var g = document.getElementById("layer-" + box.dataset.layer);
    if (g) g.style.display = box.checked ? "" : "none";
  }});
}});
document.getElementById("map").addEventListener("mousemove", function (e) {{
  var x = V.cx + (e.offsetX - V.w / 2) / V.s, y = V.cy - (e.offsetY - V.h / 2) / V.s;
  document.getElementById("pos").textContent = "x " + x.toFixed(1) + " m, y " + y.toFixed(1) + " m";
}});
document.body.dataset.cspViolations = String(CSPV);
document.body.dataset.ready = "1";
</script>
</body></html>
"""
