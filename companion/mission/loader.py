"""Load a mission YAML file into a ``Mission``."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import yaml

from ..config import from_dict
from ..errors import MissionError
from .schema import Mission


def load_mission(path: str | Path) -> Mission:
    """Read and validate a mission file.

    Raises
    ------
    MissionError
        The file is missing, is not YAML, or breaks the schema (message names
        the file and the key).
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise MissionError(str(p), "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MissionError(str(p), f"cannot read: {exc}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f" line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise MissionError(f"{p}{':' + line.strip() if line else ''}", f"not valid YAML: {problem}") from None
    if not isinstance(data, dict):
        raise MissionError(str(p), "expected a mapping of mission keys at the top level")
    for key in ("base_dir", "source"):
        if key in data:
            raise MissionError(f"{p}: key '{key}'", "unknown key (set by the loader)")
    mission = from_dict(Mission, data, str(p))
    return dataclasses.replace(mission, base_dir=str(p.resolve().parent), source=str(p))
