"""The simulated battery: drains with the power the rotors draw (pure, no clock).

Power: the same momentum-theory rotor model the planner uses
(``mavcore.energy.rotor_power_w``) applied to each rotor's actual thrust,
plus the avionics. The pack is ``n`` LiPo cells (``n = round(V_nominal /
3.7 V)``) whose open-circuit voltage falls linearly from 4.2 V to 3.5 V per
cell with the state of charge, behind the pack resistance ``R``: drawing
power ``P`` takes the current ``I = (V_oc - sqrt(V_oc^2 - 4 R P)) / (2 R)``
(from ``P = (V_oc - I R) I``), the terminal voltage is ``V_oc - I R``, and the
charge falls by ``I dt``. An empty pack stays at 0 % (the SITL keeps
flying; the report is what matters here).
"""

from __future__ import annotations

import math

from mavcore.energy import EnergyConfig

CELL_FULL_V = 4.2
CELL_EMPTY_V = 3.5
CELL_NOMINAL_V = 3.7


class Battery:
    """State of the simulated pack.

    Attributes
    ----------
    cells : int
    remaining : float
        State of charge, 0..1.
    voltage_v, current_a : float
        Terminal voltage and current of the last step.
    consumed_ah, consumed_wh : float
        Charge and energy drawn from the cells so far.
    """

    def __init__(self, cfg: EnergyConfig) -> None:
        self.cfg = cfg
        self.cells = max(1, round(cfg.battery_voltage_v / CELL_NOMINAL_V))
        self._k = 1.0 / (math.sqrt(2.0 * cfg.air_density_kg_m3 * cfg.disk_area_m2)
                         * cfg.figure_of_merit * cfg.drive_efficiency)
        self.remaining = 1.0
        self.consumed_ah = 0.0
        self.consumed_wh = 0.0
        self.current_a = 0.0
        self.voltage_v = self.open_circuit_v

    @property
    def open_circuit_v(self) -> float:
        return self.cells * (CELL_EMPTY_V + (CELL_FULL_V - CELL_EMPTY_V) * self.remaining)

    def power_w(self, thrusts_n) -> float:
        """Battery power (W) for rotor thrusts (N, any number of rotors) plus the avionics."""
        k = self._k
        return sum(k * f ** 1.5 for f in thrusts_n if f > 0.0) + self.cfg.avionics_power_w

    def drain(self, thrusts_n, dt_s: float) -> None:
        """Draw the power of ``thrusts_n`` for ``dt_s`` seconds."""
        p = self.power_w(thrusts_n)
        v_oc = self.open_circuit_v
        r = self.cfg.internal_resistance_ohm
        disc = v_oc * v_oc - 4.0 * r * p
        if r <= 0.0:
            i = p / v_oc
        elif disc >= 0.0:
            i = (v_oc - math.sqrt(disc)) / (2.0 * r)
        else:       # more than the pack can deliver: it gives its maximum power
            i = v_oc / (2.0 * r)
        self.current_a = i
        self.voltage_v = v_oc - i * r
        self.consumed_ah += i * dt_s / 3600.0
        self.consumed_wh += v_oc * i * dt_s / 3600.0
        self.remaining = max(0.0, 1.0 - self.consumed_ah / self.cfg.battery_capacity_ah)
