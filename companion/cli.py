"""``companion`` command line: ``plan``, ``fly``, ``demo``, ``replay``, ``campaign``.

Each subcommand lives in ``companion.commands.<name>`` with
``add_arguments(parser)`` and ``run(args) -> int``. Bad input of any kind
(``InputError``) ends here as one line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from mavcore.logs import add_verbosity, configure

from . import process_clock  # noqa: F401  (starts the fallback clock of timings_s.wall)
from mavcore.errors import InputError

COMMANDS = {
    "plan": "plan a coverage mission: maps -> ISOA -> way-points -> LQR trajectory -> plan.json",
    "fly": "fly a planned mission over MAVLink against a vehicle (the bundled SITL or a flight stack)",
    "demo": "start the bundled SITL, plan and fly a bundled mission, write out/",
    "replay": "replay a recorded flight (.tlog): its metrics; with --mission, re-run the companion and compare",
    "campaign": "fly many varied scenarios (Monte Carlo or a falsification search) on Dask, summarise them",
}


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The ``companion`` parser. ``only``: the subcommand the command line names
    (``command_named``): its module alone is imported and given its arguments, the
    others are listed by name and help text (the parser is only asked to parse that
    command line); None: every subcommand in full (``--help``, tests, the campaigns)."""
    parser = argparse.ArgumentParser(prog="companion", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, help_text in COMMANDS.items():
        if only is not None and name != only:
            sub.add_parser(name, help=help_text, description=help_text)
            continue
        try:
            module = importlib.import_module(f"companion.commands.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"companion.commands.{name}":
                raise
            continue  # subcommand not built yet
        p = sub.add_parser(name, help=help_text, description=help_text)
        module.add_arguments(p)
        add_verbosity(p)
        p.set_defaults(_run=module.run)
    return parser


def command_named(argv: list[str]) -> str | None:
    """The subcommand ``argv`` (without the program name) runs: its first word when
    that is one of ``COMMANDS`` (the parser has no option before it), else None."""
    return argv[0] if argv and argv[0] in COMMANDS else None


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv``; None: the process's own (``sys.argv``: the
    ``companion`` script, ``python -m companion``), after which the process exits, so
    a command may keep its imports out of the garbage collector (``args.process_exits``,
    :mod:`companion.long_lived`). Returns the exit code."""
    # only the command named is imported: ``companion fly`` starts without the planner's modules
    parser = build_parser(command_named(sys.argv[1:] if argv is None else list(argv)))
    args = parser.parse_args(argv)
    args.process_exits = argv is None
    configure(args.verbose, args.quiet)
    try:
        return int(args._run(args) or 0)
    except InputError as exc:
        print(f"companion {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"companion {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
