"""The flight figures (``companion.flight_plot``) as matplotlib objects: every
axis labelled, compass headings on hand-worked yaws, the height above a
hand-worked tilted DEM, the rows and obstacles drawn under the path."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from companion.flight_plot import compass_heading_deg, flight_figures  # noqa: E402
from mavcore.maps import load_ogm  # noqa: E402
from mavcore.maps.grid import ElevationModel  # noqa: E402
from mavcore.mission.sim import ObstacleConfig  # noqa: E402
from companion.runner import FlightLog, _PHASE_CODE  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: (ENU yaw deg, counter-clockwise from east) -> compass heading (deg, clockwise from north)
YAWS = [(0.0, 90.0), (30.0, 60.0), (90.0, 0.0), (135.0, 315.0), (180.0, 270.0), (-90.0, 180.0), (-150.0, 240.0)]
SAMPLES_PER_YAW = 10
#: tilted plane z = 0.1 x + 0.05 y (m), 1 m cells from (0, 0) to (40, 40)
SLOPE = (0.1, 0.05)
AGL_TRUE_M, AGL_REF_M = 1.5, 2.0


def rz(yaw_rad: float) -> np.ndarray:
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def tilted_dem() -> ElevationModel:
    r, c = np.mgrid[0:41, 0:41].astype(float)
    return ElevationModel(heights_m=SLOPE[0] * c + SLOPE[1] * r, x0_m=0.0, y0_m=0.0, cellsize_m=1.0)


@pytest.fixture(scope="module")
def figures():
    log = FlightLog()
    n = len(YAWS) * SAMPLES_PER_YAW
    for i in range(n):
        yaw = math.radians(YAWS[i // SAMPLES_PER_YAW][0])
        x, y = 2.0 + 0.25 * i, 3.0 + 0.05 * i
        ground = SLOPE[0] * x + SLOPE[1] * y
        R = rz(yaw)
        log.append([0.1 * i, _PHASE_CODE["trajectory"]], [x, y, ground + AGL_REF_M], [x, y, ground + AGL_TRUE_M],
                   [x, y, ground + AGL_TRUE_M], R.ravel(), R.T.ravel(), [9.81], R[:, 1])
    box = ObstacleConfig(type="box", x=12.0, y=6.0, height=2.0, size_x=1.0, size_y=0.5)
    grid = load_ogm(ROOT / "missions" / "flat-rectangle" / "map.yaml")    # rows at y = 2.5, 5, 7.5 m
    return flight_figures(log, None, obstacles=[box], dem=tilted_dem(), grid=grid)


def test_compass_heading_hand_worked():
    yaw = np.radians([y for y, _ in YAWS])
    np.testing.assert_allclose(compass_heading_deg(yaw), [h for _, h in YAWS], atol=1e-9)


def test_every_axis_is_labelled(figures):
    assert set(figures) == {"path3d", "position", "attitude", "errors", "directions"}
    for name, fig in figures.items():
        for ax in fig.axes:
            assert ax.get_xlabel().strip() and ax.get_ylabel().strip(), (name, ax.get_title())
            if hasattr(ax, "get_zlabel"):
                assert ax.get_zlabel().strip(), name
    # directions.png had no time axis: every panel has one now
    assert all("time" in ax.get_xlabel() for ax in figures["directions"].axes)


def axis_by_ylabel(fig, needle: str):
    (ax,) = [a for a in fig.axes if needle in a.get_ylabel()]
    return ax


def test_heading_is_compass(figures):
    ax = axis_by_ylabel(figures["attitude"], "heading")
    assert "clockwise from north" in ax.get_ylabel()
    expected = np.repeat([h for _, h in YAWS], SAMPLES_PER_YAW)
    for line in ax.get_lines():      # desired R_d and true R: the same attitude here
        y = np.asarray(line.get_ydata(), float)
        got = y[np.isfinite(y)]                      # NaN only where the heading crosses north
        assert len(got) == len(expected), line.get_label()
        np.testing.assert_allclose(got, expected, atol=1e-9)
    assert not any("yaw" in a.get_ylabel() for a in figures["attitude"].axes)


def test_height_above_tilted_ground(figures):
    ax = axis_by_ylabel(figures["position"], "height above ground")
    ref, true = ax.get_lines()
    # z - dem(x, y) on the plane is the constant the log was built with, though z itself climbs
    np.testing.assert_allclose(ref.get_ydata(), AGL_REF_M, atol=1e-9)
    np.testing.assert_allclose(true.get_ydata(), AGL_TRUE_M, atol=1e-9)


def test_rows_and_obstacles_under_the_path(figures):
    fig = figures["path3d"]
    top = [a for a in fig.axes if a.get_title() == "Top view"][0]
    rows = [ln for ln in top.get_lines() if ln.get_color() == "tab:green"]
    ys = sorted(float(np.mean(ln.get_ydata())) for ln in rows)
    np.testing.assert_allclose(ys, [2.5, 5.0, 7.5], atol=0.1)     # the map's rows, one 0.1 m cell
    (patch,) = top.patches
    xy = patch.get_xy()
    np.testing.assert_allclose([xy[:, 0].min(), xy[:, 0].max(), xy[:, 1].min(), xy[:, 1].max()],
                               [11.5, 12.5, 5.75, 6.25], atol=1e-9)
    labels = set(top.get_legend_handles_labels()[1])
    assert {"vine rows", "take-off", "flown", "reference"} <= labels
    ax3d = [a for a in fig.axes if hasattr(a, "get_zlabel")][0]
    # in 3D the rows lie on the terrain: z = dem(x, y) along them
    for ln in ax3d.get_lines():
        if ln.get_color() == "tab:green":
            x, y, z = ln.get_data_3d()
            np.testing.assert_allclose(z, SLOPE[0] * np.asarray(x) + SLOPE[1] * np.asarray(y), atol=1e-9)
