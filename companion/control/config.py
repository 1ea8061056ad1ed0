"""Geometric controller gains (mission key ``control``).

Placeholder defaults; owned by the control module (issue 4).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ControlConfig:
    """Gains of the paper's Section 2.4.2 controller."""

    kx: float = 16.0
    kv: float = 5.6
    rho1: float = 1.0
    rho2: float = 1.0
    alpha: float = 10.0
