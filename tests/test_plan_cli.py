"""``companion plan``: bad input (exit 2, one line, nothing written) and plans
checked against independent computations."""

from __future__ import annotations

import contextlib
import io
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from companion.cli import main
from mavcore.errors import PlanError
from mavcore.maps import load_dem, load_ogm
from mavcore.mission import load_mission
from companion.plan_io import load_plan

ROOT = Path(__file__).resolve().parents[1]
MISSIONS = ROOT / "missions"
LOADER_KEYS = {"frame", "origin", "path", "waypoints", "trajectory", "stats", "timings_s"}
STATS_KEYS = {"coverage_fraction", "path_length_m", "duration_s", "n_waypoints", "orientation_deg",
              "max_speed_m_s", "max_accel_m_s2", "waypoint_residual_m"}


def copy_mission(tmp_path: Path, name: str = "flat-rectangle") -> Path:
    dst = tmp_path / name
    shutil.copytree(MISSIONS / name, dst)
    return dst / "mission.yaml"


def run_bad(capsys, tmp_path, argv_tail: list[str], mission: str | Path, needle: str) -> str:
    out = tmp_path / "out"
    out.mkdir(exist_ok=True)
    before = set(out.iterdir())
    rc = main(["plan", str(mission), "-o", str(out / "plan.json"), "--qgc", str(out / "p.plan"),
               "--waypoints", str(out / "p.waypoints"), *argv_tail])
    err = capsys.readouterr().err
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert needle in lines[0], lines[0]
    assert set(out.iterdir()) == before      # nothing written, no temporaries left
    return lines[0]


def test_missing_mission(capsys, tmp_path):
    run_bad(capsys, tmp_path, [], tmp_path / "nope.yaml", "nope.yaml")


def test_unknown_key(capsys, tmp_path):
    m = copy_mission(tmp_path)
    m.write_text(m.read_text() + "speed: 3\n")
    line = run_bad(capsys, tmp_path, [], m, "mission.yaml")
    assert "speed" in line and "unknown key" in line


def test_bad_pgm(capsys, tmp_path):
    m = copy_mission(tmp_path)
    pgm = m.parent / "map.pgm"
    pgm.write_bytes(pgm.read_bytes()[: 1000])       # truncated raster
    line = run_bad(capsys, tmp_path, [], m, "map.pgm")
    assert "truncated" in line


def test_dem_not_covering(capsys, tmp_path):
    m = copy_mission(tmp_path)
    # A DEM of the field's south-west 5 m x 5 m only.
    (m.parent / "dem.asc").write_text("ncols 5\nnrows 5\nxllcorner 0\nyllcorner 0\ncellsize 1\n"
                                      + "0 0 0 0 0\n" * 5)
    line = run_bad(capsys, tmp_path, [], m, "dem.asc")
    assert "cover" in line


def test_dem_hole_between_path_vertices(capsys, tmp_path):
    m = copy_mission(tmp_path)
    # Flat 1 m DEM over x -5..30, y -5..20 with one NODATA cell centred at (11.5, 1.5): on the
    # southern lane (y = 1.25, x 0.5 .. 22.5), half-way between its end vertices.
    z = np.zeros((25, 35))
    z[6, 16] = -9999.0                     # row 6 from the south, column 16 from the west
    body = "\n".join(" ".join(f"{v:g}" for v in row) for row in z[::-1])
    (m.parent / "dem.asc").write_text("ncols 35\nnrows 25\nxllcorner -5\nyllcorner -5\ncellsize 1\n"
                                      "NODATA_value -9999\n" + body + "\n")
    line = run_bad(capsys, tmp_path, [], m, "dem.asc")
    assert "NODATA" in line


