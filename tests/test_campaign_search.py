"""The falsification search: its score, and CMA-ES driving the flights toward the worst case."""

from __future__ import annotations

import argparse
import math

import pytest

pytest.importorskip("cma")
pytest.importorskip("dask.distributed")

from companion.campaign.results import make_row  # noqa: E402
from companion.campaign.scenario_file import load_scenario  # noqa: E402
from companion.campaign.search import CRASH_SCORE, run_search, score  # noqa: E402
from companion.campaign.spec import spec_from_dict  # noqa: E402


def test_score():
    row = {"outcome": "completed", "min_clearance_m": 0.7, "tracking_max_error_m": 0.03}
    assert score(row, "clearance") == 0.7
    assert score(row, "tracking", 0.1) == pytest.approx(0.07)
    assert score(dict(row, outcome="crashed"), "clearance") == CRASH_SCORE
    assert score(dict(row, outcome="held"), "clearance") == 0.7


def _fly(s, out, keep, transport):
    """Fake flight: the clearance falls with the wind toward 200 deg (ENU, from east)."""
    from companion.campaign.results import make_row as row

    w = s["overrides"]["sim"]["wind"]["mean_enu_m_s"]
    along = w[0] * math.cos(math.radians(200)) + w[1] * math.sin(math.radians(200))
    return row(s, {"completed": True, "crashed": False, "replanning": {"min_clearance_m": 3.0 - along}}, None, 0.0)


def test_cma_finds_the_worst_wind_and_writes_reproducible_scenarios(tmp_path):
    from dask.distributed import Client

    spec = spec_from_dict({"name": "s", "missions": ["flat-rectangle"], "flights": 1, "seed": 4, "cut_s": 5.0,
                           "wind": {"speed_m_s": [0.0, 2.0], "direction_deg": [0.0, 360.0]}}, "s.yaml")
    args = argparse.Namespace(spec="s.yaml", search="clearance", budget=64, tracking_bound=0.1, transport=None,
                              quiet=True, scheduler=None, workers=None)
    with Client(processes=False, n_workers=1, threads_per_worker=4, dashboard_address=None) as client:
        assert run_search(spec, {"flat-rectangle": None}, tmp_path, args, client=client, fly=_fly) == 0
    worst = (tmp_path / "search" / "worst.md").read_text()
    first = worst.splitlines()[4]
    k, best = int(first.split("|")[1]), float(first.split("|")[2])
    assert 1.0 <= best < 1.1
    # the true worst is 2 m/s toward 200 deg: clearance 1.0 m
    sc = load_scenario(tmp_path / "search" / "scenarios" / f"{k:04d}.yaml")
    w = sc.overrides["sim"]["wind"]["mean_enu_m_s"]
    assert math.hypot(w[0], w[1]) > 1.8
    assert abs(math.degrees(math.atan2(w[1], w[0])) % 360 - 200.0) < 20.0
    assert "companion demo --scenario" in worst
    assert len(list((tmp_path / "search" / "results").glob("*.json"))) == 64
