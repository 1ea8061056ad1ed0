"""Micro-benchmarks run in a fresh process per source tree, interleaved (shared by
``bench_speed3_parts.py`` and ``bench_known_parts.py``).

The calling script re-runs itself with ``--child`` in each tree (``cwd`` and
``PYTHONPATH`` the tree), ``repeat`` times in turn; its child prints one JSON
object of CPU microseconds per call (and optionally a ``checksum`` of the
answers, which must agree between trees). Kept: the minimum per part and tree.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path


def run_trees(script: str | Path, trees: list[Path], repeat: int) -> tuple[dict[str, dict[str, float]], dict]:
    """({part: {tree: min us}}, {checksum: {trees}}) over ``repeat`` interleaved rounds."""
    best: dict[str, dict[str, float]] = {}
    sums: dict[str, set] = {}
    for _ in range(repeat):
        for tree in trees:
            r = subprocess.run([sys.executable, str(Path(script).resolve()), "--child"], cwd=tree, check=True,
                               env=dict(os.environ, PYTHONPATH=str(tree)), capture_output=True, text=True)
            got = json.loads(r.stdout.strip().splitlines()[-1])
            if "checksum" in got:
                sums.setdefault(got.pop("checksum"), set()).add(str(tree))
            for k, v in got.items():
                d = best.setdefault(k, {})
                d[str(tree)] = min(v, d.get(str(tree), float("inf")))
    return best, sums


def print_table(best: dict[str, dict[str, float]], trees: list[Path], digits: int = 1) -> None:
    """The markdown table of ``run_trees``'s minima, one column per tree."""
    print("| part | " + " | ".join(f"{Path(t).name} (us)" for t in map(str, trees)) + " |")
    print("|---|" + "---:|" * len(trees))
    for k, d in best.items():
        print(f"| {k} | " + " | ".join(f"{d[str(t)]:.{digits}f}" for t in trees) + " |")


def main(doc: str, child, script: str | Path, root: Path, digits: int = 1) -> int:
    """The command line of such a script: ``[--tree DIR]... [--repeat N]``; ``--child`` runs
    ``child()`` (this tree's measurements). Prints the table, and whether the trees'
    answers agree when the child reports a checksum (exit 1 if not)."""
    import argparse

    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--tree", action="append", default=None)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child()
    trees = [root] + [Path(t).resolve() for t in (args.tree or [])]
    best, sums = run_trees(script, trees, args.repeat)
    print_table(best, trees, digits)
    if sums:
        print("answers identical on every tree" if len(sums) == 1 else f"ANSWERS DIFFER: {sums}")
    return 0 if len(sums) <= 1 else 1
