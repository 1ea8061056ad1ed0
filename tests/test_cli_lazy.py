"""``companion COMMAND``: only the command named is imported (``companion.cli.command_named``)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from companion.cli import COMMANDS, build_parser, command_named

ROOT = Path(__file__).resolve().parents[1]


def test_command_named_is_the_first_word_when_it_is_a_command():
    assert command_named(["fly", "m.yaml", "--plan", "p.json"]) == "fly"
    assert command_named(["plan", "m.yaml"]) == "plan"
    assert command_named([]) is None
    assert command_named(["--help"]) is None
    assert command_named(["fyl", "m.yaml"]) is None      # not a command: the full parser says so
    assert command_named(["m.yaml", "fly"]) is None


@pytest.mark.parametrize("command", list(COMMANDS))
def test_the_parser_of_one_command_parses_as_the_full_one(command):
    argv = {"plan": ["m.yaml", "-o", "p.json"], "fly": ["m.yaml", "--plan", "p.json", "--sortie", "2", "-v"],
            "replay": ["f.tlog"], "campaign": ["c.yaml", "--out", "d"], "demo": ["-q"]}[command]
    full = vars(build_parser().parse_args([command, *argv]))
    one = vars(build_parser(command).parse_args([command, *argv]))
    assert full.keys() == one.keys() and all(
        full[k] == one[k] for k in full if k != "_run")
    assert full["_run"] is one["_run"]


def test_fly_imports_no_other_command_and_help_lists_them_all():
    code = ("import sys; from companion.cli import build_parser, command_named; "
            "build_parser(command_named(['fly', 'm.yaml'])); "
            "print(sorted(m for m in sys.modules if m.startswith('companion.commands.')))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert r.stdout.strip() == "['companion.commands.fly']", r.stdout + r.stderr
    r = subprocess.run([sys.executable, "-m", "companion", "--help"], capture_output=True, text=True,
                       timeout=60, cwd=ROOT)
    assert r.returncode == 0 and all(name in r.stdout for name in COMMANDS), r.stdout + r.stderr
    r = subprocess.run([sys.executable, "-m", "companion", "fly", "--help"], capture_output=True, text=True,
                       timeout=60, cwd=ROOT)
    assert r.returncode == 0 and "--sortie" in r.stdout, r.stdout + r.stderr
