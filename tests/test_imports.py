"""The import structure of the three packages (issue 17): ``sitl`` and
``mavcore`` never import ``companion``, ``mavcore`` imports neither of the
others, and the graph of package-level imports has no cycle.

The graph is built statically with ``ast`` from every ``import`` statement,
function-level (lazy) imports included, so a cycle hidden inside a function
counts as one. A package-level node is a first-level subpackage
(``companion.replan``) or a top-level module (``companion.runner``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("companion", "sitl", "mavcore")


def module_name(path: Path, root: Path = ROOT) -> str:
    """Dotted module name of ``path`` (a package's ``__init__.py`` is the package)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _resolve(name: str, modules: set) -> str | None:
    """The longest prefix of ``name`` that is one of ``modules``."""
    parts = name.split(".")
    while parts:
        candidate = ".".join(parts)
        if candidate in modules:
            return candidate
        parts.pop()
    return None


def imported_modules(source: str, module: str, is_package: bool, modules: set) -> set:
    """The modules of ``modules`` that ``source`` (module ``module``) imports,
    at any depth of the file (function-level imports included)."""
    found = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".") if is_package else module.split(".")[:-1]
                base = base[:len(base) - (node.level - 1)]
                origin = ".".join(base + ([node.module] if node.module else []))
            else:
                origin = node.module
            # ``from pkg import sub`` imports the submodule ``pkg.sub``
            targets = [f"{origin}.{a.name}" if f"{origin}.{a.name}" in modules else origin for a in node.names]
        else:
            continue
        for t in targets:
            hit = _resolve(t, modules)
            if hit is not None and hit != module:
                found.add(hit)
    return found


def module_graph(root: Path = ROOT, packages=PACKAGES) -> dict:
    """module -> set of the modules it imports, for every module of ``packages``."""
    paths = {module_name(p, root): p for pkg in packages for p in (root / pkg).rglob("*.py")}
    names = set(paths)
    return {m: imported_modules(p.read_text(encoding="utf-8"), m, p.name == "__init__.py", names)
            for m, p in paths.items()}


def package_node(module: str) -> str:
    """The package-level node of ``module``: its first two dotted parts."""
    return ".".join(module.split(".")[:2])


def package_graph(graph: dict) -> dict:
    """The module graph collapsed onto package-level nodes (self-edges dropped)."""
    out: dict = {}
    for m, deps in graph.items():
        node = package_node(m)
        out.setdefault(node, set())
        out[node] |= {package_node(d) for d in deps if package_node(d) != node}
    return out


def cycles(graph: dict) -> list:
    """The strongly connected components of more than one node (Tarjan), each sorted."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


@pytest.fixture(scope="module")
def graph():
    return module_graph()


# --- the checker itself, on synthetic graphs ----------------------------------


def test_cycles_finds_a_three_node_cycle_and_ignores_a_tail():
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert cycles(g) == [["a", "b", "c"]]


def test_cycles_finds_two_separate_cycles_and_none_in_a_dag():
    assert cycles({"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"c", "a"}}) == [["a", "b"], ["c", "d"]]
    assert cycles({"a": {"b", "c"}, "b": {"c"}, "c": set()}) == []


def test_function_level_and_relative_imports_are_edges(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("from .. import top\n")
    (pkg / "top.py").write_text("def f():\n    from .sub import leaf\n    return leaf\n")
    (pkg / "sub" / "leaf.py").write_text("import os\n")
    g = module_graph(tmp_path, ("pkg",))
    assert g["pkg.top"] == {"pkg.sub.leaf"}          # function-level, relative, names a submodule
    assert g["pkg.sub"] == {"pkg.top"}
    assert cycles(package_graph(g)) == [["pkg.sub", "pkg.top"]]


# --- the project -----------------------------------------------------------------


def test_sitl_and_mavcore_never_import_companion(graph):
    bad = sorted((m, d) for m, deps in graph.items() if m.split(".")[0] in ("sitl", "mavcore")
                 for d in deps if d.split(".")[0] == "companion")
    assert bad == []


def test_mavcore_imports_neither_companion_nor_sitl(graph):
    bad = sorted((m, d) for m, deps in graph.items() if m.split(".")[0] == "mavcore"
                 for d in deps if d.split(".")[0] != "mavcore")
    assert bad == []


def test_no_package_level_import_cycle(graph):
    assert cycles(package_graph(graph)) == []


def relative_imports_beyond_top(source: str, module: str, is_package: bool) -> list:
    """Line numbers of the relative imports of ``source`` that climb above its top-level package
    (``from ..x`` in ``companion/flight_plan.py``: an ImportError only when that line runs)."""
    depth = len(module.split(".")) - (0 if is_package else 1)
    return [n.lineno for n in ast.walk(ast.parse(source))
            if isinstance(n, ast.ImportFrom) and n.level and n.level > depth]


def test_relative_import_beyond_top_is_found():
    src = "from .a import b\n\ndef f():\n    from ..c import d\n"
    assert relative_imports_beyond_top(src, "pkg.mod", False) == [4]
    assert relative_imports_beyond_top(src, "pkg.sub.mod", False) == []


def test_no_relative_import_climbs_out_of_its_package():
    bad = []
    for pkg in PACKAGES:
        for p in (ROOT / pkg).rglob("*.py"):
            lines = relative_imports_beyond_top(p.read_text(encoding="utf-8"), module_name(p), p.name == "__init__.py")
            bad += [f"{p.relative_to(ROOT)}:{k}" for k in lines]
    assert bad == []
