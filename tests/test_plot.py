"""plan.png (``companion.plot``) as a matplotlib figure: the sorties in distinct
colours with a legend, and the launch point."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")


def test_plan_figure_shows_sorties_and_launch(multi_sortie_plan):
    from matplotlib.colors import to_rgb

    from companion.plot import plan_figure

    _, plan = multi_sortie_plan
    fig = plan_figure(plan, "t")
    ax = fig.axes[0]
    for a in fig.axes:
        assert a.get_xlabel().strip() and a.get_ylabel().strip()
    labels = ax.get_legend_handles_labels()[1]
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    sorties = plan.sorties.sorties
    colours = set()
    for s in sorties:
        (name,) = [lab for lab in labels if lab.startswith(f"sortie {s.index}:")]
        ln = lines[name]
        np.testing.assert_array_equal(np.column_stack([ln.get_xdata(), ln.get_ydata()]),
                                      np.asarray(s.waypoints.p_enu_m)[:, :2])
        colours.add(to_rgb(ln.get_color()))
    assert len(colours) == len(sorties)                     # one colour each
    assert "launch point" in labels
    launch = lines["launch point"]
    np.testing.assert_array_equal([launch.get_xdata()[0], launch.get_ydata()[0]], plan.sorties.launch_xy_m)


def test_plan_title_gives_a_compass_bearing(multi_sortie_plan):
    from companion.plot import plan_figure

    _, plan = multi_sortie_plan
    # flat-rectangle's lines run east-west: ENU orientation 0 deg, compass bearing 90 deg
    assert "compass bearing 90.0 deg" in plan_figure(plan).axes[0].get_title()
