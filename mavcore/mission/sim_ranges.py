"""Physical ranges of the ``sim:`` parameters, checked when a mission is loaded.

A value can be finite and well-typed and still make no sense for a small
quadrotor in a vineyard (a 1e308 m/s wind overflows the drag force mid-flight;
a zero magnetic field leaves the magnetometer direction undefined). Each
numeric ``sim`` key has a range here; vectors are checked by their
Euclidean norm where the norm is the physical quantity (wind speed, field
strength), else component by component. ``[]`` stands for every item of a list.

=================================  ==============  ========  =====================================
key                                range           unit      why
=================================  ==============  ========  =====================================
seed                               [0, 2^63 - 1]             numpy seeds are non-negative
canopy_height_m                    (0, 20]         m         vine canopies are 1-3 m
magnetic_field_enu_gauss           [0.2, 0.7]      gauss     norm; Earth's surface field 0.22-0.67 G
start_enu_m                        [-1e6, 1e6]     m         each; the SITL checks it is on the map
obstacles[].x, obstacles[].y       [-1e6, 1e6]     m
obstacles[].height                 (0, 100]        m
obstacles[].radius                 [0, 50]         m
obstacles[].size_x, size_y         [0, 500]        m
obstacles[].yaw_deg                [-360, 360]     deg
movers[].speed_m_s                 (0, 5]          m/s       a walker at most 1.5 (checked by type)
movers[].start_s                   [0, 1e6]        s         vehicle clock
noise.vector_variance              [0, 1]                    per component of a unit vector
noise.gyro_variance                [0, 1]          (rad/s)^2
noise.position_std_m               [0, 10]         m
noise.velocity_std_m_s             [0, 10]         m/s
noise.gyro_bias_rad_s              [-1, 1]         rad/s     each; MEMS gyro biases are < 0.1 rad/s
noise.accel_bias_m_s2              [-5, 5]         m/s^2     each
noise.range_std_m                  [0, 5]          m
noise.range_dropout_probability    [0, 1]
noise.*_noise_density_*            [0, 0.1] / [0, 1]         gyro rad/s/sqrt(Hz) / accel m/s^2/sqrt(Hz)
noise.*_bias_turn_on_std_*         [0, 1] / [0, 5]           rad/s / m/s^2
noise.*_bias_walk_*                [0, 0.1] / [0, 1]         rad/s/sqrt(s) / m/s^2/sqrt(s)
noise.mag_noise_std_gauss          [0, 1]          gauss
noise.mag_hard_iron_gauss          [-2, 2]         gauss     each
noise.mag_thrust_gauss_per_n       [-0.1, 0.1]     gauss/N   each
noise.position_z_std_m             [0, 10]         m
noise.gnss_rate_hz                 (0, 1000]       Hz
noise.gnss_latency_s               [0, 1)          s         (the upper bound excluded by NoiseConfig)
collision.vehicle_radius_m         (0, 10]         m
collision.touchdown_*_m_s          [0, 20]         m/s
rangefinders[].id                  [0, 255]
rangefinders[].orientation         [0, 255]                  (MAV_SENSOR_ORIENTATION, see sim.py)
rangefinders[].min_m               [0, 10]         m
rangefinders[].max_m               (0, 655]        m         DISTANCE_SENSOR carries uint16 cm
rangefinders[].position_flu_m      [-10, 10]       m         each
rangefinders[].rotation_flu_deg    [-360, 360]     deg       each
rangefinders[].hfov_deg, vfov_deg  [0, 180]        deg
rangefinders[].rate_hz             (0, 1000]       Hz
wind.mean_enu_m_s                  [0, 30]         m/s       norm; 30 m/s is a violent storm
wind.gust_std_m_s                  [0, 15]         m/s
wind.gust_time_constant_s          (0, 3600]       s
wind.drag_n_s_m                    [0, 10]         N s/m     a 1-2 kg quadrotor: ~0.1-0.5
=================================  ==============  ========  =====================================
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Range:
    """An interval (``lo_open``: lo excluded) in ``unit``; ``norm``: check a vector's norm."""

    lo: float
    hi: float
    unit: str = ""
    lo_open: bool = False
    norm: bool = False

    def holds(self, x: float) -> bool:
        return (x > self.lo if self.lo_open else x >= self.lo) and x <= self.hi

    def text(self) -> str:
        u = f" {self.unit}" if self.unit else ""
        return f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}]{u}"


