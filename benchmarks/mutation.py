"""Mutation testing of the safety modules (issue 19, deliverable 6).

A small AST mutation tool, written here rather than mutmut 3 because mutmut 3
mutates only function bodies (its trampolines), so module constants and
dataclass defaults - ``RTL_ACCEPT_RADIUS_M``, ``MonitorConfig.max_nav_age_s``,
the two mutants the audit found surviving - would never be generated; and
because each module must be tested by its own fast unit tests only (the
machine is small and shared).

Operators (each mutant is one change):

``cmp``    a comparison operator flipped: ``<`` -> ``<=`` and ``>=``, ``>`` -> ``>=``
           and ``<=``, ``==`` <-> ``!=``, ``is`` <-> ``is not``, ``in`` <-> ``not in``;
``num``    a float constant x100 and /100 (0.0 -> 1.0), an int constant +1 and -1
           (0 -> 1);
``bool``   ``not x`` -> ``x``, ``and`` <-> ``or``, ``True`` <-> ``False``;
``arith``  ``+`` <-> ``-``, ``*`` <-> ``/`` (also in ``+=``/``-=``), unary minus dropped;
``stmt``   an assignment, expression statement, ``raise``, ``del`` or ``return x``
           removed (``pass`` / ``return None``);
``audit``  the two mutants issue 19's audit found surviving (``AUDIT``).

Strings, f-strings, docstrings, annotations and imports are not mutated.

How a mutant is run: the parent process imports the third-party libraries
once, then forks one child per mutant; the child installs an import hook that
serves the mutated source for the target module (the working tree is never
written) and runs ``pytest -x -q -p no:cacheprovider -m "not slow"`` on the
module's test selection. A non-zero exit, or a timeout, kills the mutant.

Usage::

    python benchmarks/mutation.py                    # all five modules
    python benchmarks/mutation.py --only monitor     # one of them
    python benchmarks/mutation.py --list             # the mutants, not run
    python benchmarks/mutation.py --json out.json

Equivalent mutants (no behavioural change possible) are listed in
``EQUIVALENT`` below with the reason; the score is given both over all
mutants and over the non-equivalent ones.
"""

from __future__ import annotations

import argparse
import ast
import copy
import importlib.abc
import importlib.util
import json
import os
import signal
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_FS_FAILSAFE = ("RTL_ACCEPT_RADIUS_M", "ARM_MAX_TILT_RAD", "PARAM_SPECS[COM_*].default",
                "FlightStack.system_status", "FlightStack._limits", "FlightStack.offboard_fresh",
                "FlightStack.actuators_fresh", "FlightStack.crash", "FlightStack.arm",
                "FlightStack._prearm_failure", "FlightStack.disarm", "FlightStack.update",
                "FlightStack._rtl_setpoint")


@dataclass(frozen=True)
class Target:
    name: str
    path: str                    # relative to the repository root
    tests: tuple[str, ...]       # pytest arguments (files, -k selections)
    scope: tuple[str, ...] | None = None   # qualified names to mutate (None: the whole module)


TARGETS = (
    Target("monitor", "companion/flight/monitor.py",
           ("tests/test_flight_monitor.py", "tests/test_flight_units.py", "-k", "monitor")),
    Target("health", "companion/flight/health.py",
           ("tests/test_flight_health.py", "tests/test_flight_units.py", "-k", "health")),
    Target("flightstack", "sitl/flightstack.py",
           ("tests/test_sitl_flightstack.py", "tests/test_sitl_failsafes.py"), _FS_FAILSAFE),
    Target("link_auth", "companion/link/auth.py", ("tests/test_link_auth_rules.py", "tests/test_link_auth.py")),
    Target("sitl_auth", "sitl/auth.py", ("tests/test_sitl_auth_rules.py", "tests/test_sitl_auth.py")),
)

