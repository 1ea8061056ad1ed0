"""``companion campaign SPEC.yaml --out DIR [--workers N | --scheduler tcp://HOST:8786] [--search FIGURE --budget N]``.

Runs a campaign (docs/campaign.md): the spec's scenarios, each written as
``DIR/scenarios/NNNN.yaml``, flown as Dask tasks (``companion demo
--scenario`` in a worker), one row per flight in ``DIR/results/<hash>.json``
(resume: a rerun skips the finished ones) and ``DIR/results.parquet`` /
``.csv``, then ``summary.md``, the figures and ``summary.html``. Prints the
command that reproduces each flight that did not complete.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from mavcore.errors import CampaignError, InputError

SEARCH_FIGURES = ("clearance", "tracking")


def add_arguments(parser) -> None:
    parser.add_argument("spec", metavar="SPEC.yaml", help="the campaign spec (docs/campaign.md)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory (created; reused to resume)")
    parser.add_argument("--workers", type=int, default=None, metavar="N",
                        help="LocalCluster worker processes (default: one per core)")
    parser.add_argument("--scheduler", default=None, metavar="tcp://HOST:8786",
                        help="use this existing Dask scheduler instead of a LocalCluster")
    parser.add_argument("--flights", type=int, default=None, metavar="N", help="override the spec's flights")
    parser.add_argument("--cut", type=float, default=None, metavar="S", help="override the spec's cut_s")
    parser.add_argument("--transport", choices=("inproc", "udp"), default="inproc",
                        help="how each flight reaches its SITL (companion demo --transport): inproc (default: "
                             "in the worker's process, the same MAVLink bytes through memory) or udp (a SITL "
                             "subprocess per flight, loopback UDP)")
    parser.add_argument("--search", choices=SEARCH_FIGURES, default=None,
                        help="falsification: CMA-ES over the spec's continuous dimensions to minimise the "
                             "true clearance, or the margin to the tracking bound")
    parser.add_argument("--budget", type=int, default=40, metavar="N", help="--search: flights (default %(default)s)")
    parser.add_argument("--tracking-bound", type=float, default=0.1, metavar="M",
                        help="--search tracking: the bound on the max tracking error (default %(default)s m)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress line")


def _check_out(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}", "exists and is not a directory")
    if not out.exists() and not out.parent.is_dir():
        raise InputError(f"--out {out}", f"directory {out.parent} does not exist")


def run(args) -> int:
    import dataclasses

    from ..campaign.spec import load_spec, with_source

    spec = load_spec(args.spec)
    if args.flights is not None:
        if args.flights < 1:
            raise InputError(f"--flights {args.flights}", "must be >= 1")
        spec = with_source(dataclasses.replace(spec, flights=args.flights), args.spec)
    if args.cut is not None:
        if not args.cut > 0:
            raise InputError(f"--cut {args.cut}", "must be > 0 s")
        spec = with_source(dataclasses.replace(spec, cut_s=args.cut), args.spec)
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers {args.workers}", "must be >= 1")
    if args.search is not None and args.budget < 1:
        raise InputError(f"--budget {args.budget}", "must be >= 1")
    if args.scheduler is not None and not args.scheduler.startswith(("tcp://", "tls://", "inproc://", "ucx://")):
        raise InputError(f"--scheduler {args.scheduler}", "expected an address like tcp://HOST:8786")
    out = Path(args.out)
    _check_out(out)
    from ..campaign.scenarios import load_fields, scenario, scenario_yaml

    fields = load_fields(spec)   # plans each base mission once (bad missions fail here, before any output)
    try:
        import dask.distributed  # noqa: F401
        import pyarrow  # noqa: F401
    except ImportError as exc:
        raise InputError("companion campaign", f"needs the campaign extra (pip install -e '.[campaign]'): {exc}") \
            from None

    if args.search is not None:
        from ..campaign.search import run_search

        return run_search(spec, fields, out, args)

    t0 = time.monotonic()
    scenarios = [scenario(spec, fields, i) for i in range(spec.flights)]
    (out / "scenarios").mkdir(parents=True, exist_ok=True)
    for s in scenarios:
        p = out / "scenarios" / f"{s['scenario']:04d}.yaml"
        text = scenario_yaml(s)
        if not p.exists() or p.read_text(encoding="utf-8") != text:
            p.write_text(text, encoding="utf-8")
    return _fly_and_summarise(spec, fields, scenarios, out, args, t0)


def _fly_and_summarise(spec, fields, scenarios, out: Path, args, t0: float) -> int:
    from ..campaign.results import read_results, write_table
    from ..campaign.run import CampaignProgress, make_client, run_flights
    from ..campaign.scenarios import scenario_hash
    from ..campaign.summary import reproduce_command, write_summary

    wanted = {scenario_hash(s) for s in scenarios}
    done = {h: r for h, r in read_results(out / "results").items() if h in wanted}
    progress = CampaignProgress(len(scenarios), len(done), enabled=not args.quiet)
    if not args.quiet:
        print(f"campaign {spec.name}: {len(scenarios)} flights, {len(done)} done earlier, "
              f"{len(scenarios) - len(done)} to fly", file=sys.stderr)
    rows = list(done.values())
    if len(done) < len(scenarios):
        client = make_client(args.scheduler, args.workers)
        try:
            rows = run_flights(client, scenarios, out, keep_completed_fraction=spec.keep_completed_fraction,
                               transport=args.transport, done=done, progress=progress)
        finally:
            cluster = getattr(client, "cluster", None)
            client.close()
            if cluster is not None:
                cluster.close()
    write_table(rows, out)
    if all(f is None for f in fields.values()):
        first = next(iter(fields), None)
        fields = {} if first is None else {first: _map_field(spec, fields)}
    files = write_summary(spec.name, rows, out, time.monotonic() - t0, fields)
    counts = {k: sum(1 for r in rows if r["outcome"] == k) for k in ("completed", "held", "crashed", "failed")}
    print(f"campaign {spec.name}: {len(rows)} flights: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    print(f"wrote {out}/: results.parquet, results.csv, " + ", ".join(f.name for f in files))
    for r in sorted(rows, key=lambda r: r["scenario"]):
        if r["outcome"] != "completed":
            print(f"  {r['outcome']:8s} scenario {r['scenario']}: {(r.get('reason') or '')[:100]}\n"
                  f"           reproduce: {reproduce_command(r, out)}")
    return 0


def _map_field(spec, fields):
    """The first base mission's field for the map figure (planned here when the spec has no obstacles)."""
    try:
        from ..campaign.placement import cumulative, flown_path
        from ..campaign.scenarios import Field, mission_path
        from mavcore.mission import load_mission

        grid, path, _ = flown_path(load_mission(mission_path(next(iter(fields)))), spec.cut_s)
        return Field(grid, path, cumulative(path))
    except (InputError, CampaignError, ValueError):
        return None
