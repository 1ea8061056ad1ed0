"""Scenarios are deterministic per index, independent of the batch; the hash is the documented one."""

from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest

from companion.campaign.scenario_file import deep_merge, load_scenario, scenario_mission
from companion.campaign.scenarios import (canonical_json, continuous_dims, load_fields, scenario, scenario_hash,
                                          scenario_yaml)
from companion.campaign.spec import spec_from_dict
from mavcore.errors import CampaignError

NO_OBSTACLES = {"name": "w", "missions": ["flat-rectangle"], "flights": 50, "seed": 7, "cut_s": 10.0,
                "sensors": {"velocity_std_m_s": [0.0, 0.01]},
                "wind": {"speed_m_s": [0.0, 2.0], "direction_deg": [0.0, 360.0], "gust_std_m_s": 0.25}}


def test_hash_is_sha256_of_the_canonical_json():
    s = {"b": 1, "a": [1.5, "x"], "c": {"z": None, "y": True}}
    text = '{"a":[1.5,"x"],"b":1,"c":{"y":true,"z":null}}'     # written by hand: sorted keys, no spaces
    assert canonical_json(s) == text
    assert scenario_hash(s) == hashlib.sha256(text.encode()).hexdigest()[:16]


def test_scenario_is_the_documented_draws():
    """Scenario 3 recomputed from the documented generator and draw order."""
    spec = spec_from_dict(NO_OBSTACLES, "w.yaml")
    s = scenario(spec, load_fields(spec), 3)
    rng = np.random.default_rng(np.random.SeedSequence([7, 3]))
    seed = int(rng.integers(0, 2**31 - 1))          # one mission, one control: no choice draws
    v = round(0.0 + 0.01 * rng.random(), 6)           # velocity noise
    speed = 2.0 * rng.random()
    d = math.radians(360.0 * rng.random())
    gust = 0.25                                       # a fixed dimension still takes its draw
    rng.random()
    expected = {"campaign": "w", "scenario": 3, "mission": "flat-rectangle", "seed": seed, "cut_s": 10.0,
                "control": "companion", "overrides": {"sim": {
                    "noise": {"velocity_std_m_s": v},
                    "wind": {"mean_enu_m_s": [round(speed * math.cos(d), 6), round(speed * math.sin(d), 6), 0.0],
                             "gust_std_m_s": gust, "gust_time_constant_s": 2.0, "drag_n_s_m": 0.3}}}}
    assert s == expected
    assert scenario_hash(s) == hashlib.sha256(canonical_json(expected).encode("ascii")).hexdigest()[:16]


@pytest.fixture(scope="module")
def obstacle_spec_and_fields():
    """A synthetic field (no planning): 30 m x 12 m free, a vine row along y = 6 m from x = 5 to 25 m;
    the path flies east along y = 3 m, turns north at x = 28 m, and back west along y = 9 m."""
    from companion.campaign.placement import cumulative
    from companion.campaign.scenarios import Field
    from mavcore.maps.grid import OccupancyGrid

    res = 0.1
    occ = np.zeros((120, 300), dtype=bool)
    occ[58:62, 50:250] = True
    grid = OccupancyGrid(occupied=occ, free=~occ, resolution_m=res, origin_xy_m=(0.0, 0.0))
    t = np.linspace(0.0, 1.0, 200)
    path = np.concatenate([np.stack([2 + 26 * t, 3 + 0 * t, 1.5 + 0 * t], 1),
                           np.stack([28 + 0 * t, 3 + 6 * t, 1.5 + 0 * t], 1)[1:],
                           np.stack([28 - 26 * t, 9 + 0 * t, 1.5 + 0 * t], 1)[1:]])
    spec = spec_from_dict({"name": "o", "missions": ["obstacle-low"], "flights": 50, "seed": 3, "cut_s": 30.0,
                           "obstacles": {"count": [0, 3]}, "wind": {"speed_m_s": [0, 1]}}, "o.yaml")
    return spec, {"obstacle-low": Field(grid, path, cumulative(path))}


def test_scenario_i_alone_equals_scenario_i_in_a_batch(obstacle_spec_and_fields):
    spec, fields = obstacle_spec_and_fields
    batch = [scenario(spec, fields, i) for i in range(50)]
    for i in (0, 17, 49):
        alone = scenario(spec, fields, i)
        assert alone == batch[i] and scenario_hash(alone) == scenario_hash(batch[i])
    reversed_batch = [scenario(spec, fields, i) for i in reversed(range(50))][::-1]
    assert reversed_batch == batch
    assert len({scenario_hash(s) for s in batch}) == 50


def test_obstacles_respect_the_placement_rules(obstacle_spec_and_fields):
    from companion.campaign.placement import footprint_free

    spec, fields = obstacle_spec_and_fields
    f = fields["obstacle-low"]
    start, end = f.path[0, :2], f.path[-1, :2]
    n = 0
    for i in range(50):
        for o in scenario(spec, fields, i)["overrides"]["sim"]["obstacles"]:
            n += 1
            assert 0.8 <= o["height"] <= 4.0
            assert math.hypot(o["x"] - start[0], o["y"] - start[1]) >= 2.5
            assert math.hypot(o["x"] - end[0], o["y"] - end[1]) >= 2.5
            assert footprint_free(f.grid, o)
            # within offset + 0.001 (rounding) of the flown path
            assert np.min(np.hypot(f.path[:, 0] - o["x"], f.path[:, 1] - o["y"])) <= 0.8 + 0.05
            assert not (5.0 - 0.45 < o["x"] < 25.0 + 0.45 and 6.0 - 0.45 < o["y"] < 6.0 + 0.45)   # off the row
    assert 40 <= n <= 110    # 0-3 per flight, mean 1.5


def test_search_point_maps_the_unit_cube(obstacle_spec_and_fields):
    spec, fields = obstacle_spec_and_fields
    dims = continuous_dims(spec)
    assert dims[-2:] == ["wind.speed_m_s", "wind.direction_deg"]
    s = scenario(spec, fields, 0, {"wind.speed_m_s": 1.0, "wind.direction_deg": 0.25})
    # 1 m/s toward 90 deg (north)
    assert s["overrides"]["sim"]["wind"]["mean_enu_m_s"] == [0.0, 1.0, 0.0]


def test_scenario_file_round_trip_and_merge(tmp_path):
    spec = spec_from_dict(NO_OBSTACLES, "w.yaml")
    s = scenario(spec, load_fields(spec), 5)
    p = tmp_path / "0005.yaml"
    p.write_text(scenario_yaml(s))
    sc = load_scenario(p)
    assert (sc.seed, sc.cut_s, sc.control, sc.overrides) == (s["seed"], 10.0, "companion", s["overrides"])
    data, mission = scenario_mission(sc, str(p))
    assert mission.sim.wind.mean_enu_m_s == tuple(s["overrides"]["sim"]["wind"]["mean_enu_m_s"])
    assert mission.sim.noise.velocity_std_m_s == s["overrides"]["sim"]["noise"]["velocity_std_m_s"]
    assert mission.map_path.exists()
    assert deep_merge({"a": {"b": 1, "c": [1]}}, {"a": {"c": [2]}}) == {"a": {"b": 1, "c": [2]}}


def test_bad_scenario_file(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("campaign: c\nscenario: 0\nmission: flat-rectangle\nseed: 1\noverrides: {sim: {wnd: 1}}\n")
    with pytest.raises(CampaignError, match="s.yaml.*sim.wnd.*unknown key"):
        scenario_mission(load_scenario(p), str(p))
