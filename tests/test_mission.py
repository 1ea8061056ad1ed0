"""Mission loader: strict schema, error messages that name the file and key."""

from __future__ import annotations

from pathlib import Path

import pytest

from mavcore.errors import MissionError
from mavcore.mission import FlightConfig, load_mission

ROOT = Path(__file__).resolve().parents[1]

GOOD = """\
name: test
map: maps/map.yaml
dem: ../dem.asc
home: {lat: 44.8, lon: -0.6, alt_m: 30.0}
flight: {height_agl_m: 2.0, speed_m_s: 1.5, waypoint_interval_s: 3.0}
coverage: {line_spacing_m: 2.5, safety_margin_m: 0.4}
pointing: {target: [1.0, 2.0, 3.0]}
"""


def write(tmp_path: Path, text: str, name: str = "mission.yaml") -> Path:
    p = tmp_path / "sub" / name
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(text)
    return p


def test_good_mission_values_and_relative_paths(tmp_path, monkeypatch):
    p = write(tmp_path, GOOD)
    monkeypatch.chdir(tmp_path)       # paths resolve against the file, not the working directory
    m = load_mission("sub/mission.yaml")
    assert m.flight == FlightConfig(height_agl_m=2.0, speed_m_s=1.5, waypoint_interval_s=3.0)
    assert m.coverage.line_spacing_m == 2.5 and m.coverage.safety_margin_m == 0.4
    assert m.pointing.target == (1.0, 2.0, 3.0)
    assert m.home.lat == 44.8 and m.home.alt_m == 30.0
    assert m.map_path.resolve() == (tmp_path / "sub" / "maps" / "map.yaml").resolve()
    assert m.dem_path.resolve() == (tmp_path / "dem.asc").resolve()
    assert p.exists()


def test_defaults_and_centroid(tmp_path):
    text = "name: t\nmap: m.yaml\ndem: d.asc\nhome: {lat: 0, lon: 0, alt_m: 0}\n"
    m = load_mission(write(tmp_path, text))
    assert m.pointing.target == "centroid"
    assert m.coverage.line_spacing_m is None
    assert m.flight.speed_m_s == 1.0 and m.flight.waypoint_interval_s == 4.0   # the paper's 1 m/s x 4 s


@pytest.mark.parametrize("text, where, what", [
    (GOOD + "colour: red\n", "key 'colour'", "unknown key"),
    (GOOD.replace("speed_m_s: 1.5", "speed_m_s: 1.5, sped: 2"), "key 'flight.sped'", "unknown key"),
    (GOOD.replace("height_agl_m: 2.0", "height_agl_m: high"), "key 'flight.height_agl_m'", "expected a number"),
    (GOOD.replace("lat: 44.8", "lat: true"), "key 'home.lat'", "expected a number"),
    (GOOD.replace("map: maps/map.yaml\n", ""), "mission.yaml", "exactly one of 'map'"),
    (GOOD + "field: {file: f.geojson}\n", "mission.yaml", "exactly one of 'map'"),
    (GOOD.replace("alt_m: 30.0", "alt: 30.0"), "key 'home.alt", ""),
    (GOOD.replace("target: [1.0, 2.0, 3.0]", "target: middle"), "key 'pointing.target'", ""),
    (GOOD.replace("speed_m_s: 1.5", "speed_m_s: -1"), "key 'flight'", "speed_m_s must be > 0"),
    ("- just\n- a list\n", "mission.yaml", "mapping"),
    ("", "mission.yaml", "mapping"),
    (GOOD.replace("height_agl_m: 2.0", "height_agl_m: .nan"), "key 'flight.height_agl_m'", "finite"),
    (GOOD.replace("lat: 44.8", "lat: .inf"), "key 'home.lat'", "finite"),
    # Huge lengths overflowed the planner's grid arithmetic (tracebacks) before the bounds.
    (GOOD.replace("height_agl_m: 2.0", "height_agl_m: 1.0e+300"), "key 'flight'", "height_agl_m must be in"),
    (GOOD.replace("line_spacing_m: 2.5", "line_spacing_m: 1.0e+300"), "key 'coverage'", "line_spacing_m must be in"),
    (GOOD.replace("safety_margin_m: 0.4", "safety_margin_m: 1.0e+300"), "key 'coverage'", "safety_margin_m must be"),
    (GOOD.replace("alt_m: 30.0", "alt_m: 1.0e+308"), "key 'home'", "alt_m"),
])
def test_schema_errors_name_file_and_key(tmp_path, text, where, what):
    p = write(tmp_path, text)
    with pytest.raises(MissionError) as exc:
        load_mission(p)
    msg = str(exc.value)
    assert msg.startswith(str(p)) and where in msg and what in msg
    assert "\n" not in msg


def test_bad_yaml_names_the_line(tmp_path):
    # Line 3 opens a flow mapping that never closes; the parser reports the line where it notices.
    text = "name: t\nmap: m.yaml\nhome: {lat: 1, lon: 2\ndem: d.asc\n"
    p = write(tmp_path, text)
    with pytest.raises(MissionError) as exc:
        load_mission(p)
    assert str(p) in str(exc.value) and "line 4" in str(exc.value)


