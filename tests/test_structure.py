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
