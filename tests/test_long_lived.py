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


def _fly_freeze_count(argv_literal: str, plan: Path) -> tuple[int, bool]:
    """(frozen objects, collector enabled) when ``companion fly --plan`` reaches the runner
    (``MissionRunner.run`` replaced by a report of the collector's state: nothing is flown)."""
    code = ("import gc, sys\nimport companion.commands.fly as fly\n"
            "real = fly.execute\n"
            "def execute(*a, **k):\n"
            "    print(gc.get_freeze_count(), gc.isenabled()); sys.stdout.flush(); raise SystemExit(0)\n"
            "fly.execute = execute\n"
            f"from companion.cli import main\nsys.argv = {argv_literal}\n"
            "main() if sys.argv[0] == 'companion' else main(sys.argv[1:])\n")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT,
                         timeout=300, check=True).stdout.split()
    return int(out[0]), out[1] == "True"


def test_fly_freezes_its_imports_only_as_the_process_command_line(tmp_path):
    plan = tmp_path / "plan.json"
    subprocess.run([sys.executable, "-m", "companion", "plan", str(MISSION), "-o", str(plan)], check=True,
                   capture_output=True, env=dict(os.environ, PYTHONPATH=str(ROOT)), cwd=ROOT, timeout=300)
    args = ["fly", str(MISSION), "--plan", str(plan), "--connect", "udpout:127.0.0.1:14999",
            "--tlog", str(tmp_path / "f.tlog"), "--report", str(tmp_path / "r.json"), "-q"]
    # the flight's modules (the runner, the replanner, the guard, numpy, scipy) are frozen
    # before the mission and the plan are read; the collector runs again for the rest
    frozen, enabled = _fly_freeze_count(repr(["companion"] + args), plan)
    assert frozen > 10_000 and enabled
    frozen, enabled = _fly_freeze_count(repr(["tool"] + args), plan)
    assert frozen == 0 and enabled
