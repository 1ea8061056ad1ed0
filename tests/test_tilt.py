"""The safety limit of the desired thrust vector (companion.control.tilt), by hand-worked cases.

F_d pointing down -> the vertical floor, b3d upright; F_d at 60 deg -> rotated
to exactly the 45 deg limit with its azimuth and vertical part kept; F_d
inside the cone -> untouched. The limited direction's derivatives are checked
against finite differences of the limited direction itself.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.control import GeometricController, Measurements, Reference
from mavcore.mission.control import ControlConfig
from companion.control.tilt import limit_thrust, needs_limit
from mavcore.vehicle import GRAVITY_M_S2 as G
from mavcore.vehicle import VehicleConfig

VEH = VehicleConfig()
MG = VEH.mass_kg * G
FZ_MIN = 0.25 * MG                    # ControlConfig().vertical_thrust_min_fraction m g
TAN45 = math.tan(math.radians(45.0))


def _tilt_deg(v):
    return math.degrees(math.atan2(math.hypot(v[0], v[1]), v[2]))


def test_config_defaults_and_validation():
    cfg = ControlConfig()
    assert cfg.tilt_max_deg == 45.0 and cfg.vertical_thrust_min_fraction == 0.25
    for bad in ({"tilt_max_deg": 0.0}, {"tilt_max_deg": 90.0}, {"vertical_thrust_min_fraction": 0.0},
                {"vertical_thrust_min_fraction": 1.0}):
        with pytest.raises(ValueError):
            ControlConfig(**bad)


def test_thrust_pointing_down_is_floored_and_upright():
    # F_d = (3, -4, -20) N: below the floor. By hand: F' = (3, -4, 0.25 m g = 10.64 N),
    # tilt atan(5 / 10.64) = 25.2 deg, inside the 45 deg cone, so the horizontal part stays.
    lim = limit_thrust((3.0, -4.0, -20.0), (0.1, 0.2, 0.3), (0.0, 0.0, 0.0), FZ_MIN, TAN45)
    assert lim.F == (3.0, -4.0, FZ_MIN)
    assert _tilt_deg(lim.G) == pytest.approx(math.degrees(math.atan(5.0 / FZ_MIN)), abs=1e-12)
    assert lim.G_dot == (0.1, 0.2, 0.0)           # the floored vertical part does not move
    # straight down: upright b3d, thrust at the floor
    lim = limit_thrust((0.0, 0.0, -33.7), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), FZ_MIN, TAN45)
    assert lim.F == (0.0, 0.0, FZ_MIN)


@pytest.mark.parametrize("azimuth", [2.0, -0.7])
def test_thrust_at_60_deg_is_rotated_to_exactly_the_limit_keeping_azimuth(azimuth):
    # |F| = 50 N at 60 deg: vertical 25 N (> floor), horizontal 43.3 N -> 25 tan 45 = 25 N.
    s60, c60 = math.sin(math.radians(60.0)), math.cos(math.radians(60.0))
    F = (50.0 * s60 * math.cos(azimuth), 50.0 * s60 * math.sin(azimuth), 50.0 * c60)
    lim = limit_thrust(F, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), FZ_MIN, TAN45)
    assert lim.F[2] == F[2]
    assert np.allclose(lim.F, (25.0 * math.cos(azimuth), 25.0 * math.sin(azimuth), 25.0), rtol=0, atol=1e-12)
    assert _tilt_deg(lim.F) == pytest.approx(45.0, abs=1e-12) and _tilt_deg(lim.G) == pytest.approx(45.0, abs=1e-12)
    assert math.atan2(lim.G[1], lim.G[0]) == pytest.approx(azimuth, abs=1e-12)


def test_limited_direction_derivatives_match_finite_differences():
    # F(t) = F0 + t F1 + t^2/2 F2, tilted beyond the limit: G's derivatives against central differences.
    F0, F1, F2 = np.array([30.0, 20.0, 15.0]), np.array([-8.0, 12.0, 3.0]), np.array([5.0, -4.0, 1.0])

    def G(t):
        F = F0 + t * F1 + 0.5 * t * t * F2
        return np.array(limit_thrust(tuple(F), tuple(F1 + t * F2), tuple(F2), FZ_MIN, TAN45).G)

    lim = limit_thrust(tuple(F0), tuple(F1), tuple(F2), FZ_MIN, TAN45)
    h = 1e-4
    assert np.allclose(lim.G_dot, (G(h) - G(-h)) / (2 * h), atol=1e-7)
    assert np.allclose(lim.G_ddot, (G(h) - 2 * G(0.0) + G(-h)) / h ** 2, atol=1e-5)


def test_inside_the_cone_nothing_changes():
    assert limit_thrust((1.0, 2.0, 40.0), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0), FZ_MIN, TAN45) is None
    # just inside the 45 deg edge and just above the floor
    assert not needs_limit((0.999 * 20.0, 0.0, 20.0), FZ_MIN, TAN45 * TAN45)
    assert needs_limit((1.001 * 20.0, 0.0, 20.0), FZ_MIN, TAN45 * TAN45)
    assert not needs_limit((0.0, 0.0, FZ_MIN), FZ_MIN, 1.0) and needs_limit((0.0, 0.0, 0.999 * FZ_MIN), FZ_MIN, 1.0)


@pytest.mark.parametrize("law", ["decoupled", "paper"])
def test_controller_taking_over_in_a_fast_climb_asks_for_upright_thrust_at_the_floor(law):
    # Level, at rest in attitude, 0.3 m below the reference and climbing at 2.5 m/s:
    # F_z = -kv 2.5 + kx 0.3 + m g = -75 + 18 + 42.6 = -14.4 N (by hand: pointing down).
    cfg = ControlConfig(observer=False, attitude_law=law)
    ctl = GeometricController(VEH, cfg, (10.0, 20.0, 0.0))
    meas = Measurements((0.0, 0.0, 0.0), (0.0, 0.0, G), (0.0, 0.21, -0.42), (1.0, 2.0, 1.2), (0.0, 0.0, 2.5))
    out = ctl.update(0.0, meas, Reference((1.0, 2.0, 1.5)))
    assert -cfg.kv * 2.5 + cfg.kx * 0.3 + MG < 0.0
    assert ctl.last_limited
    assert out.b3d == pytest.approx((0.0, 0.0, 1.0), abs=1e-12)
    assert out.f_n == pytest.approx(cfg.vertical_thrust_min_fraction * MG, rel=1e-12)
    assert all(math.isfinite(w) for w in out.rate_cmd_flu_rad_s)   # --control rates: same b3d, level
    assert np.allclose(out.rate_cmd_flu_rad_s[:2], 0.0, atol=1e-9)