#: Mutant id -> why it cannot change behaviour. Ids are printed by --list.
EQUIVALENT: dict[str, str] = {
    "monitor:FlightMonitor.on_heartbeat:stmt:self._emergency_seen = True -> pass":
        "the flag is set only as the emergency becomes the first violation; a later EMERGENCY reaches "
        "_violate, which returns None once `first` is set, so nothing observable depends on it",
    "monitor:FlightMonitor.on_heartbeat:bool:True -> False": "same as the line above (the flag never set)",
    "health:LinkHealth.observe:arith:self._n += 1 -> self._n -= 1":
        "_n is only used as `_n % 25`, which is zero for -n exactly when for n",
    "health:LinkHealth.observe:num:1 -> (2) #1":
        "_n is only used as `_n % 25`; 2k is a multiple of 25 exactly when k is (gcd(2, 25) = 1)",
    "flightstack:FlightStack._limits:stmt:self._params_version = p.version -> pass":
        "a cache key only: without it the limits are recomputed from the same parameters on every call",
    "flightstack:FlightStack.arm:stmt:self._armed_t_us = int(now_us) -> pass":
        "_armed_t_us is written, never read (a dead store)",
    "flightstack:FlightStack.arm:stmt:self._land_announced = False -> pass":
        "arm calls _enter two lines later, which resets _land_announced too",
    "flightstack:FlightStack.arm:bool:False -> True #1": "same as the line above (_enter resets it)",
    "flightstack:FlightStack.arm:bool:False -> True #2":
        "_enter(self.mode, announce=True) announces only a mode change, and arming keeps the mode",
    "flightstack:FlightStack._prearm_failure:stmt:return \"\" -> return None":
        "the only caller tests the reason's truth value; '' and None are both false",
    "flightstack:FlightStack.update:stmt:self._now_us = now_us -> pass":
        "_now_us is written, never read (a dead store)",
    "flightstack:FlightStack.update:stmt:now_us = int(now_us) -> pass":
        "every caller (sitl.server, the tests) passes integer microseconds: int() is the identity there",
    "flightstack:FlightStack.update:bool:True -> False":
        "disarm(force=False) of a crashed vehicle is accepted too (crash_event set), with the same "
        "'Disarmed (crashed)' text (the reason wins over 'forced')",
    "flightstack:FlightStack.update:cmp:o.idle is idle -> (o.idle is not idle)":
        "reuse test of the last output: flipped, an equal StackOutput is built anew (a tick never changes "
        "idle while keeping the same setpoint object), so the outputs are equal",
    "flightstack:FlightStack.update:cmp:o.motor_override is None -> (o.motor_override is not None)":
        "reuse test of the last output: the override's last output is never reused after the hand-back "
        "(that tick has reset_controller set), otherwise an equal StackOutput is built anew",
    "link_auth:VehicleFilter.accept:stmt:return False -> return None":
        "accept's callers (filter, the runner) use its truth value only; None and False are both false",
    "link_auth:VehicleFilter.accept:stmt:return False -> return None #2": "as above",
    "link_auth:VehicleFilter.accept:stmt:return False -> return None #3": "as above",
    "link_auth:VehicleFilter._time_ok:stmt:return False -> return None":
        "its one caller tests `not self._time_ok(...)`; None and False are both false",
    "link_auth:VehicleFilter.__init__:stmt:self._cand_n = 0 -> pass":
        "_cand_n is assigned (= 1) before it is ever read: the first jumped frame has no candidate",
    "link_auth:VehicleFilter.__init__:num:0 -> (1) #1": "as above",
    "link_auth:VehicleFilter._time_ok:cmp:t_s > clock -> (t_s >= clock)":
        "at t_s == clock the clock is assigned its own value",
    "link_auth:VehicleFilter._time_ok:num:0 -> (1)":
        "_cand_s is set to None with it, and a None candidate sets the count to 1 at the next jumped frame",
    "link_auth:VehicleFilter._time_ok:stmt:self._cand_s, self._cand_n = None, 0 -> pass #1":
        "after re-anchoring, the candidate equals the clock: a later frame within its tolerance is "
        "accepted by the first branch, any other one restarts the count at 1",
    "link_auth:VehicleFilter._time_ok:num:0 -> (1) #1": "as above (the count is restarted at 1 anyway)",
    "flightstack:FlightStack._rtl_setpoint:num:1 -> (2)":
        "the return phase is only ever compared with 0; any non-zero value means 'flying home'",
    "flightstack:FlightStack.update:stmt:self._override_active = False -> pass":
        "disarm(), the only place that clears `armed`, clears the override with it",
}


