#!/usr/bin/env python3
"""Plan a corpus of adversarial fields end to end and check every plan independently.

Usage::

    python benchmarks/plan_corpus.py [--n 100] [--first 0] [--large] [--csv out.csv]

Each seed's field (``missions/corpus.py``: star-shaped boundaries with
notches, buildings cutting rows, ponds, narrow necks, closed-off pockets,
rows at any angle; 0.1 m cells) is written as a mission into a temporary
directory and planned with ``companion.planner.plan_mission`` (maps ->
coverage -> way-points -> LQR trajectory), as ``companion plan`` does.
For every plan it records:

- failure: any exception (the target is none);
- the independent coverage of the reachable corridors
  (``corpus.check_coverage``: drawn rows, EDT admissibility, label
  reachability, KD-tree distance; target >= 99 %);
- the smallest clearance of the path from a non-free cell centre (must be
  at least the safety margin);
- the planner's wall-clock phases (``Plan.timings_s``; targets: <= 1 s for
  fields up to 1 ha, <= 5 s for the 10 ha irregular field on one core).
  Timings on a loaded machine are not figures: re-time on an idle one.

``--large`` adds the ~10 ha irregular field (``corpus.large_irregular``).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "missions"))

import corpus  # noqa: E402  (missions/corpus.py)

from mavcore.mission import load_mission  # noqa: E402
from companion.planner import plan_mission  # noqa: E402


def run_one(f: corpus.Field, workdir: Path) -> dict:
    mission = load_mission(corpus.write_field(f, workdir / f.name))
    row = {"name": f.name, "kind": f.kind, "area_ha": f.area_m2 / 1e4}
    try:
        plan = plan_mission(mission)
    except Exception as exc:   # the corpus counts every failure, whatever its type
        row.update(failed=f"{type(exc).__name__}: {exc}")
        return row
    check = corpus.check_coverage(f, plan.coverage.path_xy_m)
    row.update(failed="", coverage=check.fraction, reachable=check.reachable_samples,
               corridor=check.corridor_samples, planner_coverage=plan.stats.coverage_fraction,
               clearance_m=corpus.path_clearance_m(plan.grid, np.asarray(plan.coverage.path_xy_m), f.resolution_m / 4),
               margin_m=f.safety_margin_m, dropped=len(plan.coverage.dropped_segments),
               t_total=plan.timings_s.total, t_coverage=plan.timings_s.coverage,
               n_waypoints=plan.stats.n_waypoints)
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100, help="number of seeds (default 100)")
    ap.add_argument("--first", type=int, default=0, help="first seed (default 0)")
    ap.add_argument("--large", action="store_true", help="also the ~10 ha irregular field")
    ap.add_argument("--csv", help="write one line per field")
    args = ap.parse_args(argv)
    fields = [corpus.draw_field(s) for s in range(args.first, args.first + args.n)]
    if args.large:
        fields.append(corpus.large_irregular(10.0))
    rows = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="plan-corpus-") as tmp:
        for f in fields:
            row = run_one(f, Path(tmp))
            rows.append(row)
            if row["failed"]:
                print(f"{row['name']:<14}{row['kind']:<10} FAILED {row['failed']}")
            else:
                flag = "" if row["coverage"] >= 0.99 and row["clearance_m"] >= row["margin_m"] - 1e-9 else "  <-- check"
                print(f"{row['name']:<14}{row['kind']:<10}{row['area_ha']:6.2f} ha  coverage {100 * row['coverage']:6.2f} % "
                      f"(planner {100 * row['planner_coverage']:5.1f} %)  clearance {row['clearance_m']:.3f} m  "
                      f"dropped {row['dropped']:2d}  plan {row['t_total']:6.2f} s{flag}")
    ok = [r for r in rows if not r["failed"]]
    failed = len(rows) - len(ok)
    low = [r for r in ok if r["coverage"] < 0.99]
    unsafe = [r for r in ok if r["clearance_m"] < r["margin_m"] - 1e-9]
    small = [r for r in ok if r["area_ha"] <= 1.0]
    print(f"\n{len(rows)} fields, {failed} failed, {len(low)} below 99 % coverage, {len(unsafe)} closer than the margin")
    if ok:
        cov = [r["coverage"] for r in ok]
        print(f"independent coverage of the reachable corridors: min {100 * min(cov):.2f} %, "
              f"median {100 * statistics.median(cov):.2f} %")
    if small:
        ts = [r["t_total"] for r in small]
        print(f"fields <= 1 ha: {len(small)}, plan time max {max(ts):.2f} s, median {statistics.median(ts):.2f} s "
              f"(wall clock on this machine; re-time idle)")
    big = [r for r in ok if r["area_ha"] > 5.0]
    for r in big:
        print(f"{r['name']}: {r['area_ha']:.2f} ha, plan {r['t_total']:.2f} s (coverage {r['t_coverage']:.2f} s), "
              f"{r['n_waypoints']} way-points")
    print(f"corpus wall time {time.perf_counter() - t0:.0f} s")
    if args.csv:
        keys = sorted({k for r in rows for k in r})
        with open(args.csv, "w", encoding="utf-8") as fh:
            fh.write(",".join(keys) + "\n")
            for r in rows:
                fh.write(",".join(str(r.get(k, "")).replace(",", ";") for k in keys) + "\n")
    return 1 if failed or low or unsafe else 0


if __name__ == "__main__":
    sys.exit(main())
