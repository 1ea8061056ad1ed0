"""Falsification: CMA-ES (``cma``) over the spec's continuous dimensions, normalised to
[0, 1], to minimise a figure of the flight, in batches flown in parallel on Dask.

Figures (smaller is worse for the vehicle):

- ``clearance``: the true minimum clearance (report ``replanning.min_clearance_m``);
- ``tracking``: the margin to the tracking bound, ``bound - tracking.max_error_m``.

A flight that crashed or failed scores ``CRASH_SCORE`` (below any real value).
Every point is a scenario (``scenario(spec, fields, 0, unit)``: the discrete
draws, the SITL seed and the control of scenario 0, the continuous ones from
the point) written to ``DIR/search/scenarios/NNNN.yaml``; its row goes to
``DIR/search/results/<hash>.json`` (a rerun with the same spec and seed asks
the same points and re-flies nothing). ``DIR/search/worst.md`` lists the worst
scenarios found with the command that reproduces each.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

#: score of a flight that crashed or failed (m)
CRASH_SCORE = -1.0
#: score of a flight without the figure (no obstacle: nothing to be near) (m)
MISSING_SCORE = 10.0
#: CMA-ES initial step in the unit cube
SIGMA0 = 0.3


def score(row: dict, figure: str, tracking_bound_m: float = 0.1) -> float:
    """The figure to minimise for one flight's row (m)."""
    if row["outcome"] in ("crashed", "failed"):
        return CRASH_SCORE
    if figure == "clearance":
        v = row.get("min_clearance_m")
        return MISSING_SCORE if v is None else float(v)
    v = row.get("tracking_max_error_m")
    return MISSING_SCORE if v is None else float(tracking_bound_m - v)


def run_search(spec, fields, out: Path, args, client=None, fly=None) -> int:
    """The search (``args``: the campaign command's). ``client``: an existing Dask client
    (default: ``make_client(args.scheduler, args.workers)``, closed at the end);
    ``fly``: the flight function (default ``run.fly_scenario``)."""
    import cma

    from mavcore.errors import InputError
    from .results import read_results, write_table
    from .run import CampaignProgress, fly_scenario, make_client, run_flights
    from .scenarios import continuous_dims, scenario, scenario_yaml
    from .summary import reproduce_command, write_summary

    dims = continuous_dims(spec)
    if not dims:
        raise InputError(args.spec, "--search needs at least one continuous dimension ([lo, hi] with lo < hi)")
    sdir = out / "search"
    (sdir / "scenarios").mkdir(parents=True, exist_ok=True)
    done = read_results(sdir / "results")
    t0 = time.monotonic()
    own = client is None
    client = make_client(args.scheduler, args.workers) if own else client
    fly = fly or fly_scenario
    rows: list[dict] = []
    try:
        workers = max(1, sum(client.nthreads().values()))
        popsize = max(4, workers)
        es = cma.CMAEvolutionStrategy(np.full(len(dims), 0.5), SIGMA0,
                                      {"bounds": [0.0, 1.0], "popsize": popsize, "seed": spec.seed + 1,
                                       "verbose": -9})
        progress = CampaignProgress(args.budget, 0, enabled=not args.quiet)
        if not args.quiet:
            print(f"search {spec.name}: minimise {args.search} over {len(dims)} dimensions, budget {args.budget} "
                  f"flights, batches of {popsize}", file=sys.stderr)
        k = 0
        while k < args.budget:
            X = es.ask()
            X = [np.clip(x, 0.0, 1.0) for x in X[: args.budget - k]]
            batch = []
            for x in X:
                s = scenario(spec, fields, 0, dict(zip(dims, (float(v) for v in x))))
                s = dict(s, campaign=f"{spec.name}-search", scenario=k)
                (sdir / "scenarios" / f"{k:04d}.yaml").write_text(scenario_yaml(s), encoding="utf-8")
                batch.append(s)
                k += 1
            got = run_flights(client, batch, sdir, keep_completed_fraction=1.0, transport=args.transport,
                              done=done, progress=progress, fly=fly)
            for r in got:
                done[r["hash"]] = r
            rows += got
            if len(X) == popsize:
                es.tell(X, [score(r, args.search, args.tracking_bound) for r in got])
        progress.close()
    finally:
        if own:
            cluster = getattr(client, "cluster", None)
            client.close()
            if cluster is not None:
                cluster.close()
    write_table(rows, sdir)
    write_summary(f"{spec.name} (search: {args.search})", rows, sdir, time.monotonic() - t0, None)
    ranked = sorted(rows, key=lambda r: score(r, args.search, args.tracking_bound))[:5]
    lines = [f"# Worst scenarios found: {spec.name}, minimising {args.search}", "",
             "| scenario | score (m) | outcome | clearance (m) | tracking max (mm) | reproduce |",
             "|---|---|---|---|---|---|"]
    for r in ranked:
        c = "n/a" if r.get("min_clearance_m") is None else f"{r['min_clearance_m']:.3f}"
        t = "n/a" if r.get("tracking_max_error_m") is None else f"{r['tracking_max_error_m'] * 1e3:.1f}"
        lines.append(f"| {r['scenario']} | {score(r, args.search, args.tracking_bound):.3f} | {r['outcome']} | {c} | "
                     f"{t} | `{reproduce_command(r, sdir)}` |")
    (sdir / "worst.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"search {spec.name}: {len(rows)} flights; worst {args.search}:")
    for r in ranked:
        print(f"  scenario {r['scenario']}: score {score(r, args.search, args.tracking_bound):.3f} m "
              f"({r['outcome']}); reproduce: {reproduce_command(r, sdir)}")
    print(f"wrote {sdir}/: scenarios/, results/, results.parquet, results.csv, summary.md, summary.html, worst.md")
    return 0
