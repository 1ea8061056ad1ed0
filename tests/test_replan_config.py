"""The mission's ``replan:`` section: strict keys, validation, what a user sees."""

from __future__ import annotations

from pathlib import Path

import pytest

from companion.cli import main
from mavcore.errors import MissionError
from mavcore.mission import ReplanConfig, SensorMount, load_mission

ROOT = Path(__file__).resolve().parents[1]
FLAT = ROOT / "missions" / "flat-rectangle"


def _mission(tmp_path: Path, replan_yaml: str) -> Path:
    text = (FLAT / "mission.yaml").read_text()
    text = text.replace("map: map.yaml", f"map: {FLAT / 'map.yaml'}").replace("dem: dem.asc", f"dem: {FLAT / 'dem.asc'}")
    p = tmp_path / "mission.yaml"
    p.write_text(text + replan_yaml)
    return p


def test_defaults_are_the_papers(tmp_path):
    m = load_mission(_mission(tmp_path, ""))
    assert m.replan == ReplanConfig()
    assert (m.replan.influence_range_m, m.replan.n, m.replan.clearance_m, m.replan.lateral_limit_m) == (2.1, 2.0, 0.5, 0.5)


def test_section_values_and_sensor_offsets(tmp_path):
    m = load_mission(_mission(tmp_path, "replan:\n  ceiling_agl_m: 4.0\n  k_rep: 0.1\n"
                                        "  sensors: [{id: 3, offset_flu_m: [0.12, 0.0, -0.05]}]\n"))
    assert m.replan.ceiling_agl_m == 4.0 and m.replan.k_rep == 0.1
    assert m.replan.sensors == (SensorMount(3, (0.12, 0.0, -0.05)),)
    assert m.replan.offset_of(3) == (0.12, 0.0, -0.05) and m.replan.offset_of(0) == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("yaml, key, what", [
    ("replan: {clearence_m: 0.5}\n", "replan.clearence_m", "unknown key"),
    ("replan: {sensors: [{id: 1, offset: [0, 0, 0]}]}\n", "replan.sensors[0].offset", "unknown key"),
    ("replan: {clearance_m: 3.0}\n", "replan", "clearance_m + body_radius_m must be below"),
    ("replan: {clearance_m: 1.0, body_radius_m: 1.2}\n", "replan", "clearance_m + body_radius_m must be below"),
    ("replan: {body_radius_m: -0.1}\n", "replan", "body_radius_m must be in"),
    ("replan: {floor_agl_m: 4.0}\n", "replan", "floor_agl_m must be below"),
    ("replan: {k_att: 0}\n", "replan", "k_att must be"),
    ("replan: {sensors: [{id: 1}, {id: 1}]}\n", "replan", "ids must be unique"),
    ("replan: {sensors: [{id: 300}]}\n", "replan.sensors[0]", "id must be in"),
    ("replan: {speed_m_s: fast}\n", "replan.speed_m_s", ""),
])
def test_bad_section_names_file_and_key(tmp_path, yaml, key, what):
    p = _mission(tmp_path, yaml)
    with pytest.raises(MissionError) as exc:
        load_mission(p)
    msg = str(exc.value)
    assert str(p) in msg and f"key '{key}" in msg and what in msg


def test_cli_one_line_exit_2_nothing_written(tmp_path, capsys):
    p = _mission(tmp_path, "replan: {lateral_limit: 0.4}\n")
    out = tmp_path / "plan.json"
    assert main(["plan", str(p), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "replan.lateral_limit" in err[0] and "unknown key" in err[0]
    assert not out.exists()
