"""The self-contained HTML map (``companion.html_map``): the SVG transform by
hand, then the page of a flight rendered by a real headless Chromium, its
screenshot checked at pixels predicted from the plan's coordinates, and no
network (the page's CSP counts every blocked fetch; a planted one is caught)."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from companion.html_map import HEIGHT_PX, MARGIN_PX, WIDTH_PX, MapView, html_map_text
from companion.map_layers import LAYER_COLOURS, sortie_colour

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
WINDOW = (1200, 900)


def test_map_view_hand_worked():
    # extent 100 m x 50 m into 1000 x 600 px with a 20 px margin:
    # scale = min(960 / 100, 560 / 50) = 9.6 px/m; centre (50, 25) m -> (500, 300) px
    v = MapView(0.0, 100.0, 0.0, 50.0, 1000, 600, 20)
    assert v.scale_px_m == pytest.approx(9.6)
    c, r = v.to_px(np.array([0.0, 100.0, 50.0]), np.array([0.0, 50.0, 25.0]))
    np.testing.assert_allclose(c, [500 - 50 * 9.6, 500 + 50 * 9.6, 500])   # 20, 980, 500
    np.testing.assert_allclose(r, [300 + 25 * 9.6, 300 - 25 * 9.6, 300])   # 540 (south is down), 60, 300
    f = MapView.fit(np.array([[3.0, 7.0], [3.0, 7.0]]))        # one point: a 1 m extent about it
    assert (f.x_min, f.x_max, f.y_min, f.y_max) == (2.5, 3.5, 6.5, 7.5)


@pytest.fixture(scope="module")
def flight_layers(multi_sortie_plan):
    """flat-rectangle with several sorties, a made-up flown track (a 1 m circle
    about (6, 6.25) m) and a box obstacle between a row and a lane."""
    from companion.map_layers import plan_layers, with_flight
    from mavcore.mission.sim import ObstacleConfig

    m, plan = multi_sortie_plan
    th = np.linspace(0, 2 * np.pi, 200)
    flown = np.column_stack([6.0 + np.cos(th), 6.25 + np.sin(th), np.full_like(th, 1.5)])
    box = ObstacleConfig(type="box", x=17.0, y=5.6, height=2.0, size_x=1.0, size_y=0.6)
    return plan, with_flight(plan_layers(plan, m), flown, [box])


def test_page_is_self_contained(flight_layers):
    _, layers = flight_layers
    text = html_map_text(layers)
    # no URL, no external resource of any kind
    for needle in ("http:", "https:", "//", "src=", "href=", "url(", "@import"):
        assert needle not in text.replace("<!--", ""), needle
    assert "Content-Security-Policy" in text and "default-src 'none'" in text


def rgb(hex_colour: str) -> np.ndarray:
    return np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)])


def colour_near(img: np.ndarray, col: float, row: float, colour: str, radius: int, tol: int = 12) -> bool:
    """Whether a pixel within ``radius`` px of (col, row) has ``colour`` (+-tol per channel)."""
    c, r = int(round(col)), int(round(row))
    win = img[max(0, r - radius): r + radius + 1, max(0, c - radius): c + radius + 1, :3].astype(int)
    return bool(np.any(np.all(np.abs(win - rgb(colour)) <= tol, axis=-1)))


def line_near(img: np.ndarray, col: float, row: float, colour: str, radius: int = 2) -> bool:
    """Whether a pixel within ``radius`` px of (col, row) is ``colour`` over white with at
    least half coverage (an anti-aliased line of width >= 1 px has such a pixel)."""
    c, r = int(round(col)), int(round(row))
    win = img[max(0, r - radius): r + radius + 1, max(0, c - radius): c + radius + 1, :3].reshape(-1, 3)
    d = 255.0 - rgb(colour)
    alpha = (255.0 - win) @ d / (d @ d)
    resid = np.abs(win - (255.0 - alpha[:, None] * d)).max(axis=1)
    return bool(np.any((alpha >= 0.5) & (resid <= 12)))


def chromium(*args, timeout=60) -> subprocess.CompletedProcess:
    return subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                           "--force-device-scale-factor=1", *args], capture_output=True, text=True,
                          timeout=timeout)


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (apt-get install chromium; .ci/run does)")
def test_chromium_screenshot_and_no_network(flight_layers, tmp_path):
    Image = pytest.importorskip("PIL.Image")
    plan, layers = flight_layers
    page = tmp_path / "map.html"
    page.write_text(html_map_text(layers, "flight"), encoding="utf-8")
    shot = tmp_path / "shot.png"
    # one run: the screenshot, and the DOM after the page's script ran
    dom = chromium(f"--screenshot={shot}", "--dump-dom", f"--window-size={WINDOW[0]},{WINDOW[1]}",
                   page.as_uri()).stdout
    img = np.asarray(Image.open(shot).convert("RGB"))
    assert img.shape[:2] == (WINDOW[1], WINDOW[0])
    # not blank: many non-white pixels, many colours
    assert np.mean(np.any(img < 245, axis=-1)) > 0.01
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 20

    # the transform the page must have used, from the plan's own coordinates
    view = MapView.fit(layers.all_xy_m())
    assert MARGIN_PX < view.scale_px_m * 23 < WIDTH_PX      # the 23 m field fills the drawing
    wp = np.asarray(plan.waypoints.p_enu_m)
    cols, rows = view.to_px(wp[:, 0], wp[:, 1])
    assert np.all((cols > 0) & (cols < WIDTH_PX) & (rows > 0) & (rows < HEIGHT_PX))
    # the route's band (9 px wide, sorties drawn along its middle) at every way-point
    for c, r in zip(cols, rows):
        assert colour_near(img, c, r, LAYER_COLOURS["path"], radius=5), (c, r)
    # every sortie's colour at one of its way-points at least
    for s in plan.sorties.sorties:
        sc, sr = view.to_px(s.waypoints.p_enu_m[:, 0], s.waypoints.p_enu_m[:, 1])
        assert any(colour_near(img, c, r, sortie_colour(s.index), radius=1) for c, r in zip(sc, sr)), s.index
    lc, lr = view.to_px(*plan.sorties.launch_xy_m)
    assert colour_near(img, lc, lr, LAYER_COLOURS["launch"], radius=1)
    # the middle row (y = 5 m, x 2.5..20.5 m) at x = 6 m; the flown circle; the obstacle's centre
    assert line_near(img, *view.to_px(6.0, 5.0), LAYER_COLOURS["rows"])
    assert line_near(img, *view.to_px(6.0, 7.25), LAYER_COLOURS["flown"])
    assert line_near(img, *view.to_px(5.0, 6.25), LAYER_COLOURS["flown"])
    obstacle_on_white = np.round(0.75 * rgb(LAYER_COLOURS["obstacles"]) + 0.25 * 255)
    assert colour_near(img, *view.to_px(17.0, 5.6), "#%02x%02x%02x" % tuple(int(v) for v in obstacle_on_white),
                       radius=0, tol=3)
    # ... and not where nothing is drawn: between the fence and the route, south-west
    assert not colour_near(img, *view.to_px(11.5, 0.05), LAYER_COLOURS["path"], radius=2)

    # no network: the page's script ran under its CSP and counted no blocked fetch ...
    body = re.search(r"<body[^>]*>", dom).group(0)
    assert 'data-ready="1"' in body and 'data-csp-violations="0"' in body, body
    # ... and a page that does fetch something is caught by the same count
    bad = tmp_path / "bad.html"
    bad.write_text(page.read_text().replace('data-csp-violations="0">',
                                            'data-csp-violations="0"><img src="http://127.0.0.1:9/t.png">'))
    body = re.search(r"<body[^>]*>", chromium("--dump-dom", bad.as_uri()).stdout).group(0)
    assert 'data-csp-violations="0"' not in body, body
