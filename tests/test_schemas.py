"""plan.json and report.json against their JSON Schemas (docs/schemas/), and format_version.

- every file the project writes validates: a plan of each bundled mission
  (``companion plan``), the plan and the report of a real short flight
  (``companion demo --cut``), the report of a flight that failed;
- the schemas are not vacuous: documents with a key missing, a wrong type,
  a value out of range or another major version are rejected;
- the schemas, the writers and the pages (docs/plan-json.md,
  docs/report-json.md) name the same keys, so none can fall behind;
- the plan loader reads 2.x, and 1.x with or without ``format_version`` (a
  stored 1.0 plan), and rejects another major version with one line (exit
  code 2 from ``companion fly``).
"""

from __future__ import annotations

import base64
import contextlib
import copy
import dataclasses
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest
from jsonschema import Draft202012Validator

from companion.cli import main
from ports import private_link
from companion.bundled import missions_dir
from mavcore.errors import PlanError
from companion.format_version import check_format_version
from companion.plan_io import PLAN_FORMAT_VERSION, load_plan
from companion.flight.monitor import FlightMonitor, Violation
from companion.report import (REPORT_FORMAT_VERSION, FlightReport, ReplanningStats, TrackingStats,
                              tracking_stats, write_report)

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
BUNDLED = sorted(d.name for d in missions_dir().iterdir() if (d / "mission.yaml").is_file())
#: A plan.json of format 1.0 as ``companion plan`` wrote it before 2.0 (the replay corpus's).
OLD_PLAN = ROOT / "tests" / "data" / "plan-1.0" / "flat-rectangle.json"
#: Top-level keys the plan schema does not require (``--samples``).
PLAN_OPTIONAL = {"samples"}


def _schema(name: str) -> dict:
    return json.loads((DOCS / "schemas" / f"{name}.schema.json").read_text(encoding="utf-8"))


PLAN_SCHEMA = _schema("plan")
REPORT_SCHEMA = _schema("report")
PLAN = Draft202012Validator(PLAN_SCHEMA)
REPORT = Draft202012Validator(REPORT_SCHEMA)


def _errors(validator, doc) -> list[str]:
    return [f"{'/'.join(map(str, e.absolute_path))}: {e.message}" for e in validator.iter_errors(doc)]


_PLANS: dict[str, dict] = {}


def _plan_doc(name: str, tmp_path_factory) -> dict:
    """plan.json of a bundled mission written by ``companion plan`` (planned once per module)."""
    if name not in _PLANS:
        out = tmp_path_factory.mktemp(f"plan-{name}") / "plan.json"
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(["plan", str(missions_dir() / name / "mission.yaml"), "-o", str(out), "--samples", "2"]) == 0
        _PLANS[name] = {"path": out, "doc": json.loads(out.read_text(encoding="utf-8"))}
    return _PLANS[name]


@pytest.fixture
def plan_doc(tmp_path_factory) -> dict:
    """A real plan.json document cut to its first 3 way-points, path points,
    trajectory pieces and samples (validating the whole one takes a good
    fraction of a second), to be spoiled by a test."""
    full = _plan_doc("flat-rectangle", tmp_path_factory)["doc"]
    doc = copy.deepcopy(dict(full, path=full["path"][:3], waypoints=full["waypoints"][:3]))
    tr = doc["trajectory"]
    va = tr["values"]
    assert tr["form"] == "knot-states"                   # Q = 0: the states at the knots
    states = np.frombuffer(base64.b64decode(va["base64"]), "<f8").reshape(va["shape"])[:3]
    tr["t"] = tr["t"][:3]
    va.update(shape=list(states.shape), base64=base64.b64encode(states.tobytes()).decode("ascii"))
    doc["samples"] = {k: v if k == "hz" else v[:3] for k, v in full["samples"].items()}
    return doc


