"""Flights as Dask tasks: the worker's flight, the cluster, resume and progress.

Each flight is ``companion demo --scenario FILE`` called in-process in a Dask
worker (``fly_scenario``: the demo's own parser and ``run``; with the
campaign's default ``--transport inproc`` the bundled SITL runs in the same
process, lockstep through memory; ``udp``: the demo starts it as its
subprocess, lockstep over loopback UDP). Scenarios go
to the workers and rows come back as small dicts; the client writes each
row to ``DIR/results/<hash>.json`` as it arrives, so an interrupted campaign
resumes without re-flying what finished.

A worker that dies (its process exits or is killed) loses only its flight:
the scheduler runs it again once (``distributed.scheduler.allowed-failures``
= 1, and ``worker-saturation`` = 1.0 so that a worker holds only the task it
runs (the batch is one graph, queued on the scheduler), both set here for
the default ``LocalCluster``; an existing cluster uses its own settings).
Dask queues only batches of more than twice the worker threads: in a smaller
one a worker may hold a second flight, which its death counts against too.
A second death, or an exception escaping the flight after ``retries=1``,
makes the row ``failed``.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import shutil
import sys
import tempfile
import time
import uuid
from pathlib import Path
from typing import Callable, TextIO

from .results import OUTCOMES, make_row, write_result
from .scenarios import scenario_hash, scenario_yaml

#: retries of a flight whose task raised, and deaths of its worker tolerated
RETRIES = 1


def demo_options() -> set[str]:
    """The option strings of ``companion demo``'s parser (e.g. to see whether it has ``--transport``)."""
    from ..cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    return {s for a in sub.choices["demo"]._actions for s in a.option_strings}


def keep_completed(h: str, fraction: float) -> bool:
    """The seeded sample of completed flights whose files are kept: by the scenario hash."""
    return int(h[:8], 16) < fraction * 2**32


def _position_at(track, t_s: float | None) -> tuple[float, float] | None:
    """ENU (x, y) of the vehicle's ground truth at ``t_s`` (None: the last one): the last
    sample of ``track`` (``sight.track_of``) at or before it; None without one."""
    import numpy as np

    t, p = track
    k = len(t) - 1 if t_s is None else int(np.searchsorted(t, t_s, side="right")) - 1
    return None if k < 0 else (float(p[k, 0]), float(p[k, 1]))


def _track_and_mission(mission_file: Path, tlog: Path, outcome: str):
    """(track or None, mission or None) of a flight: the tlog's true track is read once, and
    only when a column needs it (where a flight that did not complete went wrong; the
    line-of-sight columns of a flight with movers)."""
    from mavcore.mission import load_mission
    from .sight import track_of

    mission = None
    try:
        if mission_file.exists():
            mission = load_mission(str(mission_file))
    except ValueError:
        mission = None
    movers = mission is not None and mission.sim is not None and bool(mission.sim.movers)
    if not tlog.exists() or (outcome == "completed" and not movers):
        return None, mission
    try:
        return track_of(tlog), mission
    except (OSError, ValueError):
        return None, mission


def fly_scenario(scenario: dict, out_dir: str, keep_if_completed: bool = False,
                 transport: str | None = None) -> dict:
    """One flight (runs in a worker): write the scenario file, run ``companion demo --scenario``
    in this process, classify, keep the files of a flight that did not complete, return the row."""
    from ..cli import build_parser
    from mavcore.errors import InputError

    t0 = time.perf_counter()
    h = scenario_hash(scenario)
    work = Path(tempfile.mkdtemp(prefix=f"campaign-{scenario['scenario']:04d}-"))
    try:
        sc_file = work / "scenario.yaml"
        sc_file.write_text(scenario_yaml(scenario), encoding="utf-8")
        argv = ["demo", "--scenario", str(sc_file), "--out", str(work / "out"), "--no-plots", "--quiet"]
        if transport is not None and "--transport" in demo_options():
            argv += ["--transport", transport]
        error = None
        log = io.StringIO()
        with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
            try:
                args = build_parser().parse_args(argv)
                args._run(args)
            except InputError as exc:
                error = f"bad input: {exc}"
            except SystemExit as exc:
                error = f"demo exited with {exc.code}"
            except Exception as exc:  # noqa: BLE001 - a flight's failure is a result, not a campaign crash
                error = f"{type(exc).__name__}: {exc}"
        rp = work / "out" / "report.json"
        report = None
        if rp.exists():
            import json

            report = json.loads(rp.read_text(encoding="utf-8"))
        elif error is None:
            error = "no report.json: " + log.getvalue().strip()[-300:]
        from .results import classify

        outcome, _ = classify(report, error)
        track, mission = _track_and_mission(work / "out" / "mission.yaml", work / "out" / "flight.tlog", outcome)
        where = sight = None
        if track is not None:
            from .sight import flight_sight

            if outcome != "completed":
                where = _position_at(track, ((report or {}).get("crash") or {}).get("t_s"))
            if mission is not None:
                try:
                    sight = flight_sight(mission, track)
                except (OSError, ValueError):
                    sight = None
        kept = None
        if outcome != "completed" or keep_if_completed:
            dest = Path(out_dir) / "flights" / f"{scenario['scenario']:04d}-{h}"
            dest.mkdir(parents=True, exist_ok=True)
            for name in ("report.json", "flight.tlog", "mission.yaml"):
                if (work / "out" / name).exists():
                    shutil.copy2(work / "out" / name, dest / name)
            (dest / "demo.log").write_text(log.getvalue(), encoding="utf-8")
            kept = str(dest.relative_to(out_dir)) if dest.is_relative_to(out_dir) else str(dest)
        return make_row(scenario, report, error, time.perf_counter() - t0, kept, where, sight)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def make_client(scheduler: str | None = None, workers: int | None = None):
    """A ``dask.distributed.Client``: to ``scheduler`` (``tcp://HOST:8786``), or to a new
    ``LocalCluster`` of ``workers`` processes (default: one per core), one thread each."""
    import dask
    from dask.distributed import Client, LocalCluster

    # A dying worker counts against every task it holds: with saturation 1.0 it
    # holds only the one it runs (threads_per_worker=1), so only that flight is retried.
    dask.config.set({"distributed.scheduler.allowed-failures": RETRIES,
                     "distributed.scheduler.worker-saturation": 1.0})
    if scheduler is not None:
        return Client(scheduler)
    n = workers or os.cpu_count() or 1
    import logging

    # long-lived workers repay numba's start-up (sitl.plant_kernel): on unless the user said otherwise
    os.environ.setdefault("VINEYARD_GNC_NUMBA", "1")
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=logging.ERROR)
    return Client(cluster)


