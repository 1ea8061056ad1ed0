"""Hostile input files (issue 19, docs/limits.md): the corpus of
tests/hostile_corpus.py, every case through ``companion.cli.main`` in-process
(exit code 2, exactly one line on stderr naming the problem, no traceback,
the line bounded in length, nothing written), and a handful of the worst as
real subprocesses under a time and an address-space limit, with their peak
RSS measured (benchmarks/hostile_inputs.py runs every case that way)."""

from __future__ import annotations

import time
import warnings

import pytest

from companion.cli import main as companion_main
from ports import private_link
from hostile_corpus import CASES, SUBPROCESS_IDS, check_base, make_base, run_limited, tree

#: The longest error line allowed: a file name (elided beyond 200 characters) and a short clause.
MAX_LINE = 500


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    b = make_base(tmp_path_factory.mktemp("hostile-base"))
    check_base(b)
    return b


def test_corpus_is_large_and_covers_every_kind():
    ids = [c.id for c in CASES]
    assert len(ids) == len(set(ids)) and len(ids) >= 150
    for prefix in ("mission-", "map-", "image-", "pgm-", "png-", "dem-", "geojson-", "kml-", "planjson-",
                   "tlog-", "env-"):
        assert sum(i.startswith(prefix) for i in ids) >= 3, prefix
    for kind in ("fifo", "dev-zero", "dev-urandom", "directory", "symlink-loop", "sparse"):
        assert sum(kind in i for i in ids) >= 5, kind
    assert set(SUBPROCESS_IDS) <= set(ids)


IN_PROCESS = [c for c in CASES if c.id not in SUBPROCESS_IDS]


@pytest.mark.parametrize("case", IN_PROCESS, ids=[c.id for c in IN_PROCESS])
def test_hostile_input_is_one_line_and_exit_2(case, base, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for k, v in case.env.items():
        monkeypatch.setenv(k, v)
    argv = private_link(case.build(tmp_path, base))
    before = tree(tmp_path)
    capsys.readouterr()
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:     # a warning would be a second line on stderr
        warnings.simplefilter("always")
        rc = companion_main(argv)
    elapsed = time.perf_counter() - t0
    out, err = capsys.readouterr()
    assert rc == 2, (rc, out[-500:], err[-2000:])
    assert err.count("\n") == 1 and err.endswith("\n"), err[:2000]
    assert "Traceback" not in err and "Traceback" not in out
    noisy = [w for w in caught if issubclass(w.category, (RuntimeWarning, UserWarning))]
    assert not noisy, [str(w.message)[:200] for w in noisy]
    assert err.startswith(f"companion {argv[0]}: error: "), err[:500]
    assert case.needle in err, err[:1000]
    assert len(err) <= MAX_LINE, f"{len(err)} characters: {err[:300]}..."
    assert tree(tmp_path) == before, "something was written"
    assert elapsed < 15.0, f"{elapsed:.1f} s"   # wall time, in-process on a shared machine (CPU: the subprocess test)


SUB = [c for c in CASES if c.id in SUBPROCESS_IDS]


@pytest.mark.slow
@pytest.mark.parametrize("case", SUB, ids=[c.id for c in SUB])
def test_worst_cases_as_subprocesses_in_bounded_time_and_memory(case, base, tmp_path):
    """CPU time <= 5 s (wall time depends on the machine's load: a hang is caught by a
    30 s kill), peak RSS <= 500 MB under a 1 GiB address-space limit."""
    argv = private_link(case.build(tmp_path, base))
    before = tree(tmp_path)
    rc, err, wall, cpu, rss, timed_out = run_limited(argv, tmp_path, case.env, timeout_s=30.0)
    assert not timed_out, f"killed after {wall:.1f} s"
    assert cpu <= 5.0, f"{cpu:.1f} s of CPU"
    assert rc == 2, (rc, err[-2000:])
    assert err.count("\n") == 1 and case.needle in err, err[-2000:]
    assert rss <= 500e6, f"{rss / 1e6:.0f} MB"
    assert tree(tmp_path) == before