#: Hand-written mutants (op ``audit``): the ones issue 19's audit found surviving the whole
#: non-slow suite, where the operators above do not produce them verbatim.
AUDIT: tuple[tuple[str, str, str], ...] = (
    ("monitor", "if age > self.cfg.max_nav_age_s:", "if age > self.cfg.max_nav_age_s * 100:"),
    ("flightstack", "RTL_ACCEPT_RADIUS_M = 0.5", "RTL_ACCEPT_RADIUS_M = 50.0"),
)


# ----------------------------------------------------------------------------- generation
@dataclass
class Mutant:
    target: str
    qualname: str
    op: str
    line: int
    orig: str
    new: str
    source: str = field(repr=False)
    id: str = ""


_CMP_FLIPS = {ast.Lt: (ast.LtE, ast.GtE), ast.LtE: (ast.Lt, ast.Gt), ast.Gt: (ast.GtE, ast.LtE),
              ast.GtE: (ast.Gt, ast.Lt), ast.Eq: (ast.NotEq,), ast.NotEq: (ast.Eq,),
              ast.Is: (ast.IsNot,), ast.IsNot: (ast.Is,), ast.In: (ast.NotIn,), ast.NotIn: (ast.In,)}
_ARITH = {ast.Add: ast.Sub, ast.Sub: ast.Add, ast.Mult: ast.Div, ast.Div: ast.Mult}


def _num_variants(v):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return ()
    if isinstance(v, float):
        return (1.0,) if v == 0.0 else (v * 100.0, v / 100.0)
    return (1,) if v == 0 else (v + 1, v - 1)


