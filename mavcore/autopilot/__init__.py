"""Autopilot personalities and their registry (``--autopilot px4|ardupilot``).

``get(key)`` by name; ``from_heartbeat(autopilot)`` by a HEARTBEAT's
MAV_AUTOPILOT (what the companion does on connection).
"""

from __future__ import annotations

from .ardupilot import ARDUCOPTER, ArduCopter
from .base import BEHAVIOURS, Autopilot, MissionRules, ModeDef, OffboardLoss, ParamAlias, ParamCheck, ParamSpec
from .px4 import PX4, PX4_AUTOPILOT
from .sim_params import READ_ONLY_PARAMS, SIM_PARAM_SPECS

#: key -> personality.
REGISTRY: dict[str, Autopilot] = {PX4_AUTOPILOT.key: PX4_AUTOPILOT, ARDUCOPTER.key: ARDUCOPTER}
NAMES = tuple(REGISTRY)
DEFAULT = PX4_AUTOPILOT.key


def get(key: str) -> Autopilot:
    """The personality called ``key``; ValueError naming the known ones."""
    try:
        return REGISTRY[key]
    except KeyError:
        raise ValueError(f"unknown autopilot {key!r} (known: {', '.join(NAMES)})") from None


def from_heartbeat(mav_autopilot: int) -> Autopilot | None:
    """The personality whose HEARTBEAT ``autopilot`` is ``mav_autopilot``; None if none."""
    for ap in REGISTRY.values():
        if ap.mav_autopilot == int(mav_autopilot):
            return ap
    return None


__all__ = ["ARDUCOPTER", "ArduCopter", "Autopilot", "BEHAVIOURS", "DEFAULT", "MissionRules", "ModeDef", "NAMES", "OffboardLoss",
           "PX4", "PX4_AUTOPILOT", "ParamAlias", "ParamCheck", "ParamSpec", "READ_ONLY_PARAMS", "REGISTRY", "SIM_PARAM_SPECS",
           "from_heartbeat", "get"]
