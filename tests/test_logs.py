"""-v/-q on every command line (``mavcore.logs``)."""

from __future__ import annotations

import io
import logging

import pytest

from companion.cli import COMMANDS, build_parser
from mavcore.logs import configure, level
from sitl.cli import build_parser as sitl_parser


def test_levels():
    assert level(0, True) == logging.ERROR and level(3, True) == logging.ERROR   # -q wins
    assert (level(0, False), level(1, False), level(2, False), level(5, False)) == \
        (logging.WARNING, logging.INFO, logging.DEBUG, logging.DEBUG)


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_companion_command_takes_v_and_q(command):
    p = build_parser()
    required = {"plan": ["m.yaml", "-o", "p.json"], "fly": ["m.yaml"], "replay": ["f.tlog"],
                "campaign": ["c.yaml", "--out", "d"], "demo": []}[command]
    a = p.parse_args([command, *required, "-vv"])
    assert (a.verbose, a.quiet) == (2, False)
    a = p.parse_args([command, *required, "-q"])
    assert a.quiet


def test_sitl_takes_v_and_q():
    a = sitl_parser().parse_args(["m.yaml", "-v", "-q"])
    assert (a.verbose, a.quiet) == (1, True)


def test_configure_filters_and_does_not_stack():
    buf = io.StringIO()
    configure(0, False, stream=buf)
    configure(1, False, stream=buf)          # replaces the first handler
    log = logging.getLogger("sitl")
    log.debug("hidden")
    log.info("shown")
    assert buf.getvalue() == "sitl: INFO: shown\n"
    configure(0, False)
