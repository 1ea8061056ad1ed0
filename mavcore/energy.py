"""Vehicle energy model: electrical power from the rotor thrusts, battery, plan energy (pure).

Rotor power (actuator-disk momentum theory with a figure of merit)
    A rotor of disk area ``A = pi r^2`` producing thrust ``T`` in air of
    density ``rho`` needs the ideal induced power ``T^(3/2) / sqrt(2 rho A)``
    in hover (Leishman, *Principles of Helicopter Aerodynamics*, eq. 2.22).
    The figure of merit ``FM`` (ideal over actual rotor power; 0.5-0.7 for
    small rotors) adds the profile losses, and the drive efficiency ``eta``
    (motor and ESC) turns shaft power into battery power:

        P_rotor(T) = T^(3/2) / (sqrt(2 rho A) FM eta).

    Hover: four rotors at ``T = m g / 4`` plus the avionics. In level flight
    at speed ``V`` the induced velocity ``v_i`` drops below the hover value
    ``v_h = sqrt(T / (2 rho A))`` (Glauert: ``v_i^4 + V^2 v_i^2 = v_h^4``),
    and the body's parasite drag ``1/2 rho CdA V^2`` costs ``1/2 rho CdA V^3``:

        P_cruise(V) = P_hover v_i / v_h + 1/2 rho CdA V^3 / eta + P_avionics.

    Climbing adds ``m g w / eta`` at vertical speed ``w`` (potential energy);
    nothing is recovered descending. With the defaults (the paper's 4.34 kg
    vehicle, 15-inch rotors r = 0.19 m, FM 0.6, eta 0.8, 15 W avionics) hover
    takes about 565 W and 1 m/s cruise about 560 W.
Battery
    ``battery_voltage_v`` x ``battery_capacity_ah`` (default 6S 22.2 V,
    10 Ah: 222 Wh); a sortie may use it down to ``reserve_fraction``
    (default 25 %), so 166 Wh are planned: about 17 min of flight.
Plan energy
    The way-point timing (``coverage.waypoints``) gives each leg's duration
    and length; a leg flown in ``dt`` over a horizontal distance ``d`` and
    a climb ``dz`` costs ``P_cruise(d / dt) dt + m g max(dz, 0) / eta``.
    Take-off and landing are a climb and a descent of the flight height at
    ``climb_speed_m_s`` (hover power, plus the climb's potential energy).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from .vehicle import GRAVITY_M_S2, VehicleConfig


@dataclass(frozen=True)
class EnergyConfig:
    """Mission key ``energy``: battery, rotor aerodynamics, sortie limits.

    Attributes
    ----------
    battery_capacity_ah, battery_voltage_v : float
        Nominal pack capacity (Ah) and voltage (V).
    reserve_fraction : float
        Share of the capacity a sortie must leave unused.
    rotor_radius_m, figure_of_merit, drive_efficiency : float
        Momentum-theory rotor model (module doc).
    drag_area_m2 : float
        Parasite drag area CdA (m^2).
    avionics_power_w : float
    air_density_kg_m3 : float
    climb_speed_m_s : float
        Vertical speed of take-off and landing (m/s).
    internal_resistance_ohm : float
        Pack resistance, for the SITL's terminal voltage.
    max_mission_items : int
        Most mission items the vehicle stores (the bundled SITL: 2000); each
        sortie's mission (take-off, speed, ROI, way-points, RTL) fits in it.
    launch_xy_m : (x, y) or None
        Where every sortie starts and ends (ENU map frame, m); None: the
        admissible point nearest to the centroid of the free cells (so no
        corridor is more than about half the field away).
    split : {"auto", "none"}
        ``none`` keeps the whole plan as one sortie (and says if it does not fit).
    """

    battery_capacity_ah: float = 10.0
    battery_voltage_v: float = 22.2
    reserve_fraction: float = 0.25
    rotor_radius_m: float = 0.19
    figure_of_merit: float = 0.6
    drive_efficiency: float = 0.8
    drag_area_m2: float = 0.03
    avionics_power_w: float = 15.0
    air_density_kg_m3: float = 1.225
    climb_speed_m_s: float = 0.5
    internal_resistance_ohm: float = 0.02
    max_mission_items: int = 2000
    launch_xy_m: tuple[float, float] | None = None
    split: Literal["auto", "none"] = "auto"

    def __post_init__(self) -> None:
        for name in ("battery_capacity_ah", "battery_voltage_v", "rotor_radius_m", "air_density_kg_m3",
                     "climb_speed_m_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"energy.{name} must be > 0")
        if not 0 <= self.reserve_fraction < 1:
            raise ValueError("energy.reserve_fraction must be in [0, 1)")
        for name in ("figure_of_merit", "drive_efficiency"):
            if not 0 < getattr(self, name) <= 1:
                raise ValueError(f"energy.{name} must be in (0, 1]")
        for name in ("drag_area_m2", "avionics_power_w", "internal_resistance_ohm"):
            if getattr(self, name) < 0:
                raise ValueError(f"energy.{name} must be >= 0")
        if self.max_mission_items < 8:
            raise ValueError("energy.max_mission_items must be at least 8")
        if self.launch_xy_m is not None and not all(math.isfinite(v) for v in self.launch_xy_m):
            raise ValueError("energy.launch_xy_m must be finite")

    @property
    def battery_wh(self) -> float:
        return self.battery_capacity_ah * self.battery_voltage_v

    @property
    def usable_wh(self) -> float:
        return self.battery_wh * (1.0 - self.reserve_fraction)

    @property
    def disk_area_m2(self) -> float:
        """Area of one rotor disk (m^2)."""
        return math.pi * self.rotor_radius_m ** 2


def rotor_power_w(thrust_n, cfg: EnergyConfig):
    """Electrical power (W) of rotors at thrust ``thrust_n`` (N, scalar or array), hover form."""
    t = np.maximum(np.asarray(thrust_n, dtype=float), 0.0)
    return t ** 1.5 / (math.sqrt(2.0 * cfg.air_density_kg_m3 * cfg.disk_area_m2)
                       * cfg.figure_of_merit * cfg.drive_efficiency)


def hover_power_w(vehicle: VehicleConfig, cfg: EnergyConfig) -> float:
    """Battery power (W) to hover: four rotors at m g / 4, plus the avionics."""
    return float(4.0 * rotor_power_w(vehicle.mass_kg * GRAVITY_M_S2 / 4.0, cfg)) + cfg.avionics_power_w


def cruise_power_w(speed_m_s, vehicle: VehicleConfig, cfg: EnergyConfig):
    """Battery power (W) in level flight at ``speed_m_s`` (scalar or array; module doc)."""
    v = np.asarray(speed_m_s, dtype=float)
    thrust = vehicle.mass_kg * GRAVITY_M_S2 / 4.0
    v_h2 = thrust / (2.0 * cfg.air_density_kg_m3 * cfg.disk_area_m2)          # v_h^2
    v_i = np.sqrt((-v * v + np.sqrt(v ** 4 + 4.0 * v_h2 ** 2)) / 2.0)          # Glauert, level flight
    rotors = 4.0 * float(rotor_power_w(thrust, cfg)) * v_i / math.sqrt(v_h2)
    drag = 0.5 * cfg.air_density_kg_m3 * cfg.drag_area_m2 * v ** 3 / cfg.drive_efficiency
    return rotors + drag + cfg.avionics_power_w


@dataclass(frozen=True)
class EnergyEstimate:
    """Energy (Wh) and time (s) of a flight, and the powers used (W)."""

    duration_s: float
    energy_wh: float
    hover_power_w: float
    mean_power_w: float


def leg_energy_j(t_s: np.ndarray, p_enu_m: np.ndarray, vehicle: VehicleConfig, cfg: EnergyConfig) -> np.ndarray:
    """(N - 1,) energy (J) of each leg between consecutive way-points (module doc)."""
    t = np.asarray(t_s, dtype=float)
    p = np.asarray(p_enu_m, dtype=float)
    dt = np.diff(t)
    d = np.hypot(*np.diff(p[:, :2], axis=0).T)
    dz = np.diff(p[:, 2])
    speed = np.where(dt > 0, d / np.maximum(dt, 1e-9), 0.0)
    weight = vehicle.mass_kg * GRAVITY_M_S2
    return cruise_power_w(speed, vehicle, cfg) * dt + weight * np.maximum(dz, 0.0) / cfg.drive_efficiency


def flight_energy(t_s: np.ndarray, p_enu_m: np.ndarray, height_agl_m: float, vehicle: VehicleConfig,
                  cfg: EnergyConfig) -> EnergyEstimate:
    """Energy of flying the way-points (times ``t_s`` (N,), positions (N, 3) ENU m)
    plus a take-off and a landing of ``height_agl_m`` (module doc)."""
    t = np.asarray(t_s, dtype=float)
    weight = vehicle.mass_kg * GRAVITY_M_S2
    legs_j = float(np.sum(leg_energy_j(t, p_enu_m, vehicle, cfg)))
    p_hover = hover_power_w(vehicle, cfg)
    t_vertical = 2.0 * height_agl_m / cfg.climb_speed_m_s
    vertical_j = p_hover * t_vertical + weight * height_agl_m / cfg.drive_efficiency
    duration = float(t[-1] - t[0]) + t_vertical
    energy_wh = (legs_j + vertical_j) / 3600.0
    return EnergyEstimate(duration_s=duration, energy_wh=energy_wh, hover_power_w=p_hover,
                          mean_power_w=energy_wh * 3600.0 / duration if duration > 0 else p_hover)
