"""ISOA coverage planning and way-point extraction (paper Section 2.2, 2.3.1).

The names below are loaded on first use (PEP 562 ``__getattr__``): the flight
imports this package's free-space, path and way-point modules (the replanner,
the sorties) without the planner's own (the ISOA sweep, the block graph, the
row detection).
"""

from __future__ import annotations

import importlib

_EXPORTS = {"CoveragePlan": ".plan", "plan_coverage": ".plan", "RowSpacing": ".rows",
            "detect_row_spacing": ".rows", "Waypoints": ".waypoints", "extract_waypoints": ".waypoints",
            "waypoints_along": ".waypoints"}

__all__ = list(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
