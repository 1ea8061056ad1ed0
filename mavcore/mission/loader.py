"""Load a mission YAML file into a ``Mission``."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from ..config import from_dict
from ..errors import MissionError
from ..inputs import read_text
from .schema import Mission

#: Fields of ``Mission`` that the loader sets; a mission file may not hold them.
SET_BY_LOADER = ("base_dir", "source")


def load_mission(path: str | Path) -> Mission:
    """Read and validate a mission file.

    Raises
    ------
    MissionError
        The file is missing, is not YAML, or breaks the schema (message names
        the file and the key).
    """
    from ..inputs_yaml import parse_yaml   # PyYAML on first use

    p = Path(path)
    data = parse_yaml(read_text(p, MissionError), str(p), MissionError)
    if not isinstance(data, dict):
        raise MissionError(str(p), "expected a mapping of mission keys at the top level")
    for key in SET_BY_LOADER:
        if key in data:
            raise MissionError(f"{p}: key '{key}'", "unknown key (set by the loader)")
    mission = from_dict(Mission, data, str(p))
    return dataclasses.replace(mission, base_dir=str(p.resolve().parent), source=str(p))