SIM_RANGES: dict[str, Range] = {
    "seed": Range(0, 2**63 - 1),
    "canopy_height_m": Range(0, 20, "m", lo_open=True),
    "magnetic_field_enu_gauss": Range(0.2, 0.7, "gauss", norm=True),
    "start_enu_m": Range(-1e6, 1e6, "m"),
    "obstacles[].x": Range(-1e6, 1e6, "m"),
    "obstacles[].y": Range(-1e6, 1e6, "m"),
    "obstacles[].height": Range(0, 100, "m", lo_open=True),
    "obstacles[].radius": Range(0, 50, "m"),
    "obstacles[].size_x": Range(0, 500, "m"),
    "obstacles[].size_y": Range(0, 500, "m"),
    "obstacles[].yaw_deg": Range(-360, 360, "deg"),
    "movers[].speed_m_s": Range(0, 5, "m/s", lo_open=True),
    "movers[].start_s": Range(0, 1e6, "s"),
    "noise.vector_variance": Range(0, 1),
    "noise.gyro_variance": Range(0, 1, "(rad/s)^2"),
    "noise.position_std_m": Range(0, 10, "m"),
    "noise.velocity_std_m_s": Range(0, 10, "m/s"),
    "noise.gyro_bias_rad_s": Range(-1, 1, "rad/s"),
    "noise.accel_bias_m_s2": Range(-5, 5, "m/s^2"),
    "noise.range_std_m": Range(0, 5, "m"),
    "noise.range_dropout_probability": Range(0, 1),
    "noise.gyro_noise_density_rad_s_rthz": Range(0, 0.1, "rad/s/sqrt(Hz)"),
    "noise.accel_noise_density_m_s2_rthz": Range(0, 1, "m/s^2/sqrt(Hz)"),
    "noise.gyro_bias_turn_on_std_rad_s": Range(0, 1, "rad/s"),
    "noise.accel_bias_turn_on_std_m_s2": Range(0, 5, "m/s^2"),
    "noise.gyro_bias_walk_rad_s_rts": Range(0, 0.1, "rad/s/sqrt(s)"),
    "noise.accel_bias_walk_m_s2_rts": Range(0, 1, "m/s^2/sqrt(s)"),
    "noise.mag_noise_std_gauss": Range(0, 1, "gauss"),
    "noise.mag_hard_iron_gauss": Range(-2, 2, "gauss"),
    "noise.mag_thrust_gauss_per_n": Range(-0.1, 0.1, "gauss/N"),
    "noise.position_z_std_m": Range(0, 10, "m"),
    "noise.gnss_rate_hz": Range(0, 1000, "Hz", lo_open=True),
    "noise.gnss_latency_s": Range(0, 1, "s"),
    "collision.vehicle_radius_m": Range(0, 10, "m", lo_open=True),
    "collision.touchdown_max_down_m_s": Range(0, 20, "m/s"),
    "collision.touchdown_max_horizontal_m_s": Range(0, 20, "m/s"),
    "collision.touchdown_unplanned_max_m_s": Range(0, 20, "m/s"),
    "rangefinders[].id": Range(0, 255),
    "rangefinders[].orientation": Range(0, 255),
    "rangefinders[].min_m": Range(0, 10, "m"),
    "rangefinders[].max_m": Range(0, 655, "m", lo_open=True),   # DISTANCE_SENSOR carries uint16 cm
    "rangefinders[].position_flu_m": Range(-10, 10, "m"),
    "rangefinders[].rotation_flu_deg": Range(-360, 360, "deg"),
    "rangefinders[].quaternion_flu_wxyz": Range(-1e3, 1e3),
    "rangefinders[].hfov_deg": Range(0, 180, "deg"),
    "rangefinders[].vfov_deg": Range(0, 180, "deg"),
    "rangefinders[].rate_hz": Range(0, 1000, "Hz", lo_open=True),
    "wind.mean_enu_m_s": Range(0, 30, "m/s", norm=True),
    "wind.gust_std_m_s": Range(0, 15, "m/s"),
    "wind.gust_time_constant_s": Range(0, 3600, "s", lo_open=True),
    "wind.drag_n_s_m": Range(0, 10, "N s/m"),
}


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def numeric_keys(obj, prefix: str = ""):
    """(key, value) of every numeric leaf of a (nested) config dataclass;
    a vector (tuple of numbers) is one leaf; list items share the key ``name[]``."""
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        key = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(v):
            yield from numeric_keys(v, key + ".")
        elif isinstance(v, tuple) and v and all(dataclasses.is_dataclass(x) for x in v):
            for item in v:
                yield from numeric_keys(item, key + "[].")
        elif _is_number(v) or (isinstance(v, tuple) and v and all(_is_number(x) for x in v)):
            yield key, v


def check_sim_ranges(sim) -> None:
    """Raise ValueError naming the first ``sim.<key>`` outside its physical range.

    Parameters
    ----------
    sim : SimConfig
    """
    for key, value in numeric_keys(sim):
        r = SIM_RANGES.get(key)
        if r is None:
            raise ValueError(f"sim.{key}: no physical range is defined (mavcore/mission/sim_ranges.py)")
        if isinstance(value, tuple):
            vals = [math.hypot(*(float(x) for x in value))] if r.norm else [float(x) for x in value]
        else:
            vals = [float(value)]
        for x in vals:
            if not (math.isfinite(x) and r.holds(x)):
                what = f"norm {x:g}" if r.norm else f"{x:g}"
                raise ValueError(f"sim.{key} = {what} is outside the physical range {r.text()}")
