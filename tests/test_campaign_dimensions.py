"""The campaign dimensions added for issue 16: rangefinder dropouts, a lossy
jittery link, the launch point. Drawn after every earlier dimension from
scenario i's own generator; validated like the rest of the spec."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.campaign.placement import cumulative, footprint_free
from companion.campaign.scenario_file import load_scenario, scenario_mission
from companion.campaign.scenarios import Field, continuous_dims, scenario, scenario_params, scenario_yaml
from companion.campaign.spec import load_spec, spec_from_dict
from mavcore.errors import CampaignError

BASE = {"name": "d", "missions": ["flat-rectangle"], "flights": 50, "seed": 11, "cut_s": 10.0,
        "sensors": {"velocity_std_m_s": [0.0, 0.01]},
        "wind": {"speed_m_s": [0.0, 2.0], "gust_std_m_s": 0.25}}
NEW = {"link": {"loss": [0.0, 0.3], "delay_min_ms": 5.0, "jitter_ms": [0.0, 40.0]},
       "start": {"offset_m": [0.5, 2.0], "direction_deg": [0.0, 360.0], "margin_m": 0.5}}


@pytest.fixture(scope="module")
def field():
    """30 m x 12 m free, a vine row along y = 6 m (x 5..25 m); the path starts at (2, 3)."""
    from mavcore.maps.grid import OccupancyGrid

    occ = np.zeros((120, 300), dtype=bool)
    occ[58:62, 50:250] = True
    grid = OccupancyGrid(occupied=occ, free=~occ, resolution_m=0.1, origin_xy_m=(0.0, 0.0))
    t = np.linspace(0.0, 1.0, 100)
    path = np.stack([2 + 26 * t, 3 + 0 * t, 1.5 + 0 * t], 1)
    return {"flat-rectangle": Field(grid, path, cumulative(path))}


def _spec(extra: dict):
    data = {**BASE, **extra}
    if "range_dropout_probability" in extra:
        data = {**BASE, "sensors": {**BASE["sensors"], "range_dropout_probability": extra["range_dropout_probability"]}}
    return spec_from_dict(data, "d.yaml")


def test_new_keys_move_no_earlier_draw(field):
    """A spec with the new dimensions gives every scenario the same earlier values (seed,
    noise, wind) as the spec without them: they are drawn last."""
    old = _spec({})
    new = spec_from_dict({**BASE, **NEW, "sensors": {**BASE["sensors"], "range_dropout_probability": [0.0, 0.5]}},
                         "d.yaml")
    for i in range(20):
        a, b = scenario(old, field, i), scenario(new, field, i)
        assert b["seed"] == a["seed"]
        assert b["overrides"]["sim"]["wind"] == a["overrides"]["sim"]["wind"]
        assert b["overrides"]["sim"]["noise"]["velocity_std_m_s"] == a["overrides"]["sim"]["noise"]["velocity_std_m_s"]
        assert "link" not in a and "start_enu_m" not in a["overrides"]["sim"]


def test_documented_draws_and_ranges(field):
    """Scenario 4 recomputed by hand from the documented order: seed, velocity noise,
    wind (3 draws), dropout, link (loss, min delay, jitter), start (offset, direction)."""
    spec = spec_from_dict({**BASE, **NEW, "sensors": {**BASE["sensors"], "range_dropout_probability": [0.0, 0.5]}},
                          "d.yaml")
    s = scenario(spec, field, 4)
    rng = np.random.default_rng(np.random.SeedSequence([11, 4]))
    seed = int(rng.integers(0, 2**31 - 1))
    rng.random(), rng.random(), rng.random(), rng.random()       # velocity noise, wind speed, direction, gust
    dropout = round(0.5 * rng.random(), 6)
    loss = round(0.3 * rng.random(), 6)
    d0 = round(5.0 + 0.0 * rng.random(), 6)                       # a fixed dimension still takes its draw
    jitter = round(40.0 * rng.random(), 6)
    r = 0.5 + 1.5 * rng.random()
    a = math.radians(360.0 * rng.random())
    assert s["seed"] == seed
    assert s["overrides"]["sim"]["noise"]["range_dropout_probability"] == dropout
    assert s["link"] == {"loss": loss, "delay_ms": [d0, round(d0 + jitter, 6)]}
    x, y = s["overrides"]["sim"]["start_enu_m"]
    if footprint_free(field["flat-rectangle"].grid, {"type": "cylinder", "x": round(2 + r * math.cos(a), 3),
                                                      "y": round(3 + r * math.sin(a), 3), "radius": 0.5}, 0.0):
        assert (x, y) == (round(2 + r * math.cos(a), 3), round(3 + r * math.sin(a), 3))
    for i in range(40):
        s = scenario(spec, field, i)
        x, y = s["overrides"]["sim"]["start_enu_m"]
        assert 0.5 - 1e-3 <= math.hypot(x - 2.0, y - 3.0) <= 2.0 + 1e-3
        assert footprint_free(field["flat-rectangle"].grid, {"type": "cylinder", "x": x, "y": y, "radius": 0.5}, 0.0)
        lo, hi = s["link"]["delay_ms"]
        assert 0.0 <= s["link"]["loss"] <= 0.3 and lo == 5.0 and 5.0 <= hi <= 45.0
        p = scenario_params(s)
        assert (p["start_x_m"], p["start_y_m"], p["link_loss"]) == (x, y, s["link"]["loss"])


def test_start_point_rejected_on_rows(field):
    """A launch point fixed on the vine row (y 5.8..6.2 m, x 5..25 m): (8, 6) is 6.708 m
    from (2, 3) at 26.57 deg; its 0.5 m disk is never free, so the draws are all rejected."""
    ang = math.degrees(math.atan2(3.0, 6.0))
    spec = _spec({"start": {"offset_m": math.hypot(6.0, 3.0), "direction_deg": ang, "margin_m": 0.5}})
    with pytest.raises(CampaignError, match="key 'start'.*no launch point on free cells"):
        scenario(spec, field, 0)


def test_search_dims_and_unit_point(field):
    spec = spec_from_dict({**BASE, **NEW}, "d.yaml")
    dims = continuous_dims(spec)
    assert dims[-4:] == ["link.loss", "link.jitter_ms", "start.offset_m", "start.direction_deg"]
    s = scenario(spec, field, 0, {d: 0.0 for d in dims})
    assert s["link"] == {"loss": 0.0, "delay_ms": [5.0, 5.0]}
    assert s["overrides"]["sim"]["start_enu_m"] == [2.5, 3.0]        # 0.5 m east of the first point


@pytest.mark.parametrize("key, value, msg", [
    ("link", {"loss": 0.95}, "link.loss must lie in"),
    ("link", {"jitter_ms": [10.0, 5.0]}, "lo <= hi"),
    ("link", {"los": 0.1}, "unknown key"),
    ("start", {"offset_m": -1.0}, "start.offset_m must lie in"),
    ("start", {"margin_m": 20.0}, "start.margin_m"),
    ("sensors", {"range_dropout_probability": 1.5}, "range_dropout_probability must lie in"),
])
def test_bad_spec_keys(key, value, msg):
    with pytest.raises(CampaignError, match=msg):
        spec_from_dict({**BASE, key: value}, "d.yaml")


def test_scenario_file_link_round_trip(tmp_path, field):
    spec = spec_from_dict({**BASE, **NEW, "sensors": {**BASE["sensors"], "range_dropout_probability": 0.2}},
                          "d.yaml")
    s = scenario(spec, field, 2)
    p = tmp_path / "0002.yaml"
    p.write_text(scenario_yaml(s))
    sc = load_scenario(p)
    assert (sc.link.loss, list(sc.link.delay_ms)) == (s["link"]["loss"], s["link"]["delay_ms"])
    _, mission = scenario_mission(sc, str(p))
    assert mission.sim.noise.range_dropout_probability == 0.2
    assert list(mission.sim.start_enu_m) == s["overrides"]["sim"]["start_enu_m"]
    p.write_text(scenario_yaml({**s, "link": {"loss": 0.95, "delay_ms": [0.0, 1.0]}}))
    with pytest.raises(CampaignError, match="0002.yaml.*link.loss"):
        load_scenario(p)


def test_bundled_specs_load():
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "campaigns"
    lossy = load_spec(root / "lossy-link.yaml")
    assert lossy.link is not None and lossy.link.loss == 0.2 and lossy.link.jitter_ms == 30.0
    noise = load_spec(root / "noise.yaml")
    assert set(noise.control) == {"companion", "vehicle"}
    assert set(noise.missions) == {"flat-rectangle", "tilted-hexagon", "flat-rectangle-windy"}   # the sweep's fields
    assert noise.sensors.velocity_std_m_s == (0.0, 0.05) and noise.sensors.gyro_bias_rad_s == (0.0, 0.01)
