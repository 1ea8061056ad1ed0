"""mavcore/inputs.py: the bounded loading layer (docs/limits.md). Each cap is
checked at its boundary (the cap passes, one more fails), so a cap that is
changed or no longer enforced fails here; the YAML loader gives what
``yaml.safe_load`` gives on every bundled mission; the JSON depth scan agrees
with a recursive count on random documents, whatever the chunk boundaries."""

from __future__ import annotations

import json
import os
import random
import signal
import threading

import pytest
import yaml

from companion.bundled import missions_dir
from mavcore.errors import InputError, MapError
from mavcore.inputs import (Limits, brief, check, count_tokens, json_depth, limits, open_regular, parse_json,
                            read_bytes)
from mavcore.inputs_yaml import parse_yaml


def test_defaults_and_environment_overrides():
    assert limits({}) == Limits()
    lim = limits({"COMPANION_MAX_IMAGE_PIXELS": "1_000", "COMPANION_MAX_YAML_ALIASES": "7", "PATH": "/bin"})
    assert lim.image_pixels == 1000 and lim.yaml_aliases == 7 and lim.dem_cells == Limits().dem_cells
    for env, needle in (({"COMPANION_MAX_IMAGE_PIXELS": "many"}, "positive integer"),
                        ({"COMPANION_MAX_IMAGE_PIXELS": "0"}, "positive integer"),
                        ({"COMPANION_MAX_PIXELS": "5"}, "names no limit")):
        with pytest.raises(InputError, match=needle) as e:
            limits(env)
        assert next(iter(env)) in str(e.value)


def test_every_limit_is_documented():
    from pathlib import Path

    page = (Path(__file__).parents[1] / "docs" / "limits.md").read_text(encoding="utf-8")
    for f in Limits.__dataclass_fields__:
        assert f"`{Limits.env_name(f)}`" in page, f


def test_check_passes_the_cap_and_refuses_one_more():
    lim = Limits(dem_cells=100)
    check("f", "cells", 100, "dem_cells", MapError, lim)
    with pytest.raises(MapError) as e:
        check("f", "cells", 101, "dem_cells", MapError, lim)
    assert str(e.value) == "f: cells is 101, above the limit 100 (COMPANION_MAX_DEM_CELLS)"


def test_size_cap_at_the_boundary(tmp_path):
    p = tmp_path / "f"
    p.write_bytes(b"x" * 10)
    assert read_bytes(p, InputError, lim=Limits(text_bytes=10)) == b"x" * 10
    with pytest.raises(InputError, match="the file size is 10, above the limit 9"):
        read_bytes(p, InputError, lim=Limits(text_bytes=9))


@pytest.fixture
def alarm():
    """Fail instead of hanging: a blocking open is interrupted after 5 s."""
    if threading.current_thread() is not threading.main_thread():   # pragma: no cover
        pytest.skip("needs the main thread for SIGALRM")

    def boom(*_):
        raise TimeoutError("blocked")
    old = signal.signal(signal.SIGALRM, boom)
    signal.alarm(5)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, old)


@pytest.mark.parametrize("kind", ["fifo", "dir", "/dev/zero", "/dev/urandom", "loop"])
def test_only_regular_files_are_opened_and_nothing_blocks(kind, tmp_path, alarm):
    p = tmp_path / "x"
    if kind == "fifo":
        os.mkfifo(p)
    elif kind == "dir":
        p.mkdir()
    elif kind == "loop":
        os.symlink("y", p)
        os.symlink("x", tmp_path / "y")
    else:
        os.symlink(kind, p)
    with pytest.raises(InputError) as e:
        open_regular(p, InputError)
    assert ("not a regular file" in str(e.value)) or ("symbolic links" in str(e.value))


