"""Ports for tests that run in parallel (pytest-xdist, pyproject's addopts).

``companion fly`` binds its default link (``udpin:127.0.0.1:14540``) before it
reads the plan; two workers that both fly with the default would see "port
14540 is already in use" instead of the error a case is about. Every in-test
``fly`` that does not name ``--connect`` gets a port of its own here.
"""
from __future__ import annotations

import socket


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that the kernel had free a moment ago (an ephemeral
    port: it is not handed out again soon)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def private_link(argv: list) -> list:
    """``argv`` of ``companion fly`` with ``--connect udpin:127.0.0.1:<free port>``
    added when it names no link; any other argv unchanged."""
    if not argv or argv[0] != "fly" or "--connect" in argv:
        return list(argv)
    return [*argv, "--connect", f"udpin:127.0.0.1:{free_udp_port()}"]
