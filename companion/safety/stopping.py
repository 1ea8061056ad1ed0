"""The stopping law of the guard's speed governance (pure; PX4 collision prevention).

A vehicle moving at ``v`` toward a surface keeps flying at ``v`` for the
sensing and control delay ``tau`` (PX4 ``CP_DELAY``), then brakes at the
acceleration limit ``a``: it stops after

    s(v) = v tau + v^2 / (2 a).

It must stop before the clearance, so with ``room = d - required`` (the
distance from the vehicle's centre to the surface minus the airframe radius
and the clearance, PX4 ``CP_DIST``) the largest allowed approach speed solves
``s(v) = room``, the positive root of ``v^2 / (2 a) + v tau - room = 0``:

    v_max = sqrt(2 a room + (a tau)^2) - a tau,      v_max = 0 for room <= 0.
"""

from __future__ import annotations

import numpy as np


def stopping_distance_m(speed_m_s, accel_m_s2: float, delay_s: float):
    """Distance (m) flown from ``speed_m_s`` until at rest: ``v tau + v^2 / (2 a)``
    (scalar or array)."""
    v = np.maximum(np.asarray(speed_m_s, dtype=float), 0.0)
    out = v * delay_s + v * v / (2.0 * accel_m_s2)
    return float(out) if out.ndim == 0 else out


def stopping_speed_m_s(room_m, accel_m_s2: float, delay_s: float):
    """Largest speed (m/s) toward a surface that stops within ``room_m`` (module doc;
    0 where ``room_m <= 0``; scalar or array)."""
    r = np.maximum(np.asarray(room_m, dtype=float), 0.0)
    at = accel_m_s2 * delay_s
    out = np.sqrt(2.0 * accel_m_s2 * r + at * at) - at
    return float(out) if out.ndim == 0 else out
