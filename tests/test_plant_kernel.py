"""The compiled plant kernel (``sitl.plant_kernel``, numba) against the Python
reference (``Plant.advance``): the same states, bit for bit, over seeded
flights with take-off, touch-down, drag, wind and crashes. Skipped without numba.

Documented tolerance (docs/README.md "Optional compiled kernels"): none; the
two paths are required to agree exactly, which is also what keeps the replay
corpus valid with the kernel on.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitl import plant_kernel
from sitl.plant import Plant, PlantParams

numba = pytest.importorskip("numba")


def _state(pl: Plant) -> tuple:
    return (pl.p, pl.v, pl.w, pl.R, pl.f, pl.acc, pl.landed, pl.touchdowns, pl.impact_vel_enu_m_s, pl._count)


def _pair(monkeypatch, drag: float, ground):
    monkeypatch.setenv(plant_kernel.ENV, "1")
    fast = Plant(PlantParams(drag_n_s_m=drag), ground_height=ground, max_ground_m=0.5 if ground else math.inf)
    ref = Plant(PlantParams(drag_n_s_m=drag), ground_height=ground, max_ground_m=0.5 if ground else math.inf)
    ref._kernel = None   # the Python loop only
    return fast, ref


def _terrain(x: float, y: float) -> float:
    return 0.25 + 0.25 * math.sin(0.3 * x) * math.cos(0.2 * y)   # in [0, 0.5]


@pytest.mark.parametrize("drag", [0.0, 0.3])
def test_seeded_flight_bit_identical(monkeypatch, drag):
    """Hover-ish commands with seeded perturbations: climb-out from the ground,
    flight, descents to touch-down and lift-off again, 4 steps per frame."""
    fast, ref = _pair(monkeypatch, drag, _terrain)
    assert plant_kernel.kernel() is not None
    rng = np.random.default_rng(16)
    for pl in (fast, ref):
        pl.set_state((1.0, 2.0, _terrain(1.0, 2.0)), landed=True)
    hover = fast._m * fast._g / 4 / fast._fmax
    compiled_frames = 0
    touchdowns = 0
    for k in range(4000):
        # altitude hold on 3 m, then on 1 m below the ground (a touch-down), alternating
        z_target = 3.0 if (k // 500) % 2 == 0 else -1.0
        base = hover * (1.0 + 0.3 * (z_target - fast.p[2]) - 0.5 * fast.v[2])
        cmd = tuple(float(base + d) for d in rng.normal(0.0, 2e-4, 4))
        wind = tuple(float(w) for w in rng.normal(0.0, 2.0, 3))
        was_landed = fast.landed
        fast.advance(cmd, 0.001, 4, wind)
        ref.advance(cmd, 0.001, 4, wind)
        compiled_frames += not was_landed
        assert _state(fast) == _state(ref), f"frame {k}"
        touchdowns = fast.touchdowns
    assert touchdowns >= 2 and compiled_frames > 1000   # both branches were exercised


def test_random_states_bit_identical(monkeypatch):
    """Random attitudes, rates and thrusts far from hover (large rotations per
    step, the polar step, commands outside [0, 1] clipped), no ground."""
    fast, ref = _pair(monkeypatch, 0.2, None)
    rng = np.random.default_rng(8)
    for trial in range(200):
        R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        if np.linalg.det(R) < 0:
            R[:, 0] = -R[:, 0]
        args = dict(p=rng.normal(0, 50, 3), v=rng.normal(0, 5, 3), R=R, w=rng.normal(0, 3, 3),
                    f=rng.uniform(0, fast._fmax, 4))
        for pl in (fast, ref):
            pl.set_state(**args)
        for _ in range(int(rng.integers(1, 40))):
            cmd = tuple(float(c) for c in rng.uniform(-0.2, 1.2, 4))
            h = float(rng.choice([0.001, 0.0025, 0.004]))
            n = int(rng.integers(1, 9))
            wind = tuple(float(v) for v in rng.normal(0, 3, 3))
            fast.advance(cmd, h, n, wind)
            ref.advance(cmd, h, n, wind)
            assert _state(fast) == _state(ref), f"trial {trial}"


def test_crash_rest_falls_in_python(monkeypatch):
    """After a crash the body falls to its rest height: the kernel stops where the
    support is needed and the Python loop lands it (the same as the reference)."""
    fast, ref = _pair(monkeypatch, 0.0, None)
    for pl in (fast, ref):
        pl.set_state((0.0, 0.0, 3.0))
        pl.crash((0.0, 0.0, 3.0), 1.2)
    for _ in range(400):
        fast.advance((0.6,) * 4, 0.001, 4)
        ref.advance((0.6,) * 4, 0.001, 4)
        assert _state(fast) == _state(ref)
    assert fast.landed and fast.p[2] == 1.2


def test_env_forces_python(monkeypatch):
    monkeypatch.setenv(plant_kernel.ENV, "0")
    assert plant_kernel.kernel() is None
    assert Plant(PlantParams())._kernel is None
    monkeypatch.setenv(plant_kernel.ENV, "1")
    assert Plant(PlantParams())._kernel is plant_kernel.kernel() is not None
