"""``companion replay`` speed on the 130 s demo flight: vehicle time / wall time and MB/s.

Usage::

    python benchmarks/bench_replay.py [--tlog out/flight.tlog --plan out/plan.json] [--runs 3] [--profile]

Without ``--tlog`` it first records the demo flight (``companion demo
--no-plots --quiet`` into a temporary directory: flat-rectangle, companion
control, 130 s of vehicle time). Then, ``--runs`` times each (median):

- metrics only (``replay_chunks`` without a core: framing, CRC checks,
  decoding, metrics);
- full replay (the recorded ``FlightCore`` re-run from the setup record,
  every output compared with the recording).

The file is read into memory first (1 MB chunks), so the figures are the
replay's, not the disk's. Rebuilding the flight (planning when the flight
planned in flight, or the trajectory from ``--plan``) is timed apart: it
does not grow with the recording. ``--profile`` prints where the full
replay spends its time (cProfile, by component). Targets (issue 10):
>= 100x real time (the 130 s flight in <= 1.3 s) and >= 20 MB/s.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from companion.commands.fly import prepare  # noqa: E402
from companion.commands.replay import read_chunks  # noqa: E402
from mavcore.mission import load_mission  # noqa: E402
from companion.replay import build_core, find_setup, replay_chunks  # noqa: E402

MISSION = ROOT / "missions" / "flat-rectangle" / "mission.yaml"


def record_demo(out: Path) -> tuple[Path, Path]:
    r = subprocess.run([sys.executable, "-m", "companion.cli", "demo", "--no-plots", "--quiet", "--out", str(out)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"demo failed: {r.stderr.strip()[-500:]}")
    return out / "flight.tlog", out / "plan.json"


#: (component, file, function) for the profile breakdown: the function's cumulative time.
COMPONENTS = (
    ("framing + CRC (TlogScanner._scan)", "link/tlog_scan.py", "_scan"),
    ("decoding (FastDecoder / pymavlink)", "link/tlog_scan.py", "decode_record"),
    ("flight core (FlightCore.handle, all)", "flight/core.py", "handle"),
    ("  of which the controller (command)", "control/geometric.py", "command"),
    ("comparison (OutputComparer.compare)", "replay/compare.py", "compare"),
    ("metrics, vehicle messages", "replay/metrics.py", "vehicle"),
    ("metrics, companion messages", "replay/metrics.py", "companion"),
)


def profile(chunks, make_core) -> None:
    core = make_core()
    pr = cProfile.Profile()
    pr.enable()
    t0 = time.perf_counter()
    replay_chunks(chunks, core)
    wall = time.perf_counter() - t0
    pr.disable()
    st = pstats.Stats(pr)
    print(f"\nprofile of one full replay ({wall:.2f} s under cProfile), cumulative time by component:")
    for label, fname, func in COMPONENTS:
        cum = sum(ct for (f, _line, name), (_cc, _nc, _tt, ct, _callers) in st.stats.items()
                  if name == func and f.replace("\\", "/").endswith(fname))
        print(f"  {label:<42} {cum:7.3f} s  {100 * cum / wall:5.1f} %")
    print("\ntop functions by own time:")
    st.sort_stats("tottime").print_stats(15)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tlog", help="a companion .tlog (default: record the demo flight)")
    ap.add_argument("--plan", help="the plan.json it flew or was planned into (demo: out/plan.json)")
    ap.add_argument("--mission", default=str(MISSION))
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_replay_") as tmp:
        if args.tlog:
            tlog, plan = Path(args.tlog), (Path(args.plan) if args.plan else None)
        else:
            print("recording the demo flight ...", flush=True)
            tlog, plan = record_demo(Path(tmp))
        chunks = list(read_chunks(str(tlog)))
        n_bytes = sum(len(c) for c in chunks)
        mission = load_mission(args.mission)
        setup = find_setup(chunks)
        t0 = time.perf_counter()
        # the demo plans in flight: the plan.json it wrote has the same way-points (replay warns of
        # rounding when the flight used none; the comparison below says whether it matters)
        fp = prepare(mission, str(plan) if (plan and setup.get("plan_sha")) else None)
        t_prep = time.perf_counter() - t0

        def make_core():
            return build_core(setup, mission, fp)

        rows = {"metrics only": [], "full replay": []}
        cpu = {k: [] for k in rows}
        vehicle_s = None
        for _ in range(args.runs):
            t0, c0 = time.perf_counter(), time.process_time()
            res = replay_chunks(chunks)
            rows["metrics only"].append(time.perf_counter() - t0)
            cpu["metrics only"].append(time.process_time() - c0)
            vehicle_s = res.metrics.duration_s
            core = make_core()
            t0, c0 = time.perf_counter(), time.process_time()
            res = replay_chunks(chunks, core)
            rows["full replay"].append(time.perf_counter() - t0)
            cpu["full replay"].append(time.process_time() - c0)
            assert res.comparison.identical, res.comparison.first_divergence.describe()
        print(f"{tlog.name}: {n_bytes / 1e6:.2f} MB, {res.scan.n_records} records, {vehicle_s:.1f} s of vehicle "
              f"time; rebuilding the flight (plan/trajectory) {t_prep:.2f} s, not counted below")
        for k, v in rows.items():
            w = statistics.median(v)
            c = statistics.median(cpu[k])
            print(f"  {k:<13} median of {args.runs}: {w:.3f} s wall = {vehicle_s / w:6.1f}x real time, "
                  f"{n_bytes / 1e6 / w:6.1f} MB/s (CPU {c:.3f} s: {vehicle_s / c:.1f}x, {n_bytes / 1e6 / c:.1f} MB/s)"
                  + (f"  [{res.comparison.n_compared} outputs identical]" if k == "full replay" else ""))
        if args.profile:
            profile(chunks, make_core)
    return 0


if __name__ == "__main__":
    sys.exit(main())
