"""Mission uploads over a lossy, reordering link: how many fail (the protocol's state machines alone).

Usage::

    python benchmarks/bench_upload_lossy.py [--uploads 2000] [--items 12] [--loss 0.2]
        [--delay-ms 30] [--retries 7] [--tree NAME=PATH ...]

``mavcore.services.mission``'s ``MissionServer`` (the SITL's side) and
``MissionUploadClient`` (the companion's) back to back, stepped every 4 ms of
a simulated clock. Every message, both ways, is dropped with probability
``--loss`` and delayed by a uniform draw in [0, ``--delay-ms``], so messages
are reordered: the model of ``sitl.relay.UdpRelay`` that the lossy-link test
(``tests/test_outcomes_e2e.py``) puts between the two processes. Upload k
uses ``random.Random(k)``. Each ``--tree`` is imported in its own
subprocess (``PYTHONPATH``), so a baseline checkout can be compared in the
same run. Output: failed uploads per tree and their errors by kind.
"""

from __future__ import annotations

import argparse
import collections
import heapq
import json
import os
import random
import subprocess
import sys


def lossy_upload(seed: int, items: list, loss: float = 0.2, delay_s: float = 0.03, retries: int = 7,
                 deliver=None):
    """One upload of ``items`` (MISSION_ITEM_INT messages) over the link model (module doc):
    (client, server) when the client is done or 120 s have passed. ``deliver(msg, to_vehicle)``:
    the message as the other end receives it (default: as sent)."""
    from pymavlink.dialects.v20 import common as mavlink

    from mavcore.codec.mission_items import mission_item_from_int
    from mavcore.services.mission import MissionServer, MissionUploadClient, encode_reply

    rng = random.Random(seed)
    gcs = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    veh = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    server = MissionServer()
    client = MissionUploadClient(gcs, 1, 1, items, timeout_s=1.0, retries=retries)
    queue, k = [], 0

    def send(t, to_vehicle, m):
        nonlocal k
        if rng.random() >= loss:
            k += 1
            heapq.heappush(queue, (t + rng.uniform(0.0, delay_s), k, to_vehicle, m))

    t = 0.0
    for m in client.start(t):
        send(t, True, m)
    while not client.done and t < 120.0:
        t += 0.004
        while queue and queue[0][0] <= t:
            _, _, to_vehicle, m = heapq.heappop(queue)
            if deliver is not None:
                m = deliver(m, to_vehicle)
            if to_vehicle:
                replies = (server.handle_count(m.count, m.mission_type, t) if m.get_type() == "MISSION_COUNT"
                           else server.handle_item(mission_item_from_int(m), t))
                for r in replies:
                    send(t, False, encode_reply(veh, 255, 190, r))
            else:
                for r in client.on_message(m, t):
                    send(t, True, r)
        for r in server.tick(t):
            send(t, False, encode_reply(veh, 255, 190, r))
        for r in client.tick(t):
            send(t, True, r)
    return client, server


def one(seed: int, n: int, loss: float, delay_s: float, retries: int) -> str:
    from pymavlink.dialects.v20 import common as mavlink

    gcs = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    items = [gcs.mission_item_int_encode(1, 1, i, 3, 16, 0, 1, 0, 0, 0, 0, 448000000 + i, -6000000, 2.0, 0)
             for i in range(n)]
    client, server = lossy_upload(seed, items, loss, delay_s, retries)
    if not client.done:
        return "not finished in 120 s"
    try:
        got = client.outcome()
    except Exception as e:  # noqa: BLE001 - the kind of failure is the figure
        return type(e).__name__ + ": " + str(e).split(":")[-1].strip()[:60]
    stored = [i.y for i in server.items]
    return "ok" if got == n and stored == [m.y for m in items] else "stored items differ"


def run_here(args) -> dict:
    kinds = collections.Counter(one(s, args.items, args.loss, args.delay_ms * 1e-3, args.retries)
                                for s in range(args.uploads))
    return dict(kinds)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--uploads", type=int, default=2000)
    ap.add_argument("--items", type=int, default=12)
    ap.add_argument("--loss", type=float, default=0.2)
    ap.add_argument("--delay-ms", type=float, default=30.0)
    ap.add_argument("--retries", type=int, default=7, help="the client's re-sends in a row (the companion: 7)")
    ap.add_argument("--tree", action="append", default=[], help="NAME=PATH of a checkout (default: this one)")
    ap.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.json:
        print(json.dumps(run_here(args)))
        return 0
    trees = [t.split("=", 1) for t in args.tree] or [["this", ""]]
    for name, path in trees:
        env = dict(os.environ, PYTHONPATH=path) if path else dict(os.environ)
        cmd = [sys.executable, __file__, "--json", "--uploads", str(args.uploads), "--items", str(args.items),
               "--loss", str(args.loss), "--delay-ms", str(args.delay_ms), "--retries", str(args.retries)]
        kinds = json.loads(subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout)
        failed = args.uploads - kinds.get("ok", 0)
        print(f"{name}: {failed} of {args.uploads} uploads failed  {kinds}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
