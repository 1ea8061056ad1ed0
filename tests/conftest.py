"""Shared fixtures."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def multi_sortie_plan():
    """(mission, plan) of flat-rectangle with a 0.9 Ah battery: several sorties."""
    from mavcore.mission import load_mission
    from companion.planner import plan_mission

    m = load_mission(ROOT / "missions" / "flat-rectangle" / "mission.yaml")
    m = dataclasses.replace(m, energy=dataclasses.replace(m.energy, battery_capacity_ah=0.9))
    plan = plan_mission(m)
    assert len(plan.sorties.sorties) >= 2, "the fixture needs several sorties"
    return m, plan
