"""Drive a ``mavcore.services`` client state machine over a real link (tests only).

The state machines take the clock as an argument; here it is the wall clock
(``time.monotonic``), as a ground station's would be. Messages that the
transaction does not take go to ``conn.handler`` when one is set.
"""

from __future__ import annotations

import time


def drive(conn, client, limit_s: float = 30.0):
    """Run ``client`` (start, answers, timeouts) over ``conn`` (``companion.link.Connection``)
    until it is done; returns its outcome or raises its error (``TimeoutError`` past ``limit_s``)."""
    clock = time.monotonic
    for m in client.start(clock()):
        conn.send(m)
    deadline = clock() + limit_s
    while not client.done:
        for m in conn.poll(0.01):
            out = client.on_message(m, clock())
            for o in out:
                conn.send(o)
            if not out and conn.handler is not None:
                conn.handler(m)
        for o in client.tick(clock()):
            conn.send(o)
        if clock() > deadline:
            raise TimeoutError(f"{type(client).__name__} not done within {limit_s:g} s")
    return client.outcome()