def _report_doc(**changes) -> dict:
    """A report.json document as ``write_report`` writes it (hand-made flight figures)."""
    rep = FlightReport(completed=True, control="companion", sim_time_s=130.0, wall_time_s=4.0,
                       tracking=tracking_stats([1.0, 7.0, 8.0], [0.5, 0.003, 0.004], 0.0),
                       replanning=ReplanningStats(0, 2.2, 0.0), coverage_fraction=1.0, tlog="out/flight.tlog",
                       mission="flat-rectangle", phase="done", real_time_factor=32.5, n_frames=32500,
                       trajectory_duration_s=118.9, planned_coverage_fraction=1.0, path_flown_fraction=1.0,
                       link={"received": 250_000, "sent": 40_000, "bad": 0})
    return json.loads(json.dumps(dataclasses.replace(rep, **changes).to_dict()))


def _crashed_report_doc() -> dict:
    """The report of a crash, its ``crash`` and ``violation`` made by the flight monitor itself."""
    monitor = FlightMonitor()
    monitor.armed(3.0, 6 << 16)
    monitor.on_statustext(42.5, 2, "CRASH: vehicle hit the ground at 3.1 m/s")
    return _report_doc(completed=False, phase="trajectory", error=monitor.first.detail, crashed=True,
                       crash=monitor.crash, violation=monitor.first.to_dict(), coverage_fraction=0.4,
                       path_flown_fraction=0.4, degraded={"t_s": 20.0, "reason": "frame jitter",
                                                          "jitter_p95_s": 0.012, "frames_lost": 3},
                       end_phase="ended", control_in_use="vehicle",
                       control_mode_changes=({"t_s": 20.0, "from": "companion", "to": "vehicle",
                                              "reason": "frame jitter", "phase": "trajectory"},),
                       faults=({"t_s": 30.0, "kind": "tlog", "detail": "f.tlog: cannot write: No space left "
                                "on device (ENOSPC)", "phase": "trajectory"},
                               {"t_s": None, "kind": "report", "detail": "r.json: cannot write the report",
                                "phase": "ended"}),
                       report_fallback={"path": "/tmp/companion-r-1-2.json", "wanted": "r.json",
                                        "reason": "r.json: cannot write the report"})


# --- the schemas themselves --------------------------------------------------------

def test_schemas_are_draft_2020_12_and_describe_version_1():
    for schema in (PLAN_SCHEMA, REPORT_SCHEMA):
        assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
        Draft202012Validator.check_schema(schema)
    assert PLAN_FORMAT_VERSION == "2.1" and REPORT_FORMAT_VERSION == "3.4"
    # the writers' version is one the schemas accept, the next major is not
    for validator, doc_version in ((PLAN, PLAN_FORMAT_VERSION), (REPORT, REPORT_FORMAT_VERSION)):
        version_schema = validator.schema["properties"]["format_version"]
        assert Draft202012Validator(version_schema).is_valid(doc_version)
        major = int(doc_version.split(".")[0])
        assert not Draft202012Validator(version_schema).is_valid(f"{major + 1}.0")
        assert not Draft202012Validator(version_schema).is_valid(f"{major - 1}.0")


# --- every file the project writes validates ----------------------------------------

#: Bundled missions whose plan.json takes long to write and validate: the 1 ha vineyard's
#: 79 min of trajectory sampled at 10 Hz (~40 s here, until plan.json stores the polynomial
#: pieces, issue 18); tests/test_fields.py plans it in-process.
SLOW_PLANS = ("vineyard-1ha",)


@pytest.mark.parametrize("mission", [pytest.param(m, marks=pytest.mark.slow) if m in SLOW_PLANS else m
                                     for m in BUNDLED])
def test_plan_of_every_bundled_mission_validates_and_loads(mission, tmp_path_factory):
    planned = _plan_doc(mission, tmp_path_factory)
    doc = planned["doc"]
    assert _errors(PLAN, doc) == []
    assert doc["format_version"] == PLAN_FORMAT_VERSION
    assert next(iter(doc)) == "format_version"           # first key: readable with `head`
    pf = load_plan(planned["path"])
    assert pf.waypoint_t_s.shape[0] == doc["stats"]["n_waypoints"]