def test_brief_is_bounded_and_fast_on_a_shared_bomb():
    x = ["lol"] * 9
    for _ in range(12):          # 9**12 leaves if expanded
        x = [x] * 9
    assert len(brief(x)) <= 60 and len(brief("y" * 10**6)) <= 60 and len(brief(10**4000 // 7)) <= 60


def test_count_tokens_matches_split():
    rng = random.Random(5)
    for _ in range(200):
        data = bytes(rng.choice(b"ab \n\t1") for _ in range(rng.randint(0, 60)))
        for chunk in (1, 3, 1 << 20):
            assert count_tokens(data, chunk) == len(data.split())


# --- YAML ------------------------------------------------------------------------------

@pytest.mark.parametrize("path", sorted(missions_dir().rglob("*.yaml")), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_yaml_loader_reads_what_safe_load_reads(path):
    text = path.read_text(encoding="utf-8")
    assert parse_yaml(text, str(path), InputError) == yaml.safe_load(text)


def test_yaml_aliases_at_the_cap():
    doc = "a: &a 1\nb: [" + ", ".join(["*a"] * 5) + "]\n"
    assert parse_yaml(doc, "s", InputError, Limits(yaml_aliases=5))["b"] == [1] * 5
    with pytest.raises(InputError, match="number of YAML aliases is 5, above the limit 4"):
        parse_yaml(doc, "s", InputError, Limits(yaml_aliases=4))


def test_yaml_expanded_nodes_at_the_cap():
    # l1 = [l0 x3], l0 = [x, x]: l0 has 3 nodes, l1 1 + 3*3 = 10, the mapping 1 + 2 keys + 3 + 10 = 16
    doc = "l0: &l0 [x, x]\nl1: [*l0, *l0, *l0]\n"
    parse_yaml(doc, "s", InputError, Limits(yaml_nodes=16))
    with pytest.raises(InputError, match="aliases expanded \\(nodes\\) is 16, above the limit 15"):
        parse_yaml(doc, "s", InputError, Limits(yaml_nodes=15))


def test_yaml_nesting_at_the_cap():
    doc = "a: " + "[" * 9 + "]" * 9 + "\n"            # the mapping, then 9 lists: depth 10
    parse_yaml(doc, "s", InputError, Limits(nesting_depth=10))
    with pytest.raises(InputError, match="YAML nesting depth is 10, above the limit 9"):
        parse_yaml(doc, "s", InputError, Limits(nesting_depth=9))


def test_yaml_recursive_alias_is_refused():
    with pytest.raises(InputError, match="recursive"):
        parse_yaml("a: &x [1, *x]\n", "s", InputError)


# --- JSON ------------------------------------------------------------------------------

def _depth(doc) -> int:
    if isinstance(doc, dict):
        return 1 + max((_depth(v) for v in doc.values()), default=0)
    if isinstance(doc, list):
        return 1 + max((_depth(v) for v in doc), default=0)
    return 0


def test_json_depth_scan_agrees_with_a_recursive_count():
    rng = random.Random(3)
    leaves = [1, "a[b{\"\\", "\\\\", "\"", "}]", 2.5, None, "\\\"[["]

    def gen(d):
        if d == 0 or rng.random() < 0.3:
            return rng.choice(leaves)
        if rng.random() < 0.5:
            return [gen(d - 1) for _ in range(rng.randint(0, 3))]
        return {rng.choice(["k", "[", "{\\\"", "\\"]) + str(i): gen(d - 1) for i in range(rng.randint(0, 3))}

    for _ in range(300):
        doc = gen(8)
        text = json.dumps(doc)
        for chunk in (1, 2, 7, 1 << 20):
            assert json_depth(text, chunk) == _depth(doc), text


def test_json_nesting_at_the_cap():
    assert parse_json("[" * 10 + "]" * 10, "s", InputError, Limits(nesting_depth=10)) is not None
    with pytest.raises(InputError, match="JSON nesting depth is above the limit 9"):
        parse_json("[" * 10 + "]" * 10, "s", InputError, Limits(nesting_depth=9))
    with pytest.raises(InputError, match="JSON nesting depth"):
        parse_json("[" * 200_000 + "]" * 200_000, "s", InputError)