def test_bad_sample_rate_and_missing_output_dir(capsys, tmp_path):
    run_bad(capsys, tmp_path, ["--samples", "0"], MISSIONS / "flat-rectangle" / "mission.yaml", "--samples")
    rc = main(["plan", str(MISSIONS / "flat-rectangle" / "mission.yaml"), "-o", str(tmp_path / "no" / "p.json")])
    assert rc == 2 and "does not exist" in capsys.readouterr().err
    assert not (tmp_path / "no").exists()


def _sub(name: str, old: str, new: str):
    def mutate(d: Path) -> None:
        f = d / name
        assert old in f.read_text()
        f.write_text(f.read_text().replace(old, new))
    return mutate


def _pgm_all(value: int):
    def mutate(d: Path) -> None:
        raw = (d / "map.pgm").read_bytes()
        head = raw[: raw.index(b"255\n") + 4]               # P5 250 x 120, 8 bit, one byte per pixel
        (d / "map.pgm").write_bytes(head + bytes([value]) * (len(raw) - len(head)))
    return mutate


@pytest.mark.parametrize("mutate, needle", [
    # A map with no free cell: all unknown (205 = p 0.2 is between the thresholds) / all occupied.
    (_pgm_all(205), "map.yaml: no free space"),
    (_pgm_all(0), "map.yaml: no free space"),
    # Each of these ended in a traceback (overflow / out of memory) before.
    (_sub("mission.yaml", "speed_m_s: 1.0", "speed_m_s: 1.0e-300"), "flight.speed_m_s"),
    (_sub("mission.yaml", "waypoint_interval_s: 4.0", "waypoint_interval_s: 1.0e-9"), "waypoint_interval_s"),
    (_sub("mission.yaml", "line_spacing_m: 2.5", "line_spacing_m: 1.0e-300"), "below the map resolution"),
    (_sub("map.yaml", "resolution: 0.1", "resolution: 1.0e-300"), "map.yaml: no free space"),
    (_sub("dem.asc", "0.0000", "1e200"), "dem.asc: height value"),
], ids=["all-unknown", "all-occupied", "tiny-speed", "tiny-interval", "tiny-spacing", "tiny-resolution",
        "huge-heights"])
def test_nasty_inputs_one_line_nothing_written(capsys, tmp_path, mutate, needle):
    m = copy_mission(tmp_path)
    mutate(m.parent)
    run_bad(capsys, tmp_path, [], m, needle)


def test_late_write_failures_leave_nothing(capsys, tmp_path):
    m = MISSIONS / "flat-rectangle" / "mission.yaml"
    # An output that is a directory: found before planning; it used to be found at the last
    # rename, after plan.json had been put in place, and the message named the temporary.
    (tmp_path / "out" / "d.plan").mkdir(parents=True)
    line = run_bad(capsys, tmp_path, ["--qgc", str(tmp_path / "out" / "d.plan")], m, "d.plan: cannot write")
    assert ".tmp" not in line
    run_bad(capsys, tmp_path, ["-o", str(tmp_path / "out")], m, "out: cannot write")
    # A directory where no file can be created (even as root): fails in the write phase, after
    # the plan, with plan.json's temporary already written -- and removed again.
    if Path("/proc").is_dir() and not argparse_plot_missing():
        line = run_bad(capsys, tmp_path, ["--plot", "/proc/companion-test.png"], m, "/proc/companion-test.png")
        assert ".tmp" not in line
    # More samples than plan.json can hold.
    run_bad(capsys, tmp_path, ["--samples", "1e9"], m, "--samples")


def argparse_plot_missing() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return True
    return False


def test_plot_without_matplotlib(capsys, tmp_path, monkeypatch):
    for mod in [k for k in sys.modules if k == "matplotlib" or k.startswith("matplotlib.")]:
        monkeypatch.delitem(sys.modules, mod)
    monkeypatch.setitem(sys.modules, "matplotlib", None)    # import matplotlib -> ImportError
    line = run_bad(capsys, tmp_path, ["--plot", str(tmp_path / "out" / "p.png")],
                   MISSIONS / "flat-rectangle" / "mission.yaml", "matplotlib")
    assert "plot" in line


