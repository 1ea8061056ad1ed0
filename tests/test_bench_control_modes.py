"""benchmarks/control_modes.py: the mission copy it flies and its refusal of a bad argument."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import control_modes  # noqa: E402


def test_mission_copy_sets_the_profile_and_turns_the_replanner_off(tmp_path):
    from mavcore.mission import load_mission

    path = control_modes.mission_copy("flat-rectangle", tmp_path / "m", "icm42688p-bmm150-zedf9p", replan=False)
    m = load_mission(path)                       # absolute map paths: loads from another folder
    assert m.sim.sensor_profile == "icm42688p-bmm150-zedf9p"
    assert m.replan.enabled is False
    bundled = load_mission(ROOT / "missions" / "flat-rectangle" / "mission.yaml")
    assert bundled.replan.enabled is True and bundled.sim.sensor_profile is None
    assert m.sim.seed == bundled.sim.seed


def test_mission_copy_defaults_leave_the_mission_as_bundled(tmp_path):
    from mavcore.mission import load_mission

    m = load_mission(control_modes.mission_copy("tilted-hexagon", tmp_path / "m", None))
    assert m.replan.enabled is True and m.sim.sensor_profile is None


def test_a_checkout_without_a_label_is_refused(capsys):
    assert control_modes.main(["--checkout", str(ROOT)]) == 2
    assert "LABEL=PATH" in capsys.readouterr().err


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))
