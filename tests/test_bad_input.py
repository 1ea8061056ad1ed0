"""A corpus of bad inputs across ``companion plan``, ``companion fly``,
``companion demo``, ``sitl`` and plan.json: every one ends with exit code 2,
exactly one line on stderr that names the flag or file, no traceback, and
nothing written (the working directory is unchanged, no flight.tlog, no
report, no partial plan). Each case runs in-process in a fresh directory."""

from __future__ import annotations

import json
import math
import shutil
import socket
from pathlib import Path

import pytest
import yaml

from companion.cli import main as companion_main
from companion.bundled import missions_dir
from companion.plan_io import STATS_KEYS, TIMING_KEYS
from sitl.cli import main as sitl_main
from ports import private_link

SRC = missions_dir() / "flat-rectangle"


def _free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def good_plan_doc(mission) -> dict:
    """A small valid plan.json for the flat-rectangle field (six way-points along
    the corridor y = 8.75 m at the flight height), built by hand: the cases only
    need a plan that passes every check until one thing is broken."""
    xs = [3.0 + 3.5 * i for i in range(6)]
    z = mission.flight.height_agl_m
    wps = [{"t": 4.0 * i, "p": [x, 8.75, z], "v": [0.0, 0.0, 0.0], "a": [0.0, 0.0, 0.0], "corner": i in (0, 5)}
           for i, x in enumerate(xs)]
    h = mission.home
    return {"name": mission.name, "frame": "ENU", "origin": {"lat": h.lat, "lon": h.lon, "alt_m": h.alt_m},
            "path": [[xs[0], 8.75], [xs[-1], 8.75]], "waypoints": wps,
            "trajectory": {"t": [0.0, 20.0], "p": [wps[0]["p"], wps[-1]["p"]], "v": [[0.0] * 3] * 2,
                           "a": [[0.0] * 3] * 2, "pointing": [[0.0, 1.0, 0.0]] * 2},
            "target_enu_m": [12.0, 20.0, 1.5],
            "stats": {k: 0.0 for k in STATS_KEYS}, "timings_s": {k: 0.0 for k in TIMING_KEYS}}


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A copy of the flat-rectangle mission and a good plan.json for it."""
    from mavcore.mission import load_mission
    from companion.plan_io import load_plan
    from companion.preflight import check_plan_file

    d = tmp_path_factory.mktemp("base")
    for f in SRC.iterdir():
        shutil.copy(f, d / f.name)
    mission = load_mission(d / "mission.yaml")
    (d / "plan.json").write_text(json.dumps(good_plan_doc(mission)))
    check_plan_file(load_plan(d / "plan.json"), mission)      # the base itself is good
    return d


def mission_with(d: Path, base: Path, change) -> str:
    """mission.yaml in ``d`` (maps alongside) with ``change(doc)`` applied."""
    for f in base.iterdir():
        if f.name not in ("mission.yaml", "plan.json"):
            shutil.copy(f, d / f.name)
    doc = yaml.safe_load((base / "mission.yaml").read_text())
    change(doc)
    (d / "mission.yaml").write_text(yaml.safe_dump(doc))
    return "mission.yaml"


def plan_with(d: Path, base: Path, change, raw: str | None = None) -> str:
    doc = json.loads((base / "plan.json").read_text())
    change(doc)
    text = raw if raw is not None else json.dumps(doc)
    (d / "bad-plan.json").write_text(text)
    return "bad-plan.json"


def _set(path: str, value):
    def change(doc):
        keys = path.split(".")
        node = doc
        for k in keys[:-1]:
            node = node.setdefault(k, {})
        node[keys[-1]] = value
    return change


def _wp(i: int, key: str, value):
    def change(doc):
        doc["waypoints"][i][key] = value
    return change


M = "mission.yaml"
#: (id, program, argv builder(d, base) -> argv, text the line must contain)
CASES = [
    # --- companion plan: the mission file and the planner's limits
    ("plan-missing-mission", "companion", lambda d, b: ["plan", "nope.yaml", "-o", "p.json"], "nope.yaml"),
    ("plan-mission-is-dir", "companion", lambda d, b: ["plan", ".", "-o", "p.json"], "."),
    ("plan-not-yaml", "companion", lambda d, b: (Path(d, "g.yaml").write_text("a: [1, 2\n"),
                                                 ["plan", "g.yaml", "-o", "p.json"])[1], "g.yaml"),
    ("plan-unknown-key", "companion", lambda d, b: ["plan", mission_with(d, b, _set("wings", 2)), "-o", "p.json"],
     "wings"),
    ("plan-unknown-nested-key", "companion",
     lambda d, b: ["plan", mission_with(d, b, _set("flight.speedd", 2)), "-o", "p.json"], "flight.speedd"),
    ("plan-negative-speed", "companion",
     lambda d, b: ["plan", mission_with(d, b, _set("flight.speed_m_s", -1.0)), "-o", "p.json"], M),
    ("plan-nan-speed", "companion",
     lambda d, b: ["plan", mission_with(d, b, _set("flight.speed_m_s", float("nan"))), "-o", "p.json"], M),
    ("plan-spacing-500", "companion",
     lambda d, b: ["plan", mission_with(d, b, _set("coverage.line_spacing_m", 500.0)), "-o", "p.json"],
     "coverage.line_spacing_m"),
    ("plan-spacing-tiny", "companion",
     lambda d, b: ["plan", mission_with(d, b, _set("coverage.line_spacing_m", 0.001)), "-o", "p.json"],
     "coverage.line_spacing_m"),
    ("plan-margin-huge", "companion",
     lambda d, b: ["plan", mission_with(d, b, _set("coverage.safety_margin_m", 1e9)), "-o", "p.json"],
     "safety_margin_m"),
    ("plan-lat-200", "companion", lambda d, b: ["plan", mission_with(d, b, _set("home.lat", 200.0)), "-o", "p.json"],
     M),
    ("plan-map-missing", "companion",
     lambda d, b: ["plan", mission_with(d, b, _set("map", "gone.yaml")), "-o", "p.json"], "gone.yaml"),
    ("plan-dem-missing", "companion",
     lambda d, b: ["plan", mission_with(d, b, _set("dem", "gone.asc")), "-o", "p.json"], "gone.asc"),
    ("plan-out-missing-dir", "companion", lambda d, b: ["plan", str(b / M), "-o", "no/dir/p.json"], "no/dir/p.json"),
    ("plan-out-is-dir", "companion", lambda d, b: (Path(d, "od").mkdir(), ["plan", str(b / M), "-o", "od"])[1],
     "od"),
    ("plan-samples-0", "companion", lambda d, b: ["plan", str(b / M), "-o", "p.json", "--samples", "0"],
     "--samples"),
    ("plan-samples-nan", "companion", lambda d, b: ["plan", str(b / M), "-o", "p.json", "--samples", "nan"],
     "--samples"),
    ("plan-samples-negative", "companion", lambda d, b: ["plan", str(b / M), "-o", "p.json", "--samples", "-3"],
     "--samples"),
    ("plan-plot-format", "companion", lambda d, b: ["plan", str(b / M), "-o", "p.json", "--plot", "p.xyz"], "p.xyz"),
    ("plan-same-output-twice", "companion", lambda d, b: ["plan", str(b / M), "-o", "p.json", "--qgc", "p.json"],
     "command line"),
    # --- the sim: section out of physical range (sitl loads it; plan too)
    ("sim-wind-1e308", "sitl", lambda d, b: [mission_with(d, b, _set("sim.wind", {"mean_enu_m_s": [1e308, 0, 0]}))],
     "sim.wind.mean_enu_m_s"),
    ("sim-wind-1000", "sitl", lambda d, b: [mission_with(d, b, _set("sim.wind", {"mean_enu_m_s": [1000, 0, 0]}))],
     "sim.wind.mean_enu_m_s"),
    ("sim-zero-mag", "sitl", lambda d, b: [mission_with(d, b, _set("sim.magnetic_field_enu_gauss", [0, 0, 0]))],
     "sim.magnetic_field_enu_gauss"),
    ("sim-vector-var-5", "sitl", lambda d, b: [mission_with(d, b, _set("sim.noise.vector_variance", 5.0))],
     "sim.noise.vector_variance"),
    ("sim-gyro-var-neg", "sitl", lambda d, b: [mission_with(d, b, _set("sim.noise.gyro_variance", -1.0))],
     "gyro_variance"),
    ("sim-canopy-1e6", "sitl", lambda d, b: [mission_with(d, b, _set("sim.canopy_height_m", 1e6))],
     "sim.canopy_height_m"),
    ("sim-seed-negative", "sitl", lambda d, b: [mission_with(d, b, _set("sim.seed", -3))], "sim.seed"),
    ("sim-drag-huge", "sitl", lambda d, b: [mission_with(d, b, _set("sim.wind", {"drag_n_s_m": 1e5}))],
     "sim.wind.drag_n_s_m"),
    ("sim-gust-tau-0", "sitl", lambda d, b: [mission_with(d, b, _set("sim.wind", {"gust_time_constant_s": 0.0}))],
     "gust_time_constant_s"),
    ("sim-rangefinder-rate", "sitl", lambda d, b: [mission_with(d, b, _set("sim.rangefinders",
                                                                             [{"id": 0, "rate_hz": 1e9}]))],
     "sim.rangefinders[].rate_hz"),
    ("sim-obstacle-tall", "sitl", lambda d, b: [mission_with(d, b, _set("sim.obstacles", [
        {"type": "cylinder", "x": 1.0, "y": 1.0, "height": 1e6, "radius": 1.0}]))], "sim.obstacles[].height"),
    ("sim-position-noise", "sitl", lambda d, b: [mission_with(d, b, _set("sim.noise.position_std_m", 1e3))],
     "sim.noise.position_std_m"),
    ("sim-start-off-map", "sitl", lambda d, b: [mission_with(d, b, _set("sim.start_enu_m", [5000.0, 5000.0])),
                                                "--listen", "udpin:127.0.0.1:1"], "sim.start_enu_m"),
    ("plan-rejects-sim-too", "companion",
     lambda d, b: ["plan", mission_with(d, b, _set("sim.wind", {"mean_enu_m_s": [1e308, 0, 0]})), "-o", "p.json"],
     "sim.wind.mean_enu_m_s"),
    # --- sitl options
    ("sitl-speed-inf", "sitl", lambda d, b: [str(b / M), "--speed", "inf"], "--speed"),
    ("sitl-speed-nan", "sitl", lambda d, b: [str(b / M), "--speed", "nan"], "--speed"),
    ("sitl-speed-neg", "sitl", lambda d, b: [str(b / M), "--speed", "-1"], "--speed"),
    ("sitl-start-1e9", "sitl", lambda d, b: [str(b / M), "--start", "1e9,1e9", "--listen", "udpin:127.0.0.1:1"],
     "--start 1e9,1e9"),
    ("sitl-start-nan", "sitl", lambda d, b: [str(b / M), "--start", "nan,1"], "--start"),
    ("sitl-start-one-number", "sitl", lambda d, b: [str(b / M), "--start", "1"], "--start"),
    ("sitl-listen-garbage", "sitl", lambda d, b: [str(b / M), "--listen", "bogus"], "--listen"),
    ("sitl-listen-port-range", "sitl", lambda d, b: [str(b / M), "--listen", "udpin:127.0.0.1:99999"], "--listen"),
    ("sitl-out-garbage", "sitl", lambda d, b: [str(b / M), "--out", "tcp:nohost"], "--out"),
    ("sitl-listen-unresolvable", "sitl", lambda d, b: [str(b / M), "--listen", "udpin:no.such.host.invalid:14540"],
     "--listen"),
    ("sitl-listen-in-use", "sitl", lambda d, b: [str(b / M), "--listen", f"udpin:127.0.0.1:{_HELD_UDP[0]}"],
     "already in use"),
    ("sitl-controller-range", "sitl", lambda d, b: [str(b / M), "--controller", "300/1"], "--controller"),
    ("sitl-controller-link", "sitl", lambda d, b: [str(b / M), "--controller", "1/191@udpin:127.0.0.1:9"],
     "--controller"),
    ("sitl-key-missing", "sitl", lambda d, b: [str(b / M), "--signing-key", "none.key"], "--signing-key"),
    ("sitl-key-empty", "sitl", lambda d, b: (Path(d, "e.key").write_text(""),
                                             [str(b / M), "--signing-key", "e.key"])[1], "--signing-key"),
    ("sitl-physics-multiple", "sitl", lambda d, b: [str(b / M), "--physics-hz", "999"], "--physics-hz"),
    ("sitl-sensor-hz-divides", "sitl", lambda d, b: [str(b / M), "--physics-hz", "1001", "--sensor-hz", "7"],
     "--sensor-hz"),
    ("sitl-max-clients-0", "sitl", lambda d, b: [str(b / M), "--max-clients", "0"], "--max-clients"),
    ("sitl-client-timeout-nan", "sitl", lambda d, b: [str(b / M), "--client-timeout", "nan"], "--client-timeout"),
    ("sitl-same-link-twice", "sitl", lambda d, b: [str(b / M), "--listen", "udpin:127.0.0.1:14600", "--control-out",
                                                   "udpin:127.0.0.1:14600"], "the same link"),
    # --- companion fly: link, outputs, options
    ("fly-unresolvable", "companion", lambda d, b: ["fly", str(b / M), "--connect", "udpout:no.such.host.invalid:1"],
     "--connect udpout:no.such.host.invalid:1"),
    ("fly-tcp-refused", "companion", lambda d, b: ["fly", str(b / M), "--connect", f"tcp:127.0.0.1:{_free_tcp_port()}"],
     "--connect tcp:"),
    ("fly-udpin-in-use", "companion", lambda d, b: ["fly", str(b / M), "--connect", f"udpin:127.0.0.1:{_HELD_UDP[0]}"],
     "already in use"),
    ("fly-connect-garbage", "companion", lambda d, b: ["fly", str(b / M), "--connect", "flight.tlog"], "--connect"),
    ("fly-report-is-dir", "companion", lambda d, b: (Path(d, "r").mkdir(), ["fly", str(b / M), "--report", "r"])[1],
     "--report r"),
    ("fly-tlog-is-dir", "companion", lambda d, b: (Path(d, "t").mkdir(), ["fly", str(b / M), "--tlog", "t"])[1],
     "--tlog t"),
    ("fly-report-missing-dir", "companion", lambda d, b: ["fly", str(b / M), "--report", "x/y/r.json"], "--report"),
    ("fly-tlog-equals-report", "companion", lambda d, b: ["fly", str(b / M), "--tlog", "a.json", "--report", "a.json"],
     "--report a.json"),
    ("fly-cut-negative", "companion", lambda d, b: ["fly", str(b / M), "--cut", "-5"], "--cut"),
    ("fly-cut-nan", "companion", lambda d, b: ["fly", str(b / M), "--cut", "nan"], "--cut"),
    ("fly-key-two-words", "companion", lambda d, b: (Path(d, "k").write_text("two words\n"),
                                                     ["fly", str(b / M), "--signing-key", "k"])[1], "--signing-key k"),
    ("fly-plan-missing", "companion", lambda d, b: ["fly", str(b / M), "--plan", "gone.json"], "gone.json"),
    # --- plan.json given to fly
    ("planjson-not-json", "companion", lambda d, b: ["fly", str(b / M), "--plan", plan_with(d, b, lambda p: None,
                                                                                           raw="{oops")],
     "bad-plan.json"),
    ("planjson-1e300", "companion", lambda d, b: ["fly", str(b / M), "--plan",
                                                  plan_with(d, b, _wp(3, "p", [1e300, 0.0, 1.5]))], "waypoints[3].p"),
    ("planjson-nan", "companion", lambda d, b: ["fly", str(b / M), "--plan",      # JSON's NaN literal
                                                plan_with(d, b, _wp(3, "p", [math.nan, 0.0, 1.5]))],
     "waypoints[].p"),
    ("planjson-wrong-shape", "companion", lambda d, b: ["fly", str(b / M), "--plan",
                                                        plan_with(d, b, _wp(2, "p", [1.0, 2.0]))], "waypoints[].p"),
    ("planjson-times-not-increasing", "companion",
     lambda d, b: ["fly", str(b / M), "--plan", plan_with(d, b, _wp(4, "t", 0.0))], "waypoints[].t"),
    ("planjson-underground", "companion",
     lambda d, b: ["fly", str(b / M), "--plan", plan_with(d, b, _wp(1, "p", _shift(b, 1, (0, 0, -50))))],
     "waypoints[1].p"),
    ("planjson-5km-off-map", "companion",
     lambda d, b: ["fly", str(b / M), "--plan", plan_with(d, b, _wp(2, "p", _shift(b, 2, (5000, 0, 0))))],
     "waypoints[2].p"),
    ("planjson-other-field", "companion",
     lambda d, b: ["fly", str(b / M), "--plan", plan_with(d, b, _set("origin.lat", 45.9))], "origin"),
    ("planjson-1e5-s", "companion", lambda d, b: ["fly", str(b / M), "--plan", plan_with(d, b, _stretch_times(1e5))],
     "waypoints[].t"),
    ("planjson-speed", "companion",
     lambda d, b: ["fly", str(b / M), "--plan", plan_with(d, b, _wp(3, "v", [1e4, 0.0, 0.0]))], "waypoints[3].v"),
    ("planjson-missing-key", "companion",
     lambda d, b: ["fly", str(b / M), "--plan", plan_with(d, b, lambda p: p.pop("waypoints"))], "waypoints"),
    ("planjson-one-waypoint", "companion",
     lambda d, b: ["fly", str(b / M), "--plan", plan_with(d, b, lambda p: p.update(waypoints=p["waypoints"][:1]))],
     "waypoints"),
    # --- companion demo
    ("demo-no-such-mission", "companion", lambda d, b: ["demo", "--mission", "no-such-field"], "--mission"),
    ("demo-cut-0", "companion", lambda d, b: ["demo", "--cut", "0"], "--cut"),
    ("demo-out-is-file", "companion", lambda d, b: (Path(d, "f").write_text("x"), ["demo", "--out", "f"])[1],
     "--out f"),
    ("demo-out-missing-parent", "companion", lambda d, b: ["demo", "--out", "a/b/c"], "--out"),
    ("demo-key-is-dir", "companion", lambda d, b: ["demo", "--signing-key", "."], "--signing-key"),
    ("demo-report-is-dir", "companion", lambda d, b: (Path(d, "o", "report.json").mkdir(parents=True),
                                                      ["demo", "--out", "o"])[1], "report.json"),
    ("demo-bad-sim", "companion",
     lambda d, b: ["demo", "--mission", mission_with(d, b, _set("sim.wind", {"mean_enu_m_s": [1e308, 0, 0]}))],
     "sim.wind.mean_enu_m_s"),
]

_HELD_UDP: list[int] = []


def _shift(base: Path, i: int, dp):
    p = json.loads((base / "plan.json").read_text())["waypoints"][i]["p"]
    return [p[0] + dp[0], p[1] + dp[1], p[2] + dp[2]]


def _stretch_times(t_last: float):
    def change(doc):
        wps = doc["waypoints"]
        t0, t1 = wps[0]["t"], wps[-1]["t"]
        for w in wps:
            w["t"] = t0 + (w["t"] - t0) * (t_last - t0) / (t1 - t0)
    return change


@pytest.fixture(scope="module")
def held_udp_port():
    """A UDP port held by another socket, for the 'in use' cases. It sets
    SO_REUSEADDR as pymavlink's udpin does, so a binder that set it too would
    share the port: ours do not, so they see it in use."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    s.bind(("127.0.0.1", 0))
    _HELD_UDP[:] = [s.getsockname()[1]]
    yield s
    s.close()


