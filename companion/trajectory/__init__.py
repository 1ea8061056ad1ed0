"""LQR trajectory generation (Section 2.3.2) and the pointing direction (eq. 21).

The names are loaded on first use (PEP 562): ``companion fly --plan`` reads
the stored pieces without the LQR solver, whose
``scipy.linalg`` import is 0.2 s of the 0.5 s a flight may take to start.
"""

from importlib import import_module

_WHERE = {
    "generate_trajectory": ".lqr",
    "PointingDerivatives": ".pointing",
    "pointing_derivatives": ".pointing",
    "pointing_directions": ".pointing",
    "Trajectory": ".sampling",
    "TrajectorySample": ".sampling",
}

__all__ = list(_WHERE)


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(_WHERE[name], __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
