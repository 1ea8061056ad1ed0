#!/usr/bin/env python3
"""Compare plan.json files key by key: every key but ``timings_s`` must be equal.

Usage::

    python benchmarks/compare_plans.py BEFORE.json AFTER.json [BEFORE2.json AFTER2.json ...]

Floats must be equal (``--rel-tol`` allows a relative tolerance, for an
algorithm change that alters float rounding; integers, strings, booleans and
list lengths must still match exactly). Prints the first differences of
each pair and exits 1 if any pair differs, 2 on a missing or unreadable file.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

IGNORED = {"timings_s"}


def differences(a, b, path: str = "", rel_tol: float = 0.0, limit: int = 10) -> list[str]:
    """Paths (and values) where the JSON values ``a`` and ``b`` differ, at most ``limit``."""
    out: list[str] = []

    def walk(x, y, p):
        if len(out) >= limit:
            return
        if isinstance(x, dict) and isinstance(y, dict):
            for k in sorted(set(x) | set(y)):
                if p == "" and k in IGNORED:
                    continue
                if k not in x or k not in y:
                    out.append(f"{p}/{k}: only in {'after' if k not in x else 'before'}")
                else:
                    walk(x[k], y[k], f"{p}/{k}")
        elif isinstance(x, list) and isinstance(y, list):
            if len(x) != len(y):
                out.append(f"{p}: length {len(x)} != {len(y)}")
                return
            for i, (u, v) in enumerate(zip(x, y)):
                walk(u, v, f"{p}[{i}]")
        elif isinstance(x, float) and isinstance(y, float) and rel_tol > 0:
            if not math.isclose(x, y, rel_tol=rel_tol, abs_tol=rel_tol):
                out.append(f"{p}: {x!r} != {y!r}")
        elif type(x) is not type(y) or x != y:
            out.append(f"{p}: {x!r} != {y!r}")

    walk(a, b, path)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+", help="pairs of plan.json files: before after ...")
    ap.add_argument("--rel-tol", type=float, default=0.0)
    args = ap.parse_args(argv)
    if len(args.files) % 2:
        print("compare_plans: give the files in pairs (before after)", file=sys.stderr)
        return 2
    bad = 0
    for before, after in zip(args.files[0::2], args.files[1::2]):
        try:
            with open(before, "rb") as fa, open(after, "rb") as fb:
                a, b = json.load(fa), json.load(fb)
        except (OSError, ValueError) as e:
            print(f"compare_plans: {e}", file=sys.stderr)
            return 2
        diff = differences(a, b, rel_tol=args.rel_tol)
        print(f"{'same' if not diff else 'DIFFERENT'}: {before} {after}")
        for d in diff:
            print(f"  {d}")
        bad += bool(diff)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
