"""Python ``logging`` for every command line (``companion ...``, ``sitl``).

``add_verbosity(parser)`` gives a command ``-v``/``--verbose`` (repeatable)
and ``-q``/``--quiet``; ``configure(verbose, quiet)`` sets the root logger
from them, once, at the command line's edge (modules only call
``logging.getLogger(__name__)``):

======  ========  ===========================================================
flags   level     what is shown on stderr
======  ========  ===========================================================
-q      ERROR     errors only; no progress line (where a command has one)
(none)  WARNING   warnings; the progress line
-v      INFO      + what the vehicle says (STATUSTEXT), flight phases, links
-vv     DEBUG     + every command and its answer
======  ========  ===========================================================

A command's own result (tables, "wrote ...", the error line of bad input) is
its output, printed whatever the level.
"""

from __future__ import annotations

import logging
import sys

FORMAT = "%(name)s: %(levelname)s: %(message)s"


def add_verbosity(parser) -> None:
    """Add ``-v``/``--verbose`` and ``-q``/``--quiet`` to an argparse parser
    (a parser with its own ``--quiet`` keeps it, under ``-q`` too)."""
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="more log output on stderr (-v: info, -vv: debug)")
    if "--quiet" not in parser._option_string_actions:      # noqa: SLF001 (argparse has no public lookup)
        parser.add_argument("-q", "--quiet", action="store_true", help="errors only on stderr")


def level(verbose: int, quiet: bool) -> int:
    """The root logger's level for the flags (table above)."""
    if quiet:
        return logging.ERROR
    return {0: logging.WARNING, 1: logging.INFO}.get(int(verbose), logging.DEBUG)


def configure(verbose: int = 0, quiet: bool = False, stream=None) -> None:
    """Send log records of ``level(verbose, quiet)`` and above to stderr, one line each."""
    root = logging.getLogger()
    for h in list(root.handlers):
        if getattr(h, "_mavcore", False):
            root.removeHandler(h)
    h = logging.StreamHandler(stream if stream is not None else sys.stderr)
    h.setFormatter(logging.Formatter(FORMAT))
    h._mavcore = True       # ours: replaced, not stacked, by a second call
    root.addHandler(h)
    root.setLevel(level(verbose, quiet))
