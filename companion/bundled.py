"""The bundled missions (``missions/`` next to the ``companion`` package) and
how a ``--mission NAME|PATH`` argument names one. Used by ``companion demo``
and the campaigns' scenario files."""

from __future__ import annotations

from pathlib import Path

from mavcore.errors import InputError


def missions_dir() -> Path:
    """The bundled missions (``missions/`` next to the ``companion`` package)."""
    return Path(__file__).resolve().parents[1] / "missions"


def resolve_mission(name_or_path: str) -> Path:
    """A bundled mission name (``flat-rectangle``) or a mission YAML path."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or p.exists():
        if p.is_dir():
            p = p / "mission.yaml"
        return p
    bundled = missions_dir() / name_or_path / "mission.yaml"
    if not bundled.exists():
        names = sorted(d.name for d in missions_dir().iterdir() if (d / "mission.yaml").exists()) \
            if missions_dir().is_dir() else []
        raise InputError(f"--mission {name_or_path}", f"no such mission file or bundled mission "
                         f"(bundled: {', '.join(names) or 'none'})")
    return bundled