def test_missing_file(tmp_path):
    with pytest.raises(MissionError, match="no such file"):
        load_mission(tmp_path / "absent.yaml")


def test_base_dir_cannot_be_set_from_the_file(tmp_path):
    with pytest.raises(MissionError, match="base_dir"):
        load_mission(write(tmp_path, GOOD + "base_dir: /etc\n"))
    with pytest.raises(MissionError, match="source"):
        load_mission(write(tmp_path, GOOD + "source: x.yaml\n"))


def test_source_is_the_file(tmp_path):
    p = write(tmp_path, GOOD)
    assert load_mission(p).source == str(p)


@pytest.mark.parametrize("name", ["flat-rectangle", "tilted-hexagon"])
def test_bundled_missions_load(name):
    m = load_mission(ROOT / "missions" / name / "mission.yaml")
    assert m.name == name
    assert m.map_path.is_file() and m.dem_path.is_file()
    assert m.coverage.line_spacing_m == 2.5
    assert m.sim.noise.vector_variance == 5.0e-4 and m.sim.noise.gyro_variance == 5.0e-4  # the paper's noise


def test_exponent_numbers_without_a_dot_are_numbers(tmp_path):
    """YAML 1.1 (PyYAML) reads 5e-4 as a string; the schema takes it as 0.0005."""
    text = GOOD + "sim: {noise: {vector_variance: 5e-4, gyro_variance: 2E-3}}\n"
    m = load_mission(write(tmp_path, text))
    assert m.sim.noise.vector_variance == 0.0005
    assert m.sim.noise.gyro_variance == 0.002
    with pytest.raises(MissionError, match=r"sim\.noise\.vector_variance.*string \('5e-4x'\)"):
        load_mission(write(tmp_path, GOOD + "sim: {noise: {vector_variance: 5e-4x}}\n"))


# --- sim: sensor model keys (issue 7) ------------------------------------------


def test_sensor_keys_load_and_default_to_the_paper_model(tmp_path):
    m = load_mission(write(tmp_path, GOOD))
    assert m.sim.vector_sensors == "physical" and m.sim.sensor_profile is None
    assert m.sim.onboard_state == "estimate"
    assert m.sim.noise.gnss_rate_hz is None          # not given: the profile's or the paper's value
    text = GOOD + ("sim:\n  vector_sensors: paper\n  sensor_profile: icm42688p-bmm150-zedf9p\n"
                   "  onboard_state: truth\n"
                   "  noise: {velocity_std_m_s: 0.05, gnss_rate_hz: 20, gnss_latency_s: 0.1,\n"
                   "          gyro_bias_rad_s: [0.01, 0, 0], mag_hard_iron_gauss: [0.01, -0.02, 0.0]}\n")
    m = load_mission(write(tmp_path, text))
    assert (m.sim.vector_sensors, m.sim.sensor_profile, m.sim.onboard_state) == (
        "paper", "icm42688p-bmm150-zedf9p", "truth")
    assert m.sim.noise.velocity_std_m_s == 0.05 and m.sim.noise.gnss_rate_hz == 20.0
    assert m.sim.noise.gyro_bias_rad_s == (0.01, 0.0, 0.0)


@pytest.mark.parametrize("sim, match", [
    ("{sensor_profile: bmi088}", r"sim\.sensor_profile.*expected one of 'icm42688p-bmm150-zedf9p'"),
    ("{vector_sensors: exact}", r"sim\.vector_sensors.*expected one of 'physical', 'paper'"),
    ("{onboard_state: ekf}", r"sim\.onboard_state.*expected one of 'estimate', 'truth'"),
    ("{noise: {gyro_noise_density: 0.1}}", r"sim\.noise\.gyro_noise_density.*unknown key"),
    ("{noise: {velocity_std_m_s: -0.01}}", r"sim\.noise.*velocity_std_m_s must be >= 0"),
    ("{noise: {accel_noise_density_m_s2_rthz: -1e-3}}", r"accel_noise_density_m_s2_rthz must be >= 0"),
    ("{noise: {gyro_bias_walk_rad_s_rts: .nan}}", r"sim\.noise\.gyro_bias_walk_rad_s_rts.*finite"),
    ("{noise: {gyro_bias_rad_s: [0, .inf, 0]}}", r"gyro_bias_rad_s\[1\].*finite"),
    ("{noise: {gnss_rate_hz: 0}}", r"gnss_rate_hz must be > 0"),
    ("{noise: {gnss_latency_s: 1.0}}", r"gnss_latency_s must be in \[0, 1\) s"),
    ("{noise: {gnss_latency_s: -0.05}}", r"gnss_latency_s must be >= 0"),
    ("{noise: {vector_variance: 1.5}}", r"vector_variance must be < 1"),
    ("{noise: {mag_thrust_gauss_per_n: [0, 0]}}", r"mag_thrust_gauss_per_n.*list of 3 items"),
    ("{magnetic_field_enu_gauss: [0, 0, 0]}", r"magnetic_field_enu_gauss must be finite and non-zero"),
])
def test_bad_sensor_keys_name_the_key(tmp_path, sim, match):
    with pytest.raises(MissionError, match=match):
        load_mission(write(tmp_path, GOOD + f"sim: {sim}\n"))