class _Collector(ast.NodeVisitor):
    """Walks the module and records (node, qualname, op, replacement node) candidates."""

    def __init__(self, scope) -> None:
        self.scope = scope
        self.stack: list[str] = []
        self.out: list[tuple] = []
        self.in_scope_depth = 0

    # --- scope bookkeeping
    def _qual(self) -> str:
        return ".".join(self.stack) or "<module>"

    def _enter(self, name, node):
        self.stack.append(name)
        q = self._qual()
        inside = self.scope is None or any(q == s or q.startswith(s + ".") for s in self.scope)
        self.in_scope_depth += inside
        self._body(node)
        self.in_scope_depth -= inside
        self.stack.pop()

    def _active(self) -> bool:
        return self.scope is None or self.in_scope_depth > 0

    def _body(self, node):
        body = list(getattr(node, "body", []))
        if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                and isinstance(body[0].value.value, str):
            body = body[1:]      # docstring
        for st in body:
            self.visit(st)
        for extra in ("orelse", "finalbody", "handlers"):
            for st in getattr(node, extra, []) or []:
                self.visit(st)

    def visit_Module(self, node):
        self._body(node)

    def visit_ClassDef(self, node):
        self._enter(node.name, node)

    def visit_FunctionDef(self, node):
        # default values belong to the function's scope
        self.stack.append(node.name)
        q = self._qual()
        inside = self.scope is None or any(q == s or q.startswith(s + ".") for s in self.scope)
        self.in_scope_depth += inside
        for d in list(node.args.defaults) + [d for d in node.args.kw_defaults if d is not None]:
            self._expr(d)
        self.stack.pop()
        self.in_scope_depth -= inside
        self._enter(node.name, node)

    visit_AsyncFunctionDef = visit_FunctionDef

    def visit_Import(self, node):
        pass

    visit_ImportFrom = visit_Import

    # --- statements
    def _stmt_removal(self, node, replacement: str):
        if self._active():
            self.out.append((node, self._qual(), "stmt", replacement))

    def visit_Assign(self, node):
        names = [t.id for t in node.targets if isinstance(t, ast.Name)]
        if not self.stack and self.scope is not None:
            # module level: only the selected constants (and the PARAM_SPECS defaults)
            for n in names:
                if n in self.scope:
                    self.in_scope_depth += 1
                    self._expr(node.value)
                    self.in_scope_depth -= 1
                if n == "PARAM_SPECS" and "PARAM_SPECS[COM_*].default" in self.scope:
                    for call in node.value.elts:
                        if call.args and isinstance(call.args[0], ast.Constant) \
                                and str(call.args[0].value).startswith("COM_"):
                            self.stack.append(f"PARAM_SPECS[{call.args[0].value}]")
                            self.in_scope_depth += 1
                            self._expr(call.args[2])
                            self.in_scope_depth -= 1
                            self.stack.pop()
            return
        if self.stack:
            self._stmt_removal(node, "pass")
        self._expr(node.value)

    def visit_AnnAssign(self, node):
        if node.value is None:
            return
        if not self.stack and self.scope is not None and isinstance(node.target, ast.Name):
            self.visit_Assign(ast.Assign(targets=[node.target], value=node.value))
            return
        self._expr(node.value)

    def visit_AugAssign(self, node):
        self._stmt_removal(node, "pass")
        if type(node.op) in _ARITH and self._active():
            new = copy.deepcopy(node)
            new.op = _ARITH[type(node.op)]()
            self.out.append((node, self._qual(), "arith", ast.unparse(new)))
        self._expr(node.value)

    def visit_Expr(self, node):
        if isinstance(node.value, ast.Constant):
            return
        self._stmt_removal(node, "pass")
        self._expr(node.value)

    def visit_Return(self, node):
        if node.value is not None and not (isinstance(node.value, ast.Constant) and node.value.value is None):
            self._stmt_removal(node, "return None")
            self._expr(node.value)

    def visit_Raise(self, node):
        self._stmt_removal(node, "pass")

    def visit_Delete(self, node):
        self._stmt_removal(node, "pass")

    def visit_If(self, node):
        self._expr(node.test)
        self._body(node)

    def visit_While(self, node):
        self._expr(node.test)
        self._body(node)

    def visit_For(self, node):
        self._expr(node.iter)
        self._body(node)

    def visit_With(self, node):
        self._body(node)

    def visit_Try(self, node):
        self._body(node)

    def visit_ExceptHandler(self, node):
        self._body(node)

    # --- expressions
    def _expr(self, node):
        if node is None or not self._active():
            return
        todo = [node]
        while todo:        # ast.walk, but not into f-strings (their inner positions are not usable)
            sub = todo.pop()
            if isinstance(sub, ast.JoinedStr):
                continue
            self._expr_node(sub)
            todo.extend(ast.iter_child_nodes(sub))

    def _expr_node(self, n):
        q = self._qual()
        if isinstance(n, ast.Compare):
            for i, op in enumerate(n.ops):
                for alt in _CMP_FLIPS.get(type(op), ()):
                    new = copy.deepcopy(n)
                    new.ops[i] = alt()
                    self.out.append((n, q, "cmp", "(" + ast.unparse(new) + ")"))
        elif isinstance(n, ast.Constant):
            if isinstance(n.value, bool):
                self.out.append((n, q, "bool", str(not n.value)))
            for v in _num_variants(n.value):
                self.out.append((n, q, "num", "(" + repr(v) + ")"))
        elif isinstance(n, ast.UnaryOp):
            if isinstance(n.op, ast.Not):
                self.out.append((n, q, "bool", "(" + ast.unparse(n.operand) + ")"))
            elif isinstance(n.op, ast.USub) and not isinstance(n.operand, ast.Constant):
                self.out.append((n, q, "arith", "(" + ast.unparse(n.operand) + ")"))
            elif isinstance(n.op, ast.USub) and isinstance(n.operand, ast.Constant):
                self.out.append((n, q, "arith", "(" + ast.unparse(n.operand) + ")"))
        elif isinstance(n, ast.BoolOp):
            new = copy.deepcopy(n)
            new.op = ast.Or() if isinstance(n.op, ast.And) else ast.And()
            self.out.append((n, q, "bool", "(" + ast.unparse(new) + ")"))
        elif isinstance(n, ast.BinOp) and type(n.op) in _ARITH:
            new = copy.deepcopy(n)
            new.op = _ARITH[type(n.op)]()
            self.out.append((n, q, "arith", "(" + ast.unparse(new) + ")"))

    def generic_visit(self, node):   # other statements: nothing to mutate
        pass


