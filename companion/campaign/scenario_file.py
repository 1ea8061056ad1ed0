"""The scenario file (``DIR/scenarios/NNNN.yaml``): read, validate, and turn
into the mission file that ``companion demo --scenario`` flies.

A scenario = a base mission (bundled name or path) + ``overrides`` merged
into it (mappings key by key, anything else replaced) + the SITL's ``seed``
+ ``cut_s`` + ``control`` (+ ``link``: a lossy real-time link). Schema: docs/campaign.md.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from mavcore.config import from_dict
from mavcore.errors import CampaignError, MissionError
from mavcore.inputs import read_text

#: mission keys holding a path relative to the mission file
PATH_KEYS = (("map",), ("dem",), ("field", "file"))


@dataclass(frozen=True)
class LinkScenario:
    """A lossy, jittery link (``sitl.relay.UdpRelay``): each datagram, each
    direction, dropped with probability ``loss`` or delayed uniformly in
    ``delay_ms`` = [lo, hi] milliseconds; the flight then runs in real time over UDP."""

    loss: float = 0.0
    delay_ms: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if not 0.0 <= self.loss <= 0.9:
            raise ValueError(f"link.loss must be in [0, 0.9], got {self.loss:g}")
        lo, hi = self.delay_ms
        if not 0.0 <= lo <= hi <= 2000.0:
            raise ValueError(f"link.delay_ms: need 0 <= lo <= hi <= 2000 ms, got [{lo:g}, {hi:g}]")


@dataclass(frozen=True)
class ScenarioFile:
    campaign: str
    scenario: int
    mission: str
    seed: int
    control: Literal["companion", "vehicle"] = "companion"
    cut_s: float | None = None
    overrides: Any = None
    link: LinkScenario | None = None

    def __post_init__(self) -> None:
        if self.overrides is not None and not isinstance(self.overrides, dict):
            raise ValueError("overrides: expected a mapping of mission keys")
        if self.seed < 0:
            raise ValueError("seed must be >= 0")
        if self.cut_s is not None and not self.cut_s > 0:
            raise ValueError("cut_s must be > 0 s or null")


def load_scenario(path: str | Path) -> ScenarioFile:
    p = Path(path)
    from mavcore.inputs_yaml import parse_yaml   # PyYAML on first use
    data = parse_yaml(read_text(p, CampaignError, "scenario file"), str(p), CampaignError)
    if not isinstance(data, dict):
        raise CampaignError(str(p), "expected a mapping of scenario keys at the top level")
    return from_dict(ScenarioFile, data, str(p), "", CampaignError)


def deep_merge(base: dict, over: dict) -> dict:
    """``base`` with ``over`` merged in: mappings key by key, anything else replaced (new dict)."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def scenario_mission(sc: ScenarioFile, source: str):
    """(mission data dict with absolute map/dem/field paths, Mission) for the scenario.

    Raises CampaignError naming ``source`` when the merged mission is not valid."""
    from ..bundled import resolve_mission
    from mavcore.mission.schema import Mission

    ref = sc.mission
    if not Path(ref).is_absolute() and "/" in ref:
        ref = str((Path(source).resolve().parent / ref))
    try:
        base = resolve_mission(ref)
    except Exception as exc:
        raise CampaignError(f"{source}: key 'mission'", str(exc)) from None
    from mavcore.inputs_yaml import parse_yaml   # PyYAML on first use
    data = parse_yaml(read_text(base, MissionError), str(base), MissionError)
    if not isinstance(data, dict):
        raise CampaignError(f"{source}: key 'mission'", f"{base}: not a mapping of mission keys")
    for keys in PATH_KEYS:
        d = data
        for k in keys[:-1]:
            d = d.get(k) if isinstance(d, dict) else None
        if isinstance(d, dict) and isinstance(d.get(keys[-1]), str) and not Path(d[keys[-1]]).is_absolute():
            d[keys[-1]] = str((base.resolve().parent / d[keys[-1]]).resolve())
    merged = deep_merge(data, sc.overrides or {})
    import dataclasses

    mission = from_dict(Mission, merged, f"{source} (mission {sc.mission} + overrides)", "", CampaignError)
    return merged, dataclasses.replace(mission, base_dir=str(base.resolve().parent), source=source)
