"""companion.long_lived: the collector paused during a command's imports, everything
alive then frozen, and only when ``main`` runs as the process's own command line."""

from __future__ import annotations

import gc
import os
import subprocess
import sys
from pathlib import Path

import pytest

from companion.long_lived import imports_kept

ROOT = Path(__file__).resolve().parents[1]
MISSION = ROOT / "missions" / "flat-rectangle" / "mission.yaml"


@pytest.fixture
def gc_state():
    """Restore the test process's collector (enabled, nothing frozen) afterwards."""
    was = gc.isenabled()
    frozen = gc.get_freeze_count()
    yield frozen
    gc.unfreeze()
    (gc.enable if was else gc.disable)()


def test_imports_kept_pauses_the_collector_then_freezes_what_is_alive(gc_state):
    gc.enable()
    with imports_kept(True):
        assert not gc.isenabled()
        kept = [[i] for i in range(1000)]        # 1001 new tracked containers
    assert gc.isenabled()
    assert gc.get_freeze_count() >= gc_state + len(kept) + 1


def test_imports_kept_disabled_changes_nothing(gc_state):
    gc.enable()
    with imports_kept(False):
        assert gc.isenabled()
    assert gc.get_freeze_count() == gc_state


def test_imports_kept_restores_the_collector_and_freezes_nothing_on_an_error(gc_state):
    gc.enable()
    with pytest.raises(ImportError):
        with imports_kept(True):
            raise ImportError("a missing library")
    assert gc.isenabled() and gc.get_freeze_count() == gc_state
    gc.disable()                                  # a caller that runs without the collector keeps it so
    with imports_kept(True):
        pass
    assert not gc.isenabled()


def _freeze_count_after(argv_literal: str) -> int:
    code = (f"import gc, sys, contextlib, io\nfrom companion.cli import main\nsys.argv = {argv_literal}\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    rc = main() if sys.argv[0] == 'companion' else main(sys.argv[1:])\n"
            "print(rc, gc.get_freeze_count(), gc.isenabled())")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT,
                         timeout=300, check=True).stdout.split()
    assert out[0] == "0" and out[2] == "True"     # planned, the collector running again
    return int(out[1])


def test_plan_freezes_its_imports_only_as_the_process_command_line(tmp_path):
    plan = tmp_path / "plan.json"
    # main() reads sys.argv (the companion script, python -m companion): the imports are frozen
    assert _freeze_count_after(repr(["companion", "plan", str(MISSION), "-o", str(plan)])) > 10_000
    # main(argv) from a caller (a test, a tool): nothing frozen
    assert _freeze_count_after(repr(["tool", "plan", str(MISSION), "-o", str(plan)])) == 0