def _class_aware(tree):
    """Mark assignments directly in a class body (those are fields, not removable statements)."""
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef):
            for st in node.body:
                st._in_class = True


def mutants_of(target: Target) -> list[Mutant]:
    path = ROOT / target.path
    src = path.read_text()
    data = src.encode()
    lines = data.splitlines(keepends=True)
    offsets = [0]
    for ln in lines:
        offsets.append(offsets[-1] + len(ln))
    tree = ast.parse(src)
    _class_aware(tree)
    col = _Collector(target.scope)
    orig_visit_assign = col.visit_Assign

    def visit_assign(node):
        if getattr(node, "_in_class", False):
            col._expr(node.value)
            return
        orig_visit_assign(node)

    col.visit_Assign = visit_assign
    col.visit(tree)
    base_dump = ast.dump(tree)
    out: list[Mutant] = []
    seen: dict[tuple, int] = {}
    for node, qual, op, repl in col.out:
        a = offsets[node.lineno - 1] + node.col_offset
        b = offsets[node.end_lineno - 1] + node.end_col_offset
        orig = data[a:b].decode()
        new_src = (data[:a] + repl.encode() + data[b:]).decode()
        try:
            new_tree = ast.parse(new_src)
        except SyntaxError:
            continue
        if ast.dump(new_tree) == base_dump:
            continue
        key = (qual, op, " ".join(orig.split()), repl)
        k = seen.get(key, 0)
        seen[key] = k + 1
        mid = f"{target.name}:{qual}:{op}:{' '.join(orig.split())} -> {repl}" + (f" #{k}" if k else "")
        out.append(Mutant(target.name, qual, op, node.lineno, " ".join(orig.split()), repl, new_src, mid))
    for name, old, new in AUDIT:
        if name == target.name:
            assert src.count(old) == 1, f"audit mutant not found once in {target.path}: {old!r}"
            line = src[:src.index(old)].count("\n") + 1
            out.append(Mutant(name, "audit", "audit", line, old, new, src.replace(old, new),
                              f"{name}:audit:{old} -> {new}"))
    return out