def test_report_of_a_crashed_flight_validates():
    doc = _crashed_report_doc()
    assert _errors(REPORT, doc) == []
    assert doc["violation"]["kind"] == "crash" and doc["crash"]["t_s"] == 42.5


def test_report_of_a_failed_flight_validates(tmp_path):
    # what the runner reports when the vehicle never answers: no samples, no tlog
    rep = FlightReport(completed=False, control="vehicle", sim_time_s=0.0, wall_time_s=10.0,
                       tracking=tracking_stats([], [], 0.0, truth_source="estimate"),
                       replanning=ReplanningStats(), coverage_fraction=float("nan"), tlog=None,
                       mission="flat-rectangle", phase="connect",
                       error="udpout:127.0.0.1:14540: no vehicle HEARTBEAT within 10 s")
    doc = json.loads(write_report(rep, tmp_path / "report.json").read_text(encoding="utf-8"))
    assert _errors(REPORT, doc) == []
    assert doc["tracking"]["max_error_m"] is None and doc["coverage_fraction"] is None


@pytest.mark.slow
def test_demo_flight_writes_a_plan_and_a_report_that_validate(tmp_path):
    out = tmp_path / "out"
    with contextlib.redirect_stdout(io.StringIO()):
        rc = main(["demo", "--cut", "2", "--no-plots", "--quiet", "--out", str(out)])
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    assert rc == 0 and report["completed"], report.get("error")
    assert _errors(REPORT, report) == []
    assert _errors(PLAN, json.loads((out / "plan.json").read_text(encoding="utf-8"))) == []
    assert report["format_version"] == REPORT_FORMAT_VERSION
    assert Path(report["tlog"]).is_file()
    # the flight is over the 2 s cut, so the trajectory phase had samples
    assert report["tracking"]["n_samples"] > 0 and report["n_frames"] > 0


# --- the schemas reject what is wrong -----------------------------------------------

def _set(doc: dict, path: str, value) -> None:
    *parents, leaf = path.split(".")
    d = doc
    for p in parents:
        d = d[int(p)] if isinstance(d, list) else d[p]
    if value is _DELETE:
        del d[leaf]
    elif isinstance(d, list):
        d[int(leaf)] = value
    else:
        d[leaf] = value


class _Deleted:
    """The key is removed (a stable repr: test ids must match across pytest-xdist workers)."""

    def __repr__(self) -> str:
        return "<deleted>"


_DELETE = _Deleted()

PLAN_BREAKAGES = [
    ("format_version", "1.0"), ("format_version", "3.0"), ("format_version", "2"), ("format_version", 2.0),
    ("format_version", "2.0.0"),
    ("frame", "NED"), ("name", None),
    ("origin.lat", 91.0), ("origin.alt_m", _DELETE), ("origin.x", 0.0),
    ("path", [[0.0, 0.0]]), ("path.0", [0.0, 0.0, 0.0]),
    ("waypoints", []), ("waypoints.0.p", [1.0, 2.0]), ("waypoints.0.corner", "yes"),
    ("waypoints.0.t", "0"), ("waypoints.0.yaw", 0.0), ("waypoints.1.v", _DELETE),
    ("samples.hz", 0), ("samples.t", ["0", "1"]), ("samples.p.0", [1.0, 2.0]),
    ("samples.pointing", _DELETE), ("samples.jerk", []), ("target_enu_m", [0.0, 0.0]),
    ("trajectory.t", ["0", "1"]), ("trajectory.jerk", []), ("trajectory.form", "samples"),
    ("trajectory.degree", 7.5), ("trajectory.values.dtype", "<f4"),
    ("trajectory.values.shape", [3, 4, 2]), ("trajectory.values.base64", "not base64!"),
    ("trajectory.values.base64", _DELETE), ("timings_s.wall", _DELETE), ("timings_s.write", -1.0),
    ("trajectory_weights.r_snap", 0.0), ("trajectory_weights.q_jerk", -1.0),
    ("stats.n_waypoints", 2.5), ("stats.coverage_fraction", 1.5), ("stats.path_length_m", "184"),
    ("stats.extra", "text"), ("timings_s.total", -1.0),
]