def test_console_script_one_line_no_traceback(tmp_path):
    exe = shutil.which("companion")
    cmd = [exe] if exe else [sys.executable, "-m", "companion.cli"]
    r = subprocess.run([*cmd, "plan", str(tmp_path / "absent.yaml"), "-o", str(tmp_path / "p.json")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert "absent.yaml" in r.stderr and not (tmp_path / "p.json").exists()


# --- good plans ---------------------------------------------------------------------

@pytest.fixture(scope="module", params=["flat-rectangle", "tilted-hexagon"])
def planned(request, tmp_path_factory):
    name = request.param
    out = tmp_path_factory.mktemp(name)
    mission_path = MISSIONS / name / "mission.yaml"
    argv = ["plan", str(mission_path), "-o", str(out / "plan.json"), "--samples", "20",
            "--qgc", str(out / "p.plan"), "--waypoints", str(out / "p.waypoints")]
    try:
        import matplotlib  # noqa: F401
        argv += ["--plot", str(out / "p.png")]
    except ImportError:
        pass
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        assert main(argv) == 0
    return {"name": name, "out": out, "mission": load_mission(mission_path),
            "doc": json.loads((out / "plan.json").read_text()), "stdout": stdout.getvalue()}


def test_plan_json_keys(planned):
    doc = planned["doc"]
    assert LOADER_KEYS <= set(doc)
    assert set(doc["stats"]) == STATS_KEYS
    assert set(doc["timings_s"]) == {"load", "coverage", "trajectory", "total", "write", "wall"}
    assert set(doc["trajectory"]) == {"form", "degree", "t", "values"}
    assert set(doc["samples"]) == {"hz", "t", "p", "v", "a", "pointing"}
    assert doc["frame"] == "ENU"
    home = planned["mission"].home
    assert doc["origin"] == {"lat": home.lat, "lon": home.lon, "alt_m": home.alt_m}
    assert all(set(w) == {"t", "p", "v", "a", "corner"} for w in doc["waypoints"])
    tm = doc["timings_s"]
    assert tm["total"] >= tm["load"] + tm["coverage"] + tm["trajectory"] - 1e-9
    # wall: the process started before the planning, which came before the writing
    assert tm["wall"] >= tm["total"] + tm["write"] - 0.02       # /proc/uptime has 10 ms steps


def test_path_in_free_space_and_stats(planned):
    doc, mission = planned["doc"], planned["mission"]
    grid = load_ogm(mission.map_path)
    path = np.array(doc["path"])
    r, c = grid.world_to_cell(path[:, 0], path[:, 1])
    r, c = np.round(r).astype(int), np.round(c).astype(int)
    assert grid.free[r, c].all()
    st = doc["stats"]
    assert st["path_length_m"] == pytest.approx(np.linalg.norm(np.diff(path, axis=0), axis=1).sum(), rel=1e-6)
    assert st["n_waypoints"] == len(doc["waypoints"])
    t = np.array(doc["samples"]["t"])
    assert st["duration_s"] == pytest.approx(t[-1] - t[0])
    # About the paper's 120 s at 1 m/s.
    assert 90.0 <= st["duration_s"] <= 160.0
    v = np.linalg.norm(np.array(doc["samples"]["v"]), axis=1)
    assert st["max_speed_m_s"] >= 0.99 * v.max()
    assert st["waypoint_residual_m"] <= 0.05


def test_trajectory_sampling_and_pointing(planned):
    doc = planned["doc"]
    tr = doc["samples"]
    t = np.array(tr["t"])
    assert tr["hz"] == 20.0
    assert np.allclose(np.diff(t)[:-1], 1 / 20)          # --samples 20 (last step may be shorter)
    assert t[0] == doc["waypoints"][0]["t"] and t[-1] == doc["waypoints"][-1]["t"]
    p = np.array(tr["p"])
    s = np.array(tr["pointing"])
    d = np.array(doc["target_enu_m"]) - p
    assert np.allclose(s, d / np.linalg.norm(d, axis=1, keepdims=True), atol=1e-9)   # eq. (21)
    # Velocity is the derivative of position (central differences at 20 Hz).
    v = np.array(tr["v"])
    fd = (p[2:-1] - p[:-3]) / (t[2:-1] - t[:-3])[:, None]
    assert np.abs(fd - v[1:-2]).max() < 0.02


def test_altitude_follows_terrain(planned):
    doc, mission = planned["doc"], planned["mission"]
    dem = load_dem(mission.dem_path)
    h = mission.flight.height_agl_m
    wp = np.array([w["p"] for w in doc["waypoints"]])
    assert np.allclose(wp[:, 2] - dem.height_at(wp[:, 0], wp[:, 1]), h, atol=1e-9)
    p = np.array(doc["samples"]["p"])
    agl = p[:, 2] - dem.height_at(p[:, 0], p[:, 1])
    assert np.abs(agl - h).max() < 0.15


def test_plan_json_types_and_finite(planned):
    doc = planned["doc"]
    json.dumps(doc, allow_nan=False)                     # no NaN / inf anywhere
    assert all(isinstance(doc["origin"][k], float) for k in ("lat", "lon", "alt_m"))
    assert all(len(xy) == 2 for xy in doc["path"])
    for w in doc["waypoints"]:
        assert isinstance(w["t"], float) and isinstance(w["corner"], bool)
        assert all(len(w[k]) == 3 for k in ("p", "v", "a"))
    n = len(doc["samples"]["t"])
    assert all(len(doc["samples"][k]) == n and len(doc["samples"][k][0]) == 3
               for k in ("p", "v", "a", "pointing"))
    assert isinstance(doc["stats"]["n_waypoints"], int)
    assert all(isinstance(v, float) for k, v in doc["stats"].items() if k != "n_waypoints")
    assert all(isinstance(v, float) and v >= 0 for v in doc["timings_s"].values())


def test_summary_line(planned):
    out, st, tm = planned["stdout"], planned["doc"]["stats"], planned["doc"]["timings_s"]
    first = out.splitlines()[0]
    assert f"{st['n_waypoints']} way-points" in first
    assert f"path {st['path_length_m']:.1f} m" in first and f"duration {st['duration_s']:.1f} s" in first
    assert f"coverage {100 * st['coverage_fraction']:.1f} %" in first
    assert f"orientation {st['orientation_deg']:.1f} deg" in first
    assert "timings:" in out and f"total {tm['total']:.3f} s" in out


def test_plot_written(planned):
    png = planned["out"] / "p.png"
    if not png.exists():
        pytest.skip("matplotlib not installed")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_load_plan_round_trip_and_errors(planned, tmp_path):
    pf = load_plan(planned["out"] / "plan.json")
    doc = planned["doc"]
    assert np.array_equal(pf.p_enu_m, np.array(doc["samples"]["p"]))
    assert np.array_equal(pf.waypoint_corner, [w["corner"] for w in doc["waypoints"]])
    assert pf.origin == (doc["origin"]["lat"], doc["origin"]["lon"], doc["origin"]["alt_m"])
    bad = dict(doc)
    del bad["stats"]
    (tmp_path / "a.json").write_text(json.dumps(bad))
    with pytest.raises(PlanError, match=r"a\.json: key 'stats'"):
        load_plan(tmp_path / "a.json")
    bad = json.loads(json.dumps(doc))
    bad["samples"]["p"] = bad["samples"]["p"][:-1]
    (tmp_path / "b.json").write_text(json.dumps(bad))
    with pytest.raises(PlanError, match=r"b\.json: key 'samples.p'"):
        load_plan(tmp_path / "b.json")
    (tmp_path / "c.json").write_text("{\n  \"frame\": ")
    with pytest.raises(PlanError, match=r"c\.json: line 2"):
        load_plan(tmp_path / "c.json")
