"""Size limits of the modules that grew god objects (issue 17): no function or
method over 120 lines in the SITL's server, the flight core and the
geometric controller. Counted statically (``ast``: first to last line of the
definition, decorators excluded, docstring included)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MAX_LINES = 120
CHECKED = ("sitl/server.py", "companion/flight/core.py", "companion/control/geometric.py")


def long_functions(source: str, max_lines: int = MAX_LINES) -> list:
    """(qualified name, line count) of every function in ``source`` longer than ``max_lines``."""
    out = []

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = child.end_lineno - child.lineno + 1
                if n > max_lines:
                    out.append((prefix + child.name, n))
                visit(child, prefix + child.name + ".")
            elif isinstance(child, ast.ClassDef):
                visit(child, prefix + child.name + ".")

    visit(ast.parse(source), "")
    return out


def test_long_functions_counts_methods_and_nested_functions():
    body = "\n".join(f"    x{i} = {i}" for i in range(5))
    src = f"class A:\n    def f(self):\n    {body.replace(chr(10), chr(10) + '    ')}\n\ndef g():\n{body}\n"
    # f: the def line and 5 body lines = 6 lines; g: 6 lines
    assert long_functions(src, 5) == [("A.f", 6), ("g", 6)]
    assert long_functions(src, 6) == []


@pytest.mark.parametrize("path", CHECKED)
def test_no_function_over_the_limit(path):
    assert long_functions((ROOT / path).read_text(encoding="utf-8")) == []


def test_every_package_directory_has_an_init():
    """setuptools' ``packages.find`` (pyproject) ships regular packages only: a directory of
    modules without ``__init__.py`` works in an editable install and is missing from a wheel
    (companion/flight was such a directory)."""
    missing = [str(d.relative_to(ROOT)) for top in ("companion", "sitl", "mavcore")
               for d in [ROOT / top, *(ROOT / top).rglob("*")]
               if d.is_dir() and d.name != "__pycache__" and any(d.glob("*.py")) and not (d / "__init__.py").exists()]
    assert missing == []


# --- the two former god objects stay split (issue 17, deliverable 5; BENCHMARKS "h17-split") ---------------

#: Methods (``def`` in the class body, properties included) each class may have. The limits are the counts
#: after the split, so that a new duty has to go where it belongs instead of regrowing the class:
#: ``SitlServer`` (94 methods when issue 17 was filed, 41 before the split) keeps its lifecycle and the parts'
#: wiring (12), handing the frame's telemetry to the links (3; which streams are due and their messages are
#: ``mavcore.services.telemetry.TelemetryServer``'s, h17-fin), pacing (2), lockstep (5), reading, checking and
#: dispatching input (12) and TIMESYNC/PING (2): a new protocol is a part in ``sitl/`` (its ``handlers()``), a
#: new vehicle behaviour goes in ``sitl/vehicle.py`` or the simulation. ``FlightCore`` (64 before the split)
#: keeps the runner's face (10), the procedure's plumbing and its clients (12), the procedure (13), the
#: per-frame step with its reference, replanning and guard (13): a new message handler goes in
#: ``companion/flight/inbox.py``, a new figure of the report in ``companion/flight/reporting.py``.
METHOD_LIMITS = {("sitl/server.py", "SitlServer"): 36, ("companion/flight/core.py", "FlightCore"): 48}


def class_methods(source: str, name: str) -> list:
    """Names of the methods defined in the body of class ``name`` of ``source``."""
    for node in ast.parse(source).body:
        if isinstance(node, ast.ClassDef) and node.name == name:
            return [c.name for c in node.body if isinstance(c, (ast.FunctionDef, ast.AsyncFunctionDef))]
    raise LookupError(name)


def self_attributes(source: str, name: str) -> set:
    """Attribute names class ``name`` of ``source`` assigns on ``self`` (``self.x = ...``, ``self.x: T = ...``)."""
    cls = next(n for n in ast.parse(source).body if isinstance(n, ast.ClassDef) and n.name == name)
    out = set()
    for node in ast.walk(cls):
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, (ast.AnnAssign, ast.AugAssign)) else []
        for t in targets:
            for e in ast.walk(t):
                if isinstance(e, ast.Attribute) and isinstance(e.value, ast.Name) and e.value.id == "self":
                    out.add(e.attr)
    return out


def test_class_helpers_count_methods_and_self_attributes():
    src = ("class A:\n    def f(self):\n        self.x = 1\n        self.y: int = 2\n        self.z += 1\n"
           "        self.p, self.q = 3, 4\n        other.w = 5\n    @property\n    def g(self):\n        return 1\n"
           "class B:\n    def h(self):\n        self.v = 0\n")
    assert class_methods(src, "A") == ["f", "g"]
    assert self_attributes(src, "A") == {"x", "y", "z", "p", "q"}
    with pytest.raises(LookupError):
        class_methods(src, "C")


@pytest.mark.parametrize("path,name", sorted(METHOD_LIMITS))
def test_former_god_objects_do_not_regrow(path, name):
    methods = class_methods((ROOT / path).read_text(encoding="utf-8"), name)
    assert len(methods) <= METHOD_LIMITS[(path, name)], methods


def test_sitl_server_holds_no_vehicle_state():
    """The simulation, flight stack, parameters, battery and collision prevention are the
    ``Vehicle``'s: the server reaches them through ``self.vehicle`` only."""
    from mavcore.mission import load_mission
    from mavcore.services.params import Parameters
    from sitl.battery import Battery
    from sitl.collision_prevention import CollisionPrevention
    from sitl.flightstack import FlightStack
    from sitl.server import SitlServer
    from sitl.sim import Simulation
    from sitl.vehicle import Vehicle

    srv = SitlServer(load_mission(ROOT / "missions/flat-rectangle/mission.yaml"))   # no I/O
    assert isinstance(srv.vehicle, Vehicle)
    vehicle_state = (Simulation, FlightStack, Parameters, Battery, CollisionPrevention)
    held = {k: type(v).__name__ for k, v in vars(srv).items() if isinstance(v, vehicle_state)}
    assert held == {}
    v = srv.vehicle
    assert all(isinstance(x, t) for x, t in zip((v.sim, v.stack, v.params, v.battery, v.collision_prevention),
                                                 vehicle_state))