@pytest.mark.parametrize("path,value", PLAN_BREAKAGES, ids=[f"{p}={v!r}" for p, v in PLAN_BREAKAGES])
def test_plan_schema_rejects_a_broken_document(plan_doc, path, value):
    _set(plan_doc, path, value)
    assert _errors(PLAN, plan_doc)


@pytest.mark.parametrize("key", PLAN_SCHEMA["required"])
def test_plan_schema_rejects_a_missing_key(plan_doc, key):
    del plan_doc[key]
    assert _errors(PLAN, plan_doc)


REPORT_BREAKAGES = [
    ("format_version", "2.0"), ("format_version", "4.0"), ("format_version", None),
    ("faults", [{"t_s": 1.0, "kind": "disk", "detail": "", "phase": "trajectory"}]), ("end_phase", "flying"),
    ("control_in_use", "pilot"), ("report_fallback", {"path": "/tmp/r.json"}),
    ("completed", "yes"), ("control", "pilot"), ("sim_time_s", -1.0), ("sim_time_s", None),
    ("tracking.max_error_m", -0.1), ("tracking.max_error_m", "0.1"), ("tracking.truth_source", "gps"),
    ("tracking.n_samples", 1.5), ("tracking.p95_error_m", 0.1), ("tracking.settle_s", _DELETE),
    ("replanning.events", -1), ("replanning.min_clearance_m", _DELETE), ("coverage_fraction", 1.2),
    ("replanning.clearance_source", "rangefinder"), ("replanning.min_range_m", -0.1),
    ("replanning.event_list", [{"t_s": 1.0, "pos_enu_m": [0, 0], "obstacle_range_m": None, "action": "avoid",
                                "detail": ""}]),
    ("replanning.event_list", [{"t_s": 1.0, "pos_enu_m": [0, 0, 0], "obstacle_range_m": None,
                                "action": "dodge", "detail": ""}]),
    ("tlog", 0), ("phase", "flying"), ("n_frames", 1.5),
    ("error", "vehicle silent"),          # completed with an error
    ("phase", "landing"),                 # completed before the end
    ("crashed", True),                    # completed after a crash
    ("violation", {"t_s": 1.0, "kind": "tracking", "detail": "x", "action": "land", "values": {}}),
    ("link.received", -1), ("link.bad", _DELETE), ("link", 3), ("planned_coverage_fraction", 1.5),
    ("path_flown_fraction", -0.1), ("resumed_from_s", -1.0), ("interrupted", 2),
    ("degraded", {"t_s": 3.0}), ("crash", {"t_s": 1.0}),
]

CRASHED_BREAKAGES = [
    ("violation.action", "fly"), ("violation.kind", None), ("violation.values", []),
    ("violation.extra", 1), ("crash.text", None), ("crash.t_s", "42"), ("crashed", "yes"),
    ("degraded.reason", _DELETE), ("degraded.frames_lost", -3),
]


@pytest.mark.parametrize("path,value", CRASHED_BREAKAGES, ids=[f"{p}={v!r}" for p, v in CRASHED_BREAKAGES])
def test_report_schema_rejects_a_broken_crash_report(path, value):
    doc = _crashed_report_doc()
    _set(doc, path, value)
    assert _errors(REPORT, doc)


@pytest.mark.parametrize("path,value", REPORT_BREAKAGES, ids=[f"{p}={v!r}" for p, v in REPORT_BREAKAGES])
def test_report_schema_rejects_a_broken_document(path, value):
    doc = _report_doc()
    assert _errors(REPORT, doc) == []
    _set(doc, path, value)
    assert _errors(REPORT, doc)


@pytest.mark.parametrize("key", REPORT_SCHEMA["required"])
def test_report_schema_rejects_a_missing_key(key):
    doc = _report_doc()
    del doc[key]
    assert _errors(REPORT, doc)


