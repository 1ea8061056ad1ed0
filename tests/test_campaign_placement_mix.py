"""Whole and cut flights mixed in one campaign (``whole_fraction``), and the
obstacle placements at corridor entrances, beside row ends and in clusters
(``obstacles.placement``: a name or a list).

The placement checks run on a synthetic serpentine field whose corridors,
entrances and row ends are known by construction, and are checked here with
plain geometry, not with the placement module's own helpers."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from companion.campaign.placement import cumulative, footprint_free
from companion.campaign.scenarios import Field, continuous_dims, load_fields, scenario, scenario_hash
from companion.campaign.spec import load_spec, spec_from_dict

ROOT = Path(__file__).resolve().parents[1]
OFFSET = 0.8
ENTRANCE = 3.0
ACROSS = 1.5
CLUSTER = 2.0
TOL = 0.002          # centres are rounded to the millimetre
#: the vine rows of the synthetic field: (x0, x1, y0, y1) m
ROWS = ((5.0, 25.0, 3.3, 3.7), (5.0, 25.0, 6.3, 6.7))
#: where the vehicle turns into a corridor: (start point, direction of travel)
ENTRANCES = (((28.0, 5.0), (-1.0, 0.0)), ((2.0, 8.0), (1.0, 0.0)))
#: the ends of the corridor runs where the vehicle turns: (point, the run's direction of travel)
ROW_ENDS = (((28.0, 2.0), (1.0, 0.0)), ((28.0, 5.0), (-1.0, 0.0)),
            ((2.0, 5.0), (-1.0, 0.0)), ((2.0, 8.0), (1.0, 0.0)))


def _leg(a, b, step=0.1):
    n = max(2, int(round(math.dist(a, b) / step)) + 1)
    t = np.linspace(0.0, 1.0, n)[:, None]
    return np.hstack([np.asarray(a) + t * (np.asarray(b) - np.asarray(a)), np.full((n, 1), 1.5)])


def _polyline(*points):
    legs = [_leg(a, b) for a, b in zip(points, points[1:])]
    return np.concatenate([legs[0]] + [leg[1:] for leg in legs[1:]])


@pytest.fixture(scope="module")
def serpentine():
    """30 m x 10 m, free but for two vine rows (y = 3.5 and 6.5 m, x 5..25 m, 0.4 m thick).
    The whole trajectory: east along y = 2 (the launch at x = 2), north at x = 28, west along
    y = 5, north at x = 2, east along y = 8 to x = 28. Its corridor runs: y = 2 (flown from
    the launch: no entrance), y = 5 (entered at (28, 5)), y = 8 (entered at (2, 8); its end
    is the trajectory's). The cut trajectory stops at (15, 5), half way along y = 5."""
    from mavcore.maps.grid import OccupancyGrid

    occ = np.zeros((100, 300), dtype=bool)
    for x0, x1, y0, y1 in ROWS:
        occ[int(round(y0 / 0.1)):int(round(y1 / 0.1)), int(round(x0 / 0.1)):int(round(x1 / 0.1))] = True
    grid = OccupancyGrid(occupied=occ, free=~occ, resolution_m=0.1, origin_xy_m=(0.0, 0.0))
    whole = _polyline((2, 2), (28, 2), (28, 5), (2, 5), (2, 8), (28, 8))
    cut = _polyline((2, 2), (28, 2), (28, 5), (15, 5))
    return grid, cut, whole


def _fields(serpentine, whole_too=False):
    grid, cut, whole = serpentine
    if not whole_too:
        return {"obstacle-low": Field(grid, whole, cumulative(whole))}
    return {"obstacle-low": Field(grid, cut, cumulative(cut), whole=Field(grid, whole, cumulative(whole)))}


def _spec(placement, count=(1, 3), **top):
    data = {"name": "m", "missions": ["obstacle-low"], "flights": 400, "seed": 5, "cut_s": 30.0,
            "obstacles": {"count": list(count), "placement": placement, "offset_m": OFFSET,
                          "entrance_m": ENTRANCE, "row_end_across_m": ACROSS, "cluster_m": CLUSTER}, **top}
    return spec_from_dict(data, "m.yaml")


def _obstacles(spec, fields, n=200):
    return [scenario(spec, fields, i)["overrides"]["sim"]["obstacles"] for i in range(n)]


def _dist_to_polyline(path, x, y):
    """Shortest distance (m) from (x, y) to the polyline ``path`` (its segments, not only its points)."""
    a, b = path[:-1, :2], path[1:, :2]
    d = b - a
    L2 = np.maximum(np.sum(d * d, axis=1), 1e-18)
    t = np.clip(((x - a[:, 0]) * d[:, 0] + (y - a[:, 1]) * d[:, 1]) / L2, 0.0, 1.0)
    return float(np.min(np.hypot(a[:, 0] + t * d[:, 0] - x, a[:, 1] + t * d[:, 1] - y)))


def _local(o, point, u):
    """(along, across) of the obstacle's centre from ``point`` in the frame of the direction ``u``."""
    dx, dy = o["x"] - point[0], o["y"] - point[1]
    return dx * u[0] + dy * u[1], -dx * u[1] + dy * u[0]


def _off_the_rows(o):
    """The bare footprint, sampled every 2 cm, stays out of the vine rows (less 2 cm: the map's cells)."""
    if o["type"] == "cylinder":
        r = np.linspace(0.0, o["radius"], 12)[:, None]
        a = np.linspace(0.0, 2 * math.pi, 90, endpoint=False)[None, :]
        px, py = (o["x"] + r * np.cos(a)).ravel(), (o["y"] + r * np.sin(a)).ravel()
    else:
        u, v = np.meshgrid(np.linspace(-0.5, 0.5, 60) * o["size_x"], np.linspace(-0.5, 0.5, 60) * o["size_y"])
        c, s = math.cos(math.radians(o["yaw_deg"])), math.sin(math.radians(o["yaw_deg"]))
        px, py = o["x"] + c * u.ravel() - s * v.ravel(), o["y"] + s * u.ravel() + c * v.ravel()
    for x0, x1, y0, y1 in ROWS:
        if np.any((px > x0 + 0.02) & (px < x1 - 0.02) & (py > y0 + 0.02) & (py < y1 - 0.02)):
            return False
    return bool(np.all((px > 0.0) & (px < 30.0) & (py > 0.0) & (py < 10.0)))


def _kept_out(o, path):
    return (math.hypot(o["x"] - path[0, 0], o["y"] - path[0, 1]) >= 2.5 - TOL
            and math.hypot(o["x"] - path[-1, 0], o["y"] - path[-1, 1]) >= 2.5 - TOL)


# --- existing specs: unchanged ---------------------------------------------------------------

#: scenario hashes of scenarios 0-7 of each bundled spec, computed with the code before
#: whole_fraction and the new placements (commit 9190489, in a worktree of it:
#: ``[scenario_hash(scenario(spec, load_fields(spec), i)) for i in range(8)]``)
HASHES_9190489 = {
    "lossy-link.yaml": ["15bff92db4931841", "9750700ff71330de", "cfd8719524af38a3", "ee18a996f684150a",
                        "9cf4288d650ff2ab", "c81d12b241572e65", "3e27ccb1a72b4127", "08fe26ebbc582901"],
    "movers.yaml": ["37e8c43934974fe6", "f6212e6fb3170251", "2a5a95030c5acc94", "71637e5b9366dfff",
                    "6de1d195beb7f24d", "626f5150b5bef8f8", "44870fc1c551dd6d", "d06006302e72b05f"],
    "noise.yaml": ["feee1ba6b625872f", "4b017006052b7f08", "f5ebcf32e4c73dc7", "619153a2c2a2b73f",
                   "037cfcaa6df11e5e", "c35a677acecf4c87", "79c074be5e093296", "6e464fecf0dd8160"],
    "obstacles-under.yaml": ["f4efd5d9fc1ab241", "b7e7b69f8235e079", "57b6072b754d4a9a", "d9e0b33747943247",
                             "6f3dce3035a50b2c", "3fb000838ed12926", "75c10e2879e0dd4c", "668f658fdaf14772"],
    "obstacles-wide.yaml": ["19342d21f0bdbb67", "bc7c2704452488e0", "f6cc02fd9d7e29db", "fa43d1515560b4d0",
                            "fd3c4579c3af57b5", "30927949d303f9d2", "6a64aa09d8fa198e", "6c34c465455aae6c"],
    "obstacles.yaml": ["a570d5fbf8a230f0", "a713a597a1ffd2cf", "2a901644f9b6456b", "18b01f6bd64bae82",
                       "39c75cdb1ddf8c70", "4176ec608c8277de", "ea19ff11e3b9c35f", "4b1065a34a1424f4"],
    "smoke.yaml": ["f1d03b612786da67", "7c6c8d7647942235", "bb62a7fde7e82a4e", "f10d3b51298b1e34",
                   "7ff27303c015350c", "1656be4459b0b023", "ec71decdb561fe57", "1a1d03db2b4d7749"],
}
#: the search's scenario (``scenario(spec, fields, 0, unit)``) of each bundled spec at two points
#: of the unit cube (dimension j at ((7 j + 3) mod 11) / 10, then all at 0.5), the number of
#: dimensions and the first three names, computed at commit 9190489 likewise
SEARCH_9190489 = {
    "lossy-link.yaml": [0, [], "15bff92db4931841", "15bff92db4931841"],
    "movers.yaml": [0, [], "37e8c43934974fe6", "37e8c43934974fe6"],
    "noise.yaml": [2, ["sensors.velocity_std_m_s", "sensors.gyro_bias_rad_s"], "8ebe84634d7e31c0",
                   "eb12a7c2773f5cc5"],
    "obstacles-under.yaml": [21, ["obstacle0.0", "obstacle0.1", "obstacle0.2"], "24d326f64aa2b744",
                             "ddaf311ce0a8e136"],
    "obstacles-wide.yaml": [21, ["obstacle0.0", "obstacle0.1", "obstacle0.2"], "45e80d759285a1ad",
                            "0cba0b9396f4518b"],
    "obstacles.yaml": [21, ["obstacle0.0", "obstacle0.1", "obstacle0.2"], "f8925d8fb8f6ecc0", "3fce589f454caa0c"],
    "smoke.yaml": [4, ["sensors.velocity_std_m_s", "wind.speed_m_s", "wind.direction_deg"], "4164c338e554d568",
                   "fe7fd4aa24e97807"],
}
#: scenarios 0-5 of obstacles-wide.yaml with ``placement: rows`` and ``headlands``, at commit 9190489
ROWS_9190489 = {
    "rows": ["e3c65ae82f610f71", "4e026f1e6b8e0635", "400f97e63cbec164", "a87576ee8c1fca68", "d2f25247e350ac1f",
             "0907a82100d4ec7b"],
    "headlands": ["da72ad778e28c246", "27e69319940c8946", "845d625caf57e73a", "4d16257198bdef2f",
                  "45c99f8b13038d52", "72985dbdc3bb6324"],
}


@pytest.mark.parametrize("name", sorted(HASHES_9190489))
def test_existing_specs_give_the_scenarios_they_gave(name):
    """Determinism regression: every spec that was in campaigns/ before whole_fraction and the
    new placements gives bit for bit the scenarios it gave (values: see HASHES_9190489), in
    Monte Carlo and in the search (same dimensions, same scenario at the same point)."""
    spec = load_spec(ROOT / "campaigns" / name)
    fields = load_fields(spec)
    assert [scenario_hash(scenario(spec, fields, i)) for i in range(8)] == HASHES_9190489[name]
    dims = continuous_dims(spec)
    points = [{d: ((7 * j + 3) % 11) / 10.0 for j, d in enumerate(dims)}, {d: 0.5 for d in dims}]
    assert [len(dims), dims[:3]] + [scenario_hash(scenario(spec, fields, 0, u)) for u in points] \
        == SEARCH_9190489[name]


@pytest.mark.parametrize("placement", sorted(ROWS_9190489))
def test_rows_and_headlands_placements_are_unchanged(placement):
    import yaml

    from companion.campaign.spec import with_source

    path = ROOT / "campaigns" / "obstacles-wide.yaml"
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    data["obstacles"]["placement"] = placement
    spec = with_source(spec_from_dict(data, str(path)), path)
    fields = load_fields(spec)
    assert [scenario_hash(scenario(spec, fields, i)) for i in range(6)] == ROWS_9190489[placement]


# --- whole_fraction ----------------------------------------------------------------------------

def _whole_by_the_documented_rule(seed, i, p):
    return bool(np.random.default_rng(np.random.SeedSequence([seed, i, 16])).random() < p)


def test_whole_fraction_draws_from_its_own_generator(serpentine):
    fields = _fields(serpentine, whole_too=True)
    spec = _spec("path", whole_fraction=0.25)
    got = [scenario(spec, fields, i) for i in range(400)]
    whole = [s["cut_s"] is None for s in got]
    assert whole == [_whole_by_the_documented_rule(5, i, 0.25) for i in range(400)]
    # binomial(400, 0.25): mean 100, sd 8.7; 4 sd either side
    assert abs(sum(whole) - 100) <= 35
    assert {s["cut_s"] for s in got} == {None, 30.0}
    # scenario i is the same whether 10 or 400 are made
    assert [scenario(spec, fields, i) for i in range(10)] == got[:10]
    # a cut flight is the flight of the spec without whole_fraction (the other draws do not move)
    plain = _spec("path")
    for i in range(40):
        if not whole[i]:
            assert got[i] == scenario(plain, fields, i)


def test_whole_fraction_zero_and_one(serpentine):
    fields = _fields(serpentine, whole_too=True)
    none = [scenario(_spec("path", whole_fraction=0.0), fields, i) for i in range(50)]
    assert all(s["cut_s"] == 30.0 for s in none)
    assert none == [scenario(_spec("path"), fields, i) for i in range(50)]
    every = [scenario(_spec("path", whole_fraction=1.0), fields, i) for i in range(50)]
    assert all(s["cut_s"] is None for s in every)


def test_whole_flights_place_on_the_whole_trajectory(serpentine):
    """Obstacles and movers of a whole flight lie on the whole trajectory (some beyond the cut's
    reach); those of a cut flight near the cut trajectory only."""
    grid, cut, whole = serpentine
    fields = _fields(serpentine, whole_too=True)
    spec = spec_from_dict({"name": "m", "missions": ["obstacle-low"], "flights": 1, "seed": 9, "cut_s": 30.0,
                           "whole_fraction": 0.5, "obstacles": {"count": [2, 2], "offset_m": OFFSET},
                           "movers": {"count": [1, 1], "placement": "across", "keep_out_m": 3.0}}, "m.yaml")
    beyond = {True: 0, False: 0}
    for i in range(120):
        s = scenario(spec, fields, i)
        is_whole = s["cut_s"] is None
        flown = whole if is_whole else cut
        sim = s["overrides"]["sim"]
        centres = [(o["x"], o["y"]) for o in sim["obstacles"]]
        centres += [tuple((np.asarray(m["path"][0]) + np.asarray(m["path"][1])) / 2) for m in sim["movers"]]
        for x, y in centres:
            assert _dist_to_polyline(flown, x, y) <= OFFSET + TOL
            beyond[is_whole] += _dist_to_polyline(cut, x, y) > OFFSET + 0.5
    assert beyond[False] == 0
    assert beyond[True] >= 20


# --- placements ----------------------------------------------------------------------------------

def test_entrances_are_the_first_metres_of_a_corridor_turned_into(serpentine):
    grid, _, whole = serpentine
    fields = _fields(serpentine)
    seen = [0, 0]
    for obstacles in _obstacles(_spec("entrances"), fields):
        for o in obstacles:
            inside = []
            for point, u in ENTRANCES:
                along, across = _local(o, point, u)
                inside.append(-TOL <= along <= ENTRANCE + TOL and abs(across) <= OFFSET + TOL)
            assert any(inside), o
            seen[inside.index(True)] += 1
            assert _dist_to_polyline(whole, o["x"], o["y"]) <= OFFSET + TOL
            assert _kept_out(o, whole) and _off_the_rows(o) and footprint_free(grid, o)
    assert min(seen) >= 20        # both entrances; none at the launch's corridor


def test_row_ends_lie_beside_the_ends_where_the_vehicle_turns(serpentine):
    grid, _, whole = serpentine
    fields = _fields(serpentine)
    seen = [0] * len(ROW_ENDS)
    spread = []
    for obstacles in _obstacles(_spec("row_ends"), fields):
        for o in obstacles:
            inside = []
            for point, u in ROW_ENDS:
                along, across = _local(o, point, u)
                inside.append(abs(along) <= ENTRANCE + TOL and abs(across) <= ACROSS + TOL)
            assert any(inside), o         # the trajectory's own ends (the launch, the last point) are none
            j = inside.index(True)
            seen[j] += 1
            spread.append(np.abs(_local(o, *ROW_ENDS[j])))
            assert _kept_out(o, whole) and _off_the_rows(o) and footprint_free(grid, o)
    assert min(seen) >= 10
    # the whole rectangle is used: along to nearly entrance_m, across beyond the path placements' offset
    assert np.max(spread, axis=0)[0] > 0.8 * ENTRANCE and np.max(spread, axis=0)[1] > OFFSET + 0.3


def test_cluster_gathers_round_the_previous_obstacle(serpentine):
    grid, _, whole = serpentine
    fields = _fields(serpentine)
    gaps = []
    for obstacles in _obstacles(_spec("cluster", count=(2, 4)), fields, 150):
        first = obstacles[0]
        assert _dist_to_polyline(whole, first["x"], first["y"]) <= OFFSET + TOL      # placed as path
        for prev, o in zip(obstacles, obstacles[1:]):
            gaps.append(math.hypot(o["x"] - prev["x"], o["y"] - prev["y"]))
            assert _kept_out(o, whole) and _off_the_rows(o) and footprint_free(grid, o)
    assert max(gaps) <= CLUSTER + TOL
    assert max(gaps) > 0.8 * CLUSTER and min(gaps) < 0.3 * CLUSTER      # the disk, not a point or a ring


def test_a_list_of_placements_draws_one_per_obstacle(serpentine):
    """Each obstacle of ``[path, entrances, row_ends, cluster]`` obeys one of the four rules, and the
    rules that only its own placement can meet (off the path beside a row end; off the path
    near the previous obstacle) both occur."""
    grid, _, whole = serpentine
    fields = _fields(serpentine)
    spec = _spec(["path", "entrances", "row_ends", "cluster"])
    counts = {"on the path": 0, "beside a row end only": 0, "clustered only": 0}
    for obstacles in _obstacles(spec, fields, 300):
        for k, o in enumerate(obstacles):
            on_path = _dist_to_polyline(whole, o["x"], o["y"]) <= OFFSET + TOL
            at_end = any(abs(_local(o, p, u)[0]) <= ENTRANCE + TOL and abs(_local(o, p, u)[1]) <= ACROSS + TOL
                         for p, u in ROW_ENDS)
            near_prev = k > 0 and math.hypot(o["x"] - obstacles[k - 1]["x"],
                                             o["y"] - obstacles[k - 1]["y"]) <= CLUSTER + TOL
            assert on_path or at_end or near_prev, o
            assert _kept_out(o, whole) and footprint_free(grid, o)
            counts["on the path"] += on_path
            counts["beside a row end only"] += at_end and not on_path and not near_prev
            counts["clustered only"] += near_prev and not on_path and not at_end
    assert min(counts.values()) >= 5, counts


def test_one_placement_draws_no_choice(serpentine):
    """``placement: [rows]`` is ``placement: rows``: a list of one draws nothing more."""
    fields = _fields(serpentine)
    assert _obstacles(_spec(["rows"]), fields, 30) == _obstacles(_spec("rows"), fields, 30)


def test_search_over_several_placements(serpentine):
    grid, _, whole = serpentine
    fields = _fields(serpentine)
    names = ["path", "entrances", "row_ends", "cluster"]
    spec = _spec(names, count=(0, 3), wind={"speed_m_s": [0.0, 1.0]})
    dims = continuous_dims(spec)
    per = [f"obstacle{k}.placement" for k in range(3)]
    assert [d for d in dims if d.endswith(".placement")] == per
    assert len(dims) == 3 * 8 + 2 and dims[:2] == ["obstacle0.placement", "obstacle0.0"]
    rng = np.random.default_rng(3)
    made = 0
    for _ in range(60):
        s = scenario(spec, fields, 0, {d: float(v) for d, v in zip(dims, rng.random(len(dims)))})
        for o in s["overrides"]["sim"]["obstacles"]:
            assert _kept_out(o, whole) and footprint_free(grid, o)
            made += 1
    assert made >= 40
    # the placement coordinate picks from the list cut into four: 0.3 -> entrances
    got = 0
    for _ in range(60):
        unit = {d: float(v) for d, v in zip(dims, rng.random(len(dims)))}
        unit.update({d: 0.3 for d in per})
        for o in scenario(spec, fields, 0, unit)["overrides"]["sim"]["obstacles"]:
            assert any(-TOL <= _local(o, p, u)[0] <= ENTRANCE + TOL and abs(_local(o, p, u)[1]) <= OFFSET + TOL
                       for p, u in ENTRANCES), o
            got += 1
    assert got >= 10


def test_an_empty_placement_is_refused_naming_the_spec(serpentine):
    """A cut that stops before the vehicle turns into a second corridor has no entrance: the
    spec is refused at once, naming the file, the key and the placement."""
    from companion.campaign.spec import with_source
    from mavcore.errors import CampaignError

    grid, _, _ = serpentine
    short = _polyline((2, 2), (28, 2), (28, 4))
    fields = {"obstacle-low": Field(grid, short, cumulative(short))}
    with pytest.raises(CampaignError) as e:
        scenario(with_source(_spec("entrances", count=(1, 1)), "m.yaml"), fields, 0)
    msg = str(e.value)
    assert msg.startswith("m.yaml: key 'obstacles'") and "entrances" in msg and "empty" in msg
    assert "\n" not in msg


# --- the bundled spec -----------------------------------------------------------------------------

def test_obstacles_mix_spec(tmp_path):
    """campaigns/obstacles-mix.yaml: whole and cut flights, obstacles by the four placements,
    and its scenario files are valid missions."""
    from companion.campaign.scenario_file import load_scenario, scenario_mission
    from companion.campaign.scenarios import scenario_yaml

    spec = load_spec(ROOT / "campaigns" / "obstacles-mix.yaml")
    assert spec.whole_fraction == 0.25 and spec.cut_s == 45.0 and spec.seed == 20261200
    assert spec.obstacles.placements == ("path", "entrances", "row_ends", "cluster")
    fields = load_fields(spec)
    for f in fields.values():
        assert len(f.whole.path) > 2 * len(f.path)          # the whole trajectory: over twice the 45 s cut
    got = [scenario(spec, fields, i) for i in range(40)]
    assert {s["cut_s"] for s in got} == {None, 45.0}
    for s in got:
        assert 1 <= len(s["overrides"]["sim"]["obstacles"]) <= 3
        assert all(0.6 <= o["height"] <= 2.5 for o in s["overrides"]["sim"]["obstacles"])
    for s in (next(s for s in got if s["cut_s"] is None), next(s for s in got if s["cut_s"] is not None)):
        f = tmp_path / f"{s['scenario']:04d}.yaml"
        f.write_text(scenario_yaml(s))
        sc = load_scenario(f)
        assert sc.cut_s == s["cut_s"]
        scenario_mission(sc, str(f))
    assert json.loads(json.dumps(got)) == got