# ----------------------------------------------------------------------------- running
class _Hook(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def __init__(self, modname: str, path: str, source: str) -> None:
        self.modname, self.path, self.source = modname, path, source

    def find_spec(self, fullname, path=None, target=None):
        if fullname != self.modname:
            return None
        return importlib.util.spec_from_file_location(fullname, self.path, loader=self)

    def create_module(self, spec):
        return None

    def exec_module(self, module):
        exec(compile(self.source, self.path, "exec"), module.__dict__)


def _install(target: Target, source: str) -> None:
    """Make ``source`` the target module's code in this (child) process.

    Not imported yet: an import hook serves it. Already imported by the parent
    (the fast path): it is executed again in the module's own namespace, and
    every other project module's global that was bound to one of the module's
    old objects by name (``from .flightstack import FlightStack``) is rebound to
    the new one. ``main`` runs the unmutated source through the same path first
    and requires its tests to pass, which checks this patching.
    """
    modname = target.path[:-3].replace("/", ".")
    path = str(ROOT / target.path)
    mod = sys.modules.get(modname)
    if mod is None:
        sys.meta_path.insert(0, _Hook(modname, path, source))
        return
    old = dict(mod.__dict__)
    exec(compile(source, path, "exec"), mod.__dict__)
    new = mod.__dict__
    changed = [(k, v) for k, v in old.items() if not k.startswith("__") and new.get(k) is not v]
    for name, m in list(sys.modules.items()):
        if m is mod or name.split(".")[0] not in _PROJECT:
            continue
        d = getattr(m, "__dict__", None)
        if d is None:
            continue
        for k, v in changed:
            if d.get(k, _MISSING) is v:
                d[k] = new[k]


_MISSING = object()


def _start_child(target: Target, source: str) -> int:
    """Fork a child that runs the target's tests against ``source``; its pid."""
    pid = os.fork()
    if pid == 0:   # child
        try:
            fd = os.open(os.devnull, os.O_WRONLY)
            os.dup2(fd, 1)
            os.dup2(fd, 2)
            _install(target, source)
            import pytest
            os.chdir(ROOT)
            tests = [a for a in target.tests if not a.endswith(".py") or (ROOT / a).exists()]
            rc = pytest.main(["-x", "-q", "-p", "no:cacheprovider", "-m", "not slow", *tests])
            os._exit(int(rc))
        except BaseException:
            os._exit(99)
    return pid


def _run_all(target: Target, sources: list[str], timeout_s: float, jobs: int, done=None) -> list[tuple[int, float]]:
    """Run every source (at most ``jobs`` children at once); [(exit code, seconds)] in order.
    A child past ``timeout_s`` is killed (exit -9: the mutant made the tests hang)."""
    results: list = [None] * len(sources)
    running: dict[int, tuple[int, float]] = {}
    nxt = 0
    while nxt < len(sources) or running:
        while nxt < len(sources) and len(running) < jobs:
            running[_start_child(target, sources[nxt])] = (nxt, time.monotonic())
            nxt += 1
        time.sleep(0.005)
        for pid, (i, t0) in list(running.items()):
            got, status = os.waitpid(pid, os.WNOHANG)
            if got:
                rc = os.waitstatus_to_exitcode(status)
            elif time.monotonic() - t0 > timeout_s:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                rc = -9
            else:
                continue
            del running[pid]
            results[i] = (rc, time.monotonic() - t0)
            if done is not None:
                done(i, *results[i])
    return results


_PROJECT = ("companion", "sitl", "tests", "conftest")


def _third_party_of(tests) -> list[str]:
    """Names of the non-project modules that importing the test files loads (found in a
    throwaway child, so that the parent can import them once for every mutant)."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            os.close(r)
            sys.path.insert(0, str(ROOT))
            for i, a in enumerate(tests):
                p = ROOT / a
                if a.endswith(".py") and p.exists():
                    spec = importlib.util.spec_from_file_location(f"_mutation_probe_{i}", p)
                    spec.loader.exec_module(importlib.util.module_from_spec(spec))
            names = [m for m in list(sys.modules)
                     if m.split(".")[0] not in ("tests", "conftest") and not m.startswith("_mutation_probe")]
            os.write(w, "\n".join(names).encode())
        finally:
            os._exit(0)
    os.close(w)
    chunks = []
    while True:
        b = os.read(r, 1 << 16)
        if not b:
            break
        chunks.append(b)
    os.close(r)
    os.waitpid(pid, 0)
    return b"".join(chunks).decode().split("\n")


def _preimport(targets) -> None:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ["PYTEST_DISABLE_PLUGIN_AUTOLOAD"] = "1"
    import pytest  # noqa: F401
    sys.path.insert(0, str(ROOT))
    for t in targets:
        for name in _third_party_of(t.tests):
            if name and name not in sys.modules:
                try:
                    importlib.import_module(name)
                except Exception:   # noqa: BLE001 - best effort: the child imports what is missing
                    pass
    leaked = [m for m in sys.modules if m.split(".")[0] in ("tests", "conftest")]
    assert not leaked, f"test modules imported in the parent: {leaked[:5]}"


def _table(rows) -> None:
    print("| module | mutants | killed | survived | equivalent | score | score excl. equivalent |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['path']} | {r['mutants']} | {r['killed']} | {r['survived']} | {r['equivalent']} | "
              f"{r['score']:.1%} | {r['score_excl_equivalent']:.1%} |")


def _score(path: str, results: list[dict]) -> dict:
    n = len(results)
    killed = sum(r["killed"] for r in results)
    eq = [r for r in results if r["id"] in EQUIVALENT]
    eq_killed = sum(r["killed"] for r in eq)
    n_eff = n - len(eq)
    return {"path": path, "mutants": n, "killed": killed, "survived": n - killed, "equivalent": len(eq),
            "score": killed / n if n else 1.0,
            "score_excl_equivalent": (killed - eq_killed) / n_eff if n_eff else 1.0}


def _rescore(data: dict) -> int:
    by_path: dict[str, list] = {}
    for r in data["mutants"]:
        by_path.setdefault(r["path"], []).append(r)
    _table([_score(p, rs) for p, rs in by_path.items()])
    for r in data["mutants"]:
        if not r["killed"]:
            eq = EQUIVALENT.get(r["id"])
            print(f"{'equivalent' if eq else 'SURVIVED  '} {r['path']}:{r['line']} {r['id']}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", action="append", choices=[t.name for t in TARGETS])
    ap.add_argument("--list", action="store_true", help="print the mutants and exit")
    ap.add_argument("--json", type=Path, help="write every mutant's result here")
    ap.add_argument("--verbose", action="store_true", help="print each mutant as it finishes")
    ap.add_argument("-j", "--jobs", type=int, default=2, help="mutants run at once (default 2)")
    ap.add_argument("--ids", type=Path, metavar="FILE",
                    help="run only the mutants whose ids are listed in FILE (one a line), e.g. the "
                         "survivors of an earlier run: tests are only ever added, so a mutant killed "
                         "then is killed now")
    ap.add_argument("--rescore", type=Path, metavar="JSON",
                    help="print the table of an earlier --json run, with the current EQUIVALENT list")
    args = ap.parse_args(argv)
    if args.rescore:
        return _rescore(json.loads(args.rescore.read_text()))
    targets = [t for t in TARGETS if not args.only or t.name in args.only]
    all_mutants = {t.name: mutants_of(t) for t in targets}
    if args.ids:
        wanted = {ln.strip() for ln in args.ids.read_text().splitlines() if ln.strip()}
        all_mutants = {k: [m for m in v if m.id in wanted] for k, v in all_mutants.items()}
    if args.list:
        for t in targets:
            for m in all_mutants[t.name]:
                print(f"{t.path}:{m.line}  {m.id}")
        return 0
    _preimport(targets)
    results = []
    summary = []
    for t in targets:
        base_src = (ROOT / t.path).read_text()
        [(rc, base_s)] = _run_all(t, [base_src], 600.0, 1)
        if rc != 0:
            print(f"{t.name}: the unmutated tests fail (exit {rc}); fix them first", file=sys.stderr)
            return 1
        timeout = max(30.0, 10.0 * base_s)
        ms = all_mutants[t.name]
        t0 = time.monotonic()

        def report(i, rc, s, ms=ms, t=t):
            m = ms[i]
            if args.verbose or rc == 0:
                eq = EQUIVALENT.get(m.id)
                print(f"{'killed  ' if rc else 'SURVIVED'} {t.path}:{m.line} {m.id}"
                      + (f"  [equivalent: {eq}]" if eq and rc == 0 else ""), flush=True)

        runs = _run_all(t, [m.source for m in ms], timeout, args.jobs, report)
        killed = survived = equiv_survived = equiv_killed = 0
        for m, (rc, s) in zip(ms, runs):
            dead = rc != 0
            eq = m.id in EQUIVALENT
            killed += dead
            survived += not dead
            equiv_survived += eq and not dead
            equiv_killed += eq and dead
            results.append({"target": t.name, "path": t.path, "line": m.line, "id": m.id, "op": m.op,
                            "orig": m.orig, "new": m.new, "exit": rc, "seconds": round(s, 2), "killed": dead,
                            "equivalent": EQUIVALENT.get(m.id)})
        n = len(ms)
        n_eff = n - equiv_survived - equiv_killed
        row = {"target": t.name, "path": t.path, "mutants": n, "killed": killed, "survived": survived,
               "equivalent": equiv_survived + equiv_killed,
               "score": killed / n if n else 1.0,
               "score_excl_equivalent": (killed - equiv_killed) / n_eff if n_eff else 1.0,
               "seconds": round(time.monotonic() - t0, 1), "baseline_test_s": round(base_s, 2)}
        summary.append(row)
        print(f"== {t.name}: {killed}/{n} killed ({row['score']:.1%}); "
              f"excluding {row['equivalent']} equivalent: {row['score_excl_equivalent']:.1%}; "
              f"{row['seconds']} s", flush=True)
    print()
    _table(summary)
    if args.json:
        args.json.write_text(json.dumps({"summary": summary, "mutants": results}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