def test_schemas_accept_later_minor_versions_where_growth_is_expected(plan_doc):
    assert _errors(PLAN, plan_doc) == []                 # the cut document is valid as it is
    # a 2.x file may add keys at the top level and in the open objects
    plan_doc.update(format_version="2.3", replans=[{"waypoints": [0, 5]}])
    plan_doc["stats"]["n_sorties"] = 1
    plan_doc["timings_s"]["sorties"] = 0.01
    assert _errors(PLAN, plan_doc) == []
    doc = _report_doc()
    doc.update(format_version="3.1", sorties=[{"completed": True}])
    doc["replanning"]["replans_per_corridor"] = [1, 0]
    doc["link"]["auth_rejected"] = 0
    assert _errors(REPORT, doc) == []
    doc = _crashed_report_doc()
    doc["degraded"]["rtt_s"] = 0.01
    assert _errors(REPORT, doc) == []
    # a flight that did not complete may stop in any phase with an error
    assert _errors(REPORT, _report_doc(completed=False, phase="landing", error="no COMMAND_ACK")) == []


# --- writers, schemas and pages name the same keys ------------------------------------

def _is_object(sub: dict) -> bool:
    t = sub.get("type")
    return t == "object" or (isinstance(t, list) and "object" in t)


def _schema_keys(schema: dict, prefix: str = "") -> dict[str, dict]:
    """dotted key -> sub-schema of every object property ('[]' for array items)."""
    out = {}
    root = schema
    for key, sub in schema.get("properties", {}).items():
        while "$ref" in sub:
            sub = root["$defs"][sub["$ref"].rsplit("/", 1)[1]]
        out[prefix + key] = sub
        if _is_object(sub) and "properties" in sub:
            out.update(_schema_keys({**sub, "$defs": root.get("$defs", {})}, f"{prefix}{key}."))
        items = sub.get("items", {})
        if items.get("type") == "object":
            out.update(_schema_keys({**items, "$defs": root.get("$defs", {})}, f"{prefix}{key}[]."))
    return out


def _doc_keys(doc, prefix: str = "") -> set[str]:
    out = set()
    for key, value in doc.items():
        out.add(prefix + key)
        if isinstance(value, dict):
            out |= _doc_keys(value, f"{prefix}{key}.")
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            out |= _doc_keys(value[0], f"{prefix}{key}[].")
    return out


def _every_object_requires_all_its_properties(schema: dict, optional: frozenset = frozenset()) -> None:
    if "properties" in schema:
        assert set(schema["required"]) == set(schema["properties"]) - optional, \
            schema.get("title", schema.get("description"))
    for sub in list(schema.get("properties", {}).values()) + [schema.get("items")]:
        if isinstance(sub, dict):
            _every_object_requires_all_its_properties(sub)


def test_plan_writer_and_schema_have_the_same_keys(tmp_path_factory):
    doc = _plan_doc("flat-rectangle", tmp_path_factory)["doc"]
    assert _doc_keys(doc) == set(_schema_keys(PLAN_SCHEMA))
    _every_object_requires_all_its_properties(PLAN_SCHEMA, frozenset(PLAN_OPTIONAL))


def test_report_fields_and_schema_have_the_same_keys():
    props = REPORT_SCHEMA["properties"]
    top = {f.name for f in dataclasses.fields(FlightReport)} | {"format_version"}
    assert set(props) == set(REPORT_SCHEMA["required"]) == top
    for key, cls in (("tracking", TrackingStats), ("replanning", ReplanningStats), ("violation", Violation)):
        assert set(props[key]["properties"]) == set(props[key]["required"]) == {f.name for f in dataclasses.fields(cls)}
    crash = _crashed_report_doc()["crash"]           # the monitor's own dict
    assert set(props["crash"]["properties"]) == set(props["crash"]["required"]) == set(crash)
    # every key of a report with every optional object filled is in the schema
    assert _doc_keys(_crashed_report_doc()) <= set(_schema_keys(REPORT_SCHEMA))


def test_example_on_the_report_page_validates():
    text = (DOCS / "report-json.md").read_text(encoding="utf-8")
    example = json.loads(text.split("```json", 1)[1].split("```", 1)[0])
    assert _errors(REPORT, example) == []


