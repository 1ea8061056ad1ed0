"""A lossy, jittery UDP link between a MAVLink peer and the SITL (for tests and benchmarks).

``UdpRelay`` listens on ``listen`` (loopback by default) for the companion and
forwards its datagrams to ``target`` (the SITL's ``udpin`` address); the
SITL's answers come back to the relay's own socket and are forwarded to the
last companion address seen. Each datagram, in each direction independently,
is dropped with probability ``loss`` or delayed by a uniform draw in
``[delay_min_s, delay_max_s]`` (so datagrams can be reordered, as on a real
lossy radio link). Seeded: ``numpy.random.Generator(seed)``. ``drop``, a
predicate ``(direction, datagram) -> bool`` (0: to the vehicle, 1: to the
companion), discards chosen datagrams as well (a test's targeted loss).

Command line: ``python -m sitl.relay --to udpin-address --listen 127.0.0.1:PORT
--loss 0.2 --delay-ms 0,30 --seed 1``.
"""

from __future__ import annotations

import argparse
import heapq
import select
import socket
import threading
import time

import numpy as np


class UdpRelay:
    """See the module docstring. ``start()`` runs it in a thread; ``stop()`` ends it."""

    def __init__(self, target: tuple[str, int], listen: tuple[str, int] = ("127.0.0.1", 0), loss: float = 0.0,
                 delay_min_s: float = 0.0, delay_max_s: float = 0.0, seed: int = 0, drop=None) -> None:
        if not 0.0 <= loss < 1.0:
            raise ValueError("loss must be in [0, 1)")
        if not 0.0 <= delay_min_s <= delay_max_s < 10.0:
            raise ValueError("need 0 <= delay_min_s <= delay_max_s < 10 s")
        self.target = (str(target[0]), int(target[1]))
        self.listen_addr = (str(listen[0]), int(listen[1]))
        self.loss = float(loss)
        self.delay = (float(delay_min_s), float(delay_max_s))
        self.rng = np.random.default_rng(seed)
        self.drop = drop
        self.n_forwarded = [0, 0]     # to the vehicle, to the companion
        self.n_dropped = [0, 0]
        self._stop = threading.Event()
        self._thread = None
        self.front = None
        self.back = None

    @property
    def port(self) -> int:
        return self.front.getsockname()[1]

    def start(self) -> "UdpRelay":
        self.front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.front.bind(self.listen_addr)
        self.back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.back.bind(("127.0.0.1", 0))
        self._thread = threading.Thread(target=self._run, daemon=True, name="udp-relay")
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
        for s in (self.front, self.back):
            if s is not None:
                s.close()

    def __enter__(self) -> "UdpRelay":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def _run(self) -> None:
        queue: list = []
        seq = 0
        peer = None
        lo, hi = self.delay
        while not self._stop.is_set():
            now = time.monotonic()
            while queue and queue[0][0] <= now:
                _, _, sock, addr, data = heapq.heappop(queue)
                try:
                    sock.sendto(data, addr)
                except OSError:
                    pass
            wait = 0.05 if not queue else max(0.0, min(0.05, queue[0][0] - now))
            try:
                ready, _, _ = select.select((self.front, self.back), (), (), wait)
            except (OSError, ValueError):
                return
            for s in ready:
                try:
                    data, addr = s.recvfrom(65536)
                except OSError:
                    continue
                if s is self.front:
                    peer = addr
                    d, out, to = 0, self.back, self.target
                else:
                    if peer is None:
                        continue
                    d, out, to = 1, self.front, peer
                if self.rng.random() < self.loss or (self.drop is not None and self.drop(d, data)):
                    self.n_dropped[d] += 1
                    continue
                self.n_forwarded[d] += 1
                delay = lo if hi <= lo else float(self.rng.uniform(lo, hi))
                seq += 1
                heapq.heappush(queue, (time.monotonic() + delay, seq, out, to, data))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m sitl.relay", description=__doc__.splitlines()[0])
    p.add_argument("--to", required=True, metavar="HOST:PORT", help="the SITL's udpin address")
    p.add_argument("--listen", default="127.0.0.1:14560", metavar="HOST:PORT")
    p.add_argument("--loss", type=float, default=0.0)
    p.add_argument("--delay-ms", default="0,0", metavar="MIN,MAX")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    try:
        host, port = a.to.rsplit(":", 1)
        lhost, lport = a.listen.rsplit(":", 1)
        dmin, dmax = (float(x) * 1e-3 for x in a.delay_ms.split(","))
        relay = UdpRelay((host, int(port)), (lhost, int(lport)), a.loss, dmin, dmax, a.seed)
    except ValueError as exc:
        print(f"sitl.relay: error: {exc}")
        return 2
    relay.start()
    print(f"relay {a.listen} -> {a.to}: loss {a.loss:g}, delay {a.delay_ms} ms", flush=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        relay.stop()
    return 0


if __name__ == "__main__":   # pragma: no cover
    raise SystemExit(main())
