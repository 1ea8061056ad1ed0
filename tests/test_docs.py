"""docs/ against the code: the pages cannot fall behind what they describe.

- docs/mission.md's key table is what ``docs/mission_keys.py`` generates from
  the mission dataclasses (every key, its type and default), and every range
  written there as an interval is the loader's: a value on a closed bound is
  accepted, a value on an open bound or just outside a closed one refused;
- every hand-worked point of docs/frames.md holds for ``mavcore.frames``;
- docs/campaign.md's spec block names every key of the campaign spec and no other;
- every ``docs/...`` path named in the code and the pages exists, and nothing
  in the repository points to a design document outside it.
"""

from __future__ import annotations

import copy
import importlib.util
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from mavcore import frames
from mavcore.config import from_dict
from mavcore.errors import MissionError
from mavcore.mission.schema import Mission

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _mission_keys():
    spec = importlib.util.spec_from_file_location("mission_keys", DOCS / "mission_keys.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["mission_keys"] = module      # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


MK = _mission_keys()


# --- docs/mission.md ---------------------------------------------------------------

def test_mission_key_table_is_generated_from_the_dataclasses():
    text = (DOCS / "mission.md").read_text(encoding="utf-8")
    assert MK.current_block(text) == MK.generated_block(), "run: python docs/mission_keys.py --write"
    assert MK.main(["--check"]) == 0


def test_every_mission_key_is_documented_and_no_other():
    rows = MK.key_rows()                 # raises on an undocumented or unknown key
    keys = [r.key for r in rows]
    assert len(keys) == len(set(keys)) == len(MK.NOTES)
    # the table names the keys a mission file holds: every key of a bundled mission is in it
    import yaml

    for path in sorted((ROOT / "missions").glob("*/mission.yaml")):
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
        for key in _file_keys(data):
            assert key in keys, f"{path}: key {key} not in docs/mission.md"


def _file_keys(data, prefix: str = "") -> list[str]:
    out = []
    for k, v in data.items():
        key = prefix + k
        if isinstance(v, dict) and not key.endswith("[]"):
            out += _file_keys(v, key + ".")
        else:
            out.append(key)
            if isinstance(v, list) and v and isinstance(v[0], dict):
                for item in v:
                    out += _file_keys(item, key + "[].")
    return out


_NUM = r"([-+]?[0-9][0-9.]*(?:e[-+]?[0-9]+)?)"
_INTERVAL = re.compile(r"([\[(])" + _NUM + ", " + _NUM + r"([\])])( or null)?")
_BOUND = re.compile(r"(>=|>) " + _NUM + "( or null)?")


def _interval(text: str):
    """(lo, lo_closed, hi, hi_closed) of a range written as an interval, else None."""
    m = _INTERVAL.fullmatch(text)
    if m:
        return float(m.group(2)), m.group(1) == "[", float(m.group(3)), m.group(4) == "]"
    m = _BOUND.fullmatch(text)
    if m:
        return float(m.group(2)), m.group(1) == ">=", math.inf, False
    return None


BASE = {"name": "t", "map": "map.yaml", "dem": "dem.asc", "home": {"lat": 0.0, "lon": 0.0, "alt_m": 0.0},
        "sim": {"obstacles": [{"type": "cylinder", "x": 0.0, "y": 0.0, "height": 1.0, "radius": 0.5}],
                "rangefinders": [{"id": 0}],
                # a tractor: the widest speed range of a mover (a walker's stops at 1.5 m/s)
                "movers": [{"type": "tractor", "path": [[0.0, 0.0], [5.0, 0.0]], "speed_m_s": 1.0}]}}
_CHECKED = [(r.key, r.type, _interval(r.range)) for r in MK.key_rows()
            if r.type in ("number", "integer", "number or null") and _interval(r.range)]


def _accepts(key: str, value) -> bool:
    data = copy.deepcopy(BASE)
    d = data
    *parents, leaf = key.split(".")
    for p in parents:
        if p.endswith("[]"):
            d = d[p[:-2]][0]
        else:
            d = d.setdefault(p, {})
    d[leaf] = value
    try:
        from_dict(Mission, data, "t.yaml")
    except MissionError:
        return False
    return True


def test_enough_ranges_are_machine_checked():
    # a parser that read nothing would make the next test pass vacuously
    assert len(_CHECKED) >= 45
    assert _accepts("flight.speed_m_s", 1.0) and not _accepts("flight.speed_m_s", "fast")


@pytest.mark.parametrize("key,type_name,interval", _CHECKED, ids=[k for k, _, _ in _CHECKED])
def test_documented_range_is_the_loaders(key, type_name, interval):
    lo, lo_closed, hi, hi_closed = interval
    step = (lambda b: 1) if type_name == "integer" else (lambda b: 1e-9 * max(1.0, abs(b)))
    cast = int if type_name == "integer" else float
    for bound, closed, outward in ((lo, lo_closed, -1), (hi, hi_closed, +1)):
        if math.isinf(bound):
            continue
        inside = bound - outward * step(bound)
        assert _accepts(key, cast(bound)) == closed, f"{key} = {bound}"
        assert _accepts(key, cast(inside)), f"{key} = {inside} (inside the range)"
        if closed:
            assert not _accepts(key, cast(bound + outward * step(bound))), f"{key} just outside {bound}"


# --- docs/frames.md ------------------------------------------------------------------

def _hand_worked_rows() -> list[tuple[str, str]]:
    text = (DOCS / "frames.md").read_text(encoding="utf-8")
    section = text.split("## Hand-worked points", 1)[1]
    return re.findall(r"^\| `([^`]+)` \| `([^`]+)` \|", section, flags=re.M)


def test_frames_page_has_hand_worked_points():
    assert len(_hand_worked_rows()) >= 10


@pytest.mark.parametrize("expression,value", _hand_worked_rows())
def test_frames_hand_worked_point(expression, value):
    namespace = {name: getattr(frames, name) for name in dir(frames) if not name.startswith("_")}
    namespace.update(math=math, np=np)
    got = np.asarray(eval(expression, namespace), dtype=float)      # noqa: S307 - our own page
    want = np.asarray(eval(value, {}), dtype=float)                  # noqa: S307
    decimals = max((len(d) for d in re.findall(r"\.(\d+)", value)), default=0)
    assert got.shape == want.shape
    assert np.allclose(got, want, rtol=0.0, atol=0.5 * 10.0 ** -decimals + 1e-12), (got, want)


# --- docs/campaign.md ----------------------------------------------------------------

def _campaign_block_keys() -> list[str]:
    """The dotted keys of the spec block of docs/campaign.md (``section.key`` under a section)."""
    text = (DOCS / "campaign.md").read_text(encoding="utf-8")
    block = text.split("## The spec", 1)[1].split("```yaml", 1)[1].split("```", 1)[0]
    keys, section = [], None
    for line in block.splitlines():
        m = re.match(r"( *)([a-z_]+):", line)
        if not m:
            continue
        if not m.group(1):
            section = m.group(2)
            keys.append(section)
        else:
            keys.append(f"{section}.{m.group(2)}")
    return keys


def test_campaign_spec_block_names_every_key_and_no_other():
    import dataclasses
    import typing

    from companion.campaign.spec import CampaignSpec

    want = []
    for f in dataclasses.fields(CampaignSpec):
        if not f.init:
            continue
        want.append(f.name)
        sub = [a for a in typing.get_args(typing.get_type_hints(CampaignSpec)[f.name]) if dataclasses.is_dataclass(a)]
        for cls in sub:
            want += [f"{f.name}.{g.name}" for g in dataclasses.fields(cls) if g.init]
    got = _campaign_block_keys()
    assert len(got) == len(set(got))
    assert sorted(got) == sorted(want)


# --- references --------------------------------------------------------------------

_TEXT_FILES = [p for d in ("companion", "sitl", "tests", "missions", "benchmarks", "docs", ".ci")
               for p in (ROOT / d).rglob("*") if p.is_file() and p.suffix in (".py", ".md", ".yaml", ".toml", "")
               and ".venv" not in p.parts and "__pycache__" not in p.parts]
_TEXT_FILES += [ROOT / n for n in ("README.md", "BENCHMARKS.md", "pyproject.toml") if (ROOT / n).is_file()]


def _read(p: Path) -> str:
    try:
        return p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        return ""


def test_nothing_points_outside_the_repository():
    needles = ("DESIGN" + ".md", "../" + "shared", "/work/" + "shared")
    hits = [f"{p.relative_to(ROOT)}: {n}" for p in _TEXT_FILES for n in needles if n in _read(p)]
    assert hits == []


def test_every_docs_path_named_exists():
    missing = set()
    for p in _TEXT_FILES:
        for ref in re.findall(r"(?<![\w/.])docs/[\w./-]*[\w]", _read(p)):
            if not (ROOT / ref).exists():
                missing.add(f"{p.relative_to(ROOT)}: {ref}")
    for page in DOCS.glob("*.md"):                      # relative links between the pages
        for ref in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", _read(page)):
            if not (page.parent / ref).exists():
                missing.add(f"{page.relative_to(ROOT)}: {ref}")
    assert sorted(missing) == []