class CampaignProgress:
    """One live line on stderr: flights done, failures so far (by outcome), ETA."""

    def __init__(self, total: int, skipped: int, stream: TextIO | None = None, enabled: bool = True) -> None:
        self.total, self.skipped = total, skipped
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.t0 = time.monotonic()
        self.done = 0
        self.counts = {k: 0 for k in OUTCOMES}

    def line(self) -> str:
        n = self.skipped + self.done
        elapsed = time.monotonic() - self.t0
        left = self.total - n
        eta = "?" if not self.done else _hms(elapsed / self.done * left)
        bad = ", ".join(f"{k} {v}" for k, v in self.counts.items() if k != "completed" and v) or "none"
        skip = f" ({self.skipped} from earlier runs)" if self.skipped else ""
        return f"campaign: {n}/{self.total} flights{skip}, not completed: {bad}, elapsed {_hms(elapsed)}, ETA {eta}"

    def update(self, row: dict) -> None:
        self.done += 1
        self.counts[row["outcome"]] = self.counts.get(row["outcome"], 0) + 1
        if self.enabled:
            end = "\r" if self.tty else "\n"
            self.stream.write("\x1b[2K" + self.line() + end if self.tty else self.line() + end)
            self.stream.flush()

    def close(self) -> None:
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()


def _hms(s: float) -> str:
    if not math.isfinite(s):
        return "?"
    s = int(round(s))
    return f"{s // 3600}h{s // 60 % 60:02d}m" if s >= 3600 else f"{s // 60}m{s % 60:02d}s"


def failed_row(scenario: dict, reason: str) -> dict:
    return make_row(scenario, None, reason, 0.0)


def run_flights(client, scenarios: list[dict], out: Path, *, keep_completed_fraction: float = 0.0,
                fly: Callable = fly_scenario, transport: str | None = None, done: dict | None = None,
                progress: CampaignProgress | None = None) -> list[dict]:
    """Fly every scenario whose hash is not in ``done`` (hash -> row); write each row to
    ``out/results/<hash>.json`` as it finishes; return the rows of all ``scenarios``."""
    from dask.distributed import as_completed

    done = dict(done or {})
    todo = [s for s in scenarios if scenario_hash(s) not in done]
    # One graph for the whole batch: the scheduler then queues the flights (a worker
    # holds only the flight it runs, worker-saturation 1.0) instead of handing
    # each worker several at once, which a death would all count against.
    hashes = [scenario_hash(s) for s in todo]
    fs = client.map(fly, todo, [str(out)] * len(todo), [keep_completed(h, keep_completed_fraction) for h in hashes],
                    [transport] * len(todo), key=[f"flight-{uuid.uuid4().hex}" for _ in todo], pure=False,
                    retries=RETRIES) if todo else []
    futures = dict(zip(fs, todo))
    for f in as_completed(futures):
        s = futures[f]
        try:
            row = f.result()
        except Exception as exc:  # KilledWorker (died twice) or an exception that escaped twice
            row = failed_row(s, f"{type(exc).__name__}: {str(exc)[:200]}")
        f.release()
        write_result(out / "results", row)
        done[row["hash"]] = row
        if progress is not None:
            progress.update(row)
    if progress is not None:
        progress.close()
    return [done[scenario_hash(s)] for s in scenarios]
