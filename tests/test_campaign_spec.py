"""Campaign spec validation: one line naming the file and the key, exit code 2, no output."""

from __future__ import annotations

import pytest

from companion.campaign.spec import dim_range, is_continuous, spec_from_dict
from companion.cli import main
from mavcore.errors import CampaignError

BASE = {"name": "t", "missions": ["flat-rectangle"], "flights": 3}


@pytest.mark.parametrize("patch, key, problem", [
    ({"flihgts": 3}, "flihgts", "unknown key"),
    ({"flights": 0}, None, "flights must be in"),
    ({"cut_s": -1.0}, None, "cut_s must be > 0"),
    ({"control": ["autopilot"]}, "control[0]", "expected one of"),
    ({"wind": {"speed_m_s": [3.0, 1.0]}}, "wind", "lo <= hi"),
    ({"wind": {"speed_m_s": [0.0, 31.0]}}, "wind", "must lie in [0, 30]"),
    ({"obstacles": {"kinds": ["cone"]}}, "obstacles.kinds[0]", "expected one of"),
    ({"obstacles": {"count": [3, 1]}}, "obstacles", "min <= max"),
    ({"obstacles": {"placement": "everywhere"}}, "obstacles.placement", "expected one of"),
    ({"sensors": {"profiles": ["bogus"]}}, "sensors.profiles[0]", "expected one of"),
    ({"sensors": {"noise": 1}}, "sensors.noise", "unknown key"),
    ({"wind": {"speed_m_s": [0.0, 1.0, 2.0]}}, "wind.speed_m_s", "expected"),
    ({"obstacles": {"placement": ["path", "corners"]}}, "obstacles", "obstacles.placement[1]: expected one of"),
    ({"obstacles": {"placement": []}}, "obstacles", "obstacles.placement: at least one placement"),
    ({"obstacles": {"placement": "entrance"}}, "obstacles.placement", "expected one of"),
    ({"obstacles": {"cluster_m": -1.0}}, "obstacles", "obstacles.cluster_m must be in (0, 100] m"),
    ({"obstacles": {"entrance_m": 0.0}}, "obstacles", "obstacles.entrance_m must be in (0, 100] m"),
    ({"obstacles": {"row_end_across_m": -0.5}}, "obstacles", "obstacles.row_end_across_m must be in [0, 100] m"),
    ({"obstacles": {"entranec_m": 3.0}}, "obstacles.entranec_m", "unknown key"),
    ({"whole_fraction": 1.5, "cut_s": 45.0}, None, "whole_fraction must be in [0, 1], got 1.5"),
    ({"whole_fraction": -0.1, "cut_s": 45.0}, None, "whole_fraction must be in [0, 1]"),
    ({"whole_fraction": 0.5}, None, "whole_fraction needs a cut_s"),
])
def test_bad_spec_names_the_key(patch, key, problem):
    with pytest.raises(CampaignError) as e:
        spec_from_dict({**BASE, **patch}, "spec.yaml")
    msg = str(e.value)
    assert msg.startswith("spec.yaml")
    assert problem in msg
    if key is not None:
        assert f"key '{key}'" in msg
    assert "\n" not in msg


def test_placement_is_a_name_or_a_list_and_whole_fraction_a_probability():
    s = spec_from_dict({**BASE, "cut_s": 10.0, "whole_fraction": 1.0,
                        "obstacles": {"placement": ["path", "row_ends", "path"]}}, "spec.yaml")
    assert s.obstacles.placements == ("path", "row_ends", "path") and s.whole_fraction == 1.0
    s = spec_from_dict({**BASE, "obstacles": {"placement": "cluster"}}, "spec.yaml")
    assert s.obstacles.placements == ("cluster",) and s.whole_fraction == 0.0
    assert (s.obstacles.entrance_m, s.obstacles.row_end_across_m, s.obstacles.cluster_m) == (3.0, 1.5, 2.0)


def test_missing_required_key():
    with pytest.raises(CampaignError, match="key 'missions': missing"):
        spec_from_dict({"name": "t", "flights": 1}, "spec.yaml")


def test_dimensions():
    s = spec_from_dict({**BASE, "wind": {"speed_m_s": [0.5, 2], "gust_std_m_s": 0.25}}, "spec.yaml")
    assert dim_range(s.wind.speed_m_s) == (0.5, 2.0) and is_continuous(s.wind.speed_m_s)
    assert dim_range(s.wind.gust_std_m_s) == (0.25, 0.25) and not is_continuous(s.wind.gust_std_m_s)


@pytest.mark.parametrize("text", [
    "name: t\nmissions: [flat-rectangle]\nflights: 2\nwind: {speed: 3}\n",      # unknown key
    "name: t\nmissions: [no-such-mission]\nflights: 2\n",                     # no such mission
    "name: t\nmissions: [flat-rectangle\nflights: 2\n",                       # not YAML
    "- just a list\n",
])
def test_cli_bad_spec_exit_2_one_line_no_output(tmp_path, capsys, text):
    spec = tmp_path / "spec.yaml"
    spec.write_text(text)
    out = tmp_path / "out"
    assert main(["campaign", str(spec), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("companion campaign: error: ") and "spec.yaml" in err
    assert "Traceback" not in err
    assert not out.exists()


def test_cli_missing_spec(tmp_path, capsys):
    assert main(["campaign", str(tmp_path / "nope.yaml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nope.yaml" in err


def _bundled_specs():
    from pathlib import Path

    return sorted((Path(__file__).resolve().parents[1] / "campaigns").glob("*.yaml"))


@pytest.mark.parametrize("path", _bundled_specs(), ids=lambda p: p.name)
def test_bundled_specs_load_and_their_scenarios_are_valid_missions(path, tmp_path):
    from companion.campaign.scenario_file import load_scenario, scenario_mission
    from companion.campaign.scenarios import load_fields, scenario, scenario_yaml
    from companion.campaign.spec import load_spec

    spec = load_spec(path)
    if spec.obstacles is not None:      # planning the field: covered by test_campaign_scenarios
        return
    s = scenario(spec, load_fields(spec), 0)
    f = tmp_path / "0000.yaml"
    f.write_text(scenario_yaml(s))
    scenario_mission(load_scenario(f), str(f))


def test_demo_scenario_bad_input(tmp_path, capsys):
    assert main(["demo", "--scenario", str(tmp_path / "none.yaml"), "--out", str(tmp_path / "o")]) == 2
    assert "none.yaml" in capsys.readouterr().err
    f = tmp_path / "s.yaml"
    f.write_text("campaign: c\nscenario: 0\nmission: flat-rectangle\nseed: 1\n")
    assert main(["demo", "--scenario", str(f), "--mission", "flat-rectangle", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--mission or --scenario" in err
    assert not (tmp_path / "o").exists()