def test_report_phase_enum_is_the_runners_phases():
    from companion.runner import PHASES

    assert REPORT_SCHEMA["properties"]["phase"]["enum"] == list(PHASES)


@pytest.mark.parametrize("page,schema", [("plan-json.md", PLAN_SCHEMA), ("report-json.md", REPORT_SCHEMA)])
def test_every_schema_key_is_on_its_page(page, schema):
    text = (DOCS / page).read_text(encoding="utf-8")
    missing = []
    for dotted in _schema_keys(schema):
        leaf = dotted.rsplit(".", 1)[-1]
        parent = dotted.rsplit(".", 1)[0] if "." in dotted else None
        named = f"`{dotted}`" in text or (parent is not None and f"`{leaf}`" in text and f"`{parent}`" in text)
        if not named:
            missing.append(dotted)
    assert missing == [], f"docs/{page} does not name {missing}"


# --- format_version when reading ------------------------------------------------------

@pytest.mark.parametrize("value", ["2.0", "2.12"])
def test_plan_loader_reads_every_2x_version(plan_doc, tmp_path, value):
    plan_doc["format_version"] = value
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan_doc), encoding="utf-8")
    pf = load_plan(path)
    assert pf.data == plan_doc and pf.format_major == 2 and pf.trajectory is not None


@pytest.mark.parametrize("value", ["1.0", "1.12", None])
def test_plan_loader_reads_a_stored_1x_plan_with_every_1x_version(tmp_path, value):
    doc = json.loads(OLD_PLAN.read_text(encoding="utf-8"))
    assert doc["format_version"] == "1.0" and "t" in doc["trajectory"]     # really the old format
    if value is None:
        del doc["format_version"]       # written before versioning: read as 1.0
    else:
        doc["format_version"] = value
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    pf = load_plan(path)
    assert pf.data == doc and pf.format_major == 1 and pf.trajectory is None
    assert np.array_equal(pf.p_enu_m, doc["trajectory"]["p"])
    assert pf.waypoint_t_s.shape[0] == len(doc["waypoints"]) == doc["stats"]["n_waypoints"]


@pytest.mark.parametrize("value,problem", [
    ("3.0", r"version 3\.0 is not supported \(this companion reads 2\.x and 1\.x\)"),
    ("0.9", r"version 0\.9 is not supported"),
    ("1", r'expected a string "MAJOR\.MINOR"'), ("1.0.0", "MAJOR.MINOR"), ("v1.0", "MAJOR.MINOR"),
    ("01.0", "MAJOR.MINOR"), ("", "MAJOR.MINOR"), (1.0, "MAJOR.MINOR"), (None, "MAJOR.MINOR"),
])
def test_plan_loader_rejects_other_versions_with_one_line(plan_doc, tmp_path, value, problem):
    plan_doc["format_version"] = value
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan_doc), encoding="utf-8")
    with pytest.raises(PlanError, match=re.escape(f"{path}: key 'format_version': ") + ".*" + problem) as exc:
        load_plan(path)
    assert "\n" not in str(exc.value)


def test_check_format_version_returns_the_parsed_version():
    v = check_format_version({"format_version": "1.12"}, 1, "f.json", PlanError)
    assert (v.major, v.minor, str(v)) == (1, 12, "1.12")
    assert str(check_format_version({}, 1, "f.json", PlanError)) == "1.0"


def test_fly_with_a_plan_of_another_major_version_exits_2_and_writes_nothing(plan_doc, tmp_path, monkeypatch,
                                                                              capsys):
    monkeypatch.chdir(tmp_path)
    plan_doc["format_version"] = "3.0"
    Path("plan.json").write_text(json.dumps(plan_doc), encoding="utf-8")
    rc = main(private_link(["fly", str(missions_dir() / "flat-rectangle" / "mission.yaml"), "--plan", "plan.json",
                            "--quiet"]))
    err = capsys.readouterr().err
    assert rc == 2
    assert err == ("companion fly: error: plan.json: key 'format_version': version 3.0 is not supported "
                   "(this companion reads 2.x and 1.x)\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan.json"]      # no tlog, no report
