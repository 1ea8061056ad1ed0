"""Per-frame cost of the flight core on a recorded flight (process time, median of runs).

Usage::

    python benchmarks/bench_frame_cost.py [--flight companion-cut4] [--runs 5]
    python benchmarks/bench_frame_cost.py --tlog out/flight.tlog [--plan out/plan.json] [--mission M.yaml]

Default: the corpus flight ``tests/data/replay/companion-cut4`` (flat-rectangle,
companion control, 18 s of vehicle time, 4,500 sensor frames at 250 Hz).
``--tlog``: any companion-recorded .tlog (e.g. the one ``companion demo``
writes; give its ``plan.json`` when the flight flew a plan file).

Measured ``--runs`` times each (median), after one warm-up run:

- ``core only``: the ``FlightCore`` rebuilt from the recording's setup record
  and fed the recorded vehicle messages (decoded beforehand, not timed):
  ``handle`` and ``take_outbox``, nothing else. The controller, the observer,
  the replanner and the core's bookkeeping;
- ``full replay``: ``replay_chunks`` with a fresh core (framing, CRC checks,
  decoding, metrics, the core, every output compared with the recording; it
  must be identical, bit for bit).

Time is ``time.process_time`` (CPU of this process, all threads): on a shared
machine it is steadier than wall time, but it still grows when other processes
compete for the caches and cores, so compare two versions in the same session
and report ratios. Printed: seconds, microseconds per sensor frame and the
ratio of the flight's vehicle time to the process time (issue 10's target
for the replay: >= 100x).
"""

from __future__ import annotations

import argparse
import json
import lzma
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

from companion.commands.fly import prepare  # noqa: E402
from companion.link.connection import COMPANION_COMPONENT_ID, COMPANION_SYSTEM_ID  # noqa: E402
from companion.link.tlog_scan import TlogScanner, decode_record, new_decoder  # noqa: E402
from mavcore.mission import load_mission  # noqa: E402
from companion.replay import build_core, find_setup, replay_chunks  # noqa: E402

CORPUS = ROOT / "tests" / "data" / "replay"


def load_flight(args) -> tuple[bytes, object, object, dict]:
    """(tlog bytes, mission, flight plan, setup record) of the chosen flight."""
    if args.tlog:
        data = Path(args.tlog).read_bytes()
        mission = load_mission(args.mission or ROOT / "missions" / "flat-rectangle" / "mission.yaml")
        setup = find_setup([data])
        if setup is None:
            raise SystemExit(f"{args.tlog}: no setup record (not a companion-recorded flight)")
        plan = args.plan if (args.plan and setup.get("plan_sha")) else None
        return data, mission, prepare(mission, plan), setup
    manifest = json.loads((CORPUS / "manifest.json").read_text())
    if args.flight not in manifest:
        raise SystemExit(f"--flight: {args.flight!r} is not in {CORPUS / 'manifest.json'} ({', '.join(manifest)})")
    entry = manifest[args.flight]
    if entry["control"] != "companion":
        raise SystemExit(f"--flight: {args.flight!r} was flown with --control {entry['control']}: no companion frames")
    data = lzma.decompress((CORPUS / f"{args.flight}.tlog.xz").read_bytes())
    mission = load_mission(ROOT / entry["mission"])
    setup = find_setup([data])
    plan = CORPUS / "plan-flat-rectangle.json" if setup.get("plan_sha") else None
    return data, mission, prepare(mission, None if plan is None else str(plan)), setup


def vehicle_messages(data: bytes, core) -> list:
    """The recorded vehicle messages the core acts on, decoded, in order (as ``ReplaySession`` feeds them)."""
    ids = {getattr(mavlink, f"MAVLINK_MSG_ID_{n}") for n in core.handled_types
           if hasattr(mavlink, f"MAVLINK_MSG_ID_{n}")}
    sc = TlogScanner()
    dec = new_decoder()
    out = []
    for rec in sc.feed(data) + sc.close():
        if rec.msgid in ids and not (rec.compid == COMPANION_COMPONENT_ID and rec.sysid == COMPANION_SYSTEM_ID):
            m = decode_record(rec, dec)
            if m is not None:
                out.append(m)
    return out


def core_only(msgs: list, make_core) -> tuple[float, int]:
    """(process time s, frames) of one core fed ``msgs``."""
    core = make_core()
    c0 = time.process_time()
    for m in msgs:
        core.handle(m)
        if core.outbox:
            core.take_outbox()
    return time.process_time() - c0, (core.view if hasattr(core, "view") else core).n_frames


def full_replay(data: bytes, make_core) -> tuple[float, float]:
    """(process time s, vehicle time s) of one full replay; raises when an output differs."""
    core = make_core()
    c0 = time.process_time()
    res = replay_chunks([data], core)
    cpu = time.process_time() - c0
    if not res.comparison.identical:
        raise SystemExit(f"the replay diverged: {res.comparison.first_divergence.describe()}")
    return cpu, res.metrics.duration_s


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flight", default="companion-cut4", help="a corpus flight (tests/data/replay/manifest.json)")
    ap.add_argument("--tlog", help="a companion-recorded .tlog instead of a corpus flight")
    ap.add_argument("--plan", help="with --tlog: the plan.json the flight flew")
    ap.add_argument("--mission", help="with --tlog: its mission.yaml (default: flat-rectangle)")
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    if args.runs < 1:
        raise SystemExit("--runs: must be >= 1")
    data, mission, fp, setup = load_flight(args)

    def make_core():
        return build_core(setup, mission, fp)

    msgs = vehicle_messages(data, make_core())
    core_only(msgs, make_core)                     # warm-up (imports, caches of the first run)
    full_replay(data, make_core)
    core_t, full_t = [], []
    frames = vehicle_s = None
    for _ in range(args.runs):
        t, frames = core_only(msgs, make_core)
        core_t.append(t)
        t, vehicle_s = full_replay(data, make_core)
        full_t.append(t)
    name = args.tlog or args.flight
    print(f"{name}: {frames} sensor frames, {vehicle_s:.1f} s of vehicle time, {len(data) / 1e6:.2f} MB; "
          f"process time, median of {args.runs} (shared machine: compare versions in one session)")
    for label, ts in (("core only", core_t), ("full replay", full_t)):
        med = statistics.median(ts)
        print(f"  {label:<12} {med:7.3f} s  {1e6 * med / frames:7.1f} us/frame  {vehicle_s / med:6.1f}x vehicle time"
              f"  (min {min(ts):.3f} s, max {max(ts):.3f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