def test_corpus_is_large_and_covers_every_entry_point():
    ids = [c[0] for c in CASES]
    assert len(ids) == len(set(ids)) and len(ids) >= 60
    for prefix in ("plan-", "fly-", "sitl-", "demo-", "planjson-", "sim-"):
        assert any(i.startswith(prefix) for i in ids)


def _tree(d: Path) -> dict:
    return {str(p.relative_to(d)): (p.is_dir(), p.stat().st_size if p.is_file() else 0, p.stat().st_mtime_ns)
            for p in d.rglob("*")}


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input(case, base, held_udp_port, tmp_path, capsys, monkeypatch):
    _, program, build, needle = case
    monkeypatch.chdir(tmp_path)
    argv = build(tmp_path, base)
    before = _tree(tmp_path)
    capsys.readouterr()
    if program == "companion":
        if argv[0] in ("fly", "demo"):
            argv = argv + ["--quiet"]
        rc = companion_main(private_link(argv))
    else:
        rc = sitl_main(argv)
    out, err = capsys.readouterr()
    assert rc == 2, (rc, out, err)
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert "Traceback" not in err and "Traceback" not in out
    assert err.startswith(("companion ", "sitl: error: ")) and "error:" in err
    assert needle in err, err
    assert _tree(tmp_path) == before, "something was written"
    assert not list(base.glob("*.part")) and not Path(base, "flight.tlog").exists()