def test_sitl_server_only_hands_telemetry_to_its_links():
    """Which stream is due at which vehicle time and building its messages are the telemetry
    service's (``mavcore.services.telemetry``, ``sitl.telemetry``): the server touches neither
    the schedule's due times nor an encoder; it sends the list ``TelemetryServer`` builds."""
    tree = ast.parse((ROOT / "sitl/server.py").read_text(encoding="utf-8"))
    used = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)}
    scheduling = {"due", "due_min", "every_frame", "enabled", "next_due", "encoders", "fast", "frame_imu_args",
                  "frame_imu_pack", "last_ranges", "ranges_off", "distance_sensor_args"}
    assert used & scheduling == set()
    assert {"frame", "whole_frame"} <= used


def test_flight_core_keeps_no_message_handler_or_report():
    """The per-message updates are ``VehicleView``'s (companion/flight/inbox.py) and the
    measurements and report ``FlightRecorder``'s (reporting.py): the core defines no
    handler but the procedure's two hooks and none of their state."""
    core_src = (ROOT / "companion/flight/core.py").read_text(encoding="utf-8")
    methods = class_methods(core_src, "FlightCore")
    assert sorted(m for m in methods if m.startswith("_on_")) == ["_on_imu", "_on_service_msg"]
    assert not {"report", "coverage_flown", "_record", "_replanning_stats"} & set(methods)
    # collaborators handed to the view and the recorder, not state of their own
    shared = {"tc", "monitor", "react", "phase", "emit", "enc", "on_frame", "on_service", "replanner", "inputs",
              "view", "phase_code", "flying"}
    view = self_attributes((ROOT / "companion/flight/inbox.py").read_text(encoding="utf-8"), "VehicleView")
    recorder = self_attributes((ROOT / "companion/flight/reporting.py").read_text(encoding="utf-8"),
                               "FlightRecorder")
    assert {"pos", "t_s", "armed", "truth"} <= view and {"log", "errors", "min_clearance"} <= recorder
    assert self_attributes(core_src, "FlightCore") & ((view | recorder) - shared) == set()


def redefined(source: str) -> list:
    """(scope, name, first line, second line) of every function a class body or the module
    defines twice: the second binding replaces the first, which is then dead code that
    still reads as if it ran (property setters and ``typing.overload`` stubs excepted)."""
    out = []

    def scan(body, scope):
        seen = {}
        for node in body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                decos = [ast.unparse(d) for d in node.decorator_list]
                if any(d.endswith((".setter", ".deleter")) or d.endswith("overload") for d in decos):
                    continue
                if node.name in seen:
                    out.append((scope, node.name, seen[node.name], node.lineno))
                seen[node.name] = node.lineno
            elif isinstance(node, ast.ClassDef):
                scan(node.body, node.name)

    scan(ast.parse(source).body, "<module>")
    return out


def test_redefined_finds_a_method_defined_twice():
    src = "class A:\n    def f(self):\n        return 1\n\n    def f(self):\n        return 2\n"
    assert redefined(src) == [("A", "f", 2, 5)]
    prop = ("class B:\n    @property\n    def x(self):\n        return 1\n\n"
            "    @x.setter\n    def x(self, v):\n        pass\n")
    assert redefined(prop) == []


@pytest.mark.parametrize("package", ["companion", "mavcore", "sitl"])
def test_no_function_is_defined_twice_in_one_scope(package):
    """Replanner had two ``_calm`` methods 338 lines apart: the emergency brake's exit read
    as "within the normal limits" and ran the rejoin's "within half of them"."""
    found = [(str(p.relative_to(ROOT)),) + r for p in sorted((ROOT / package).rglob("*.py"))
             for r in redefined(p.read_text())]
    assert found == []
