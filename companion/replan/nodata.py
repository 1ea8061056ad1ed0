"""A horizontal direction with no fresh rangefinder data is blocked (PX4's CP_GO_NO_DATA = 0).

PX4's collision prevention works in the horizontal plane: with
``CP_GO_NO_DATA = 0`` the vehicle does not move toward a direction no
distance sensor has reported on lately. Here, with ENU world / FLU body:

- every DISTANCE_SENSOR that gave evidence (a return, or "no return": the
  beam is clear) refreshes its beam: the vehicle time, the mounting rotation
  sensor -> body FLU and the tangents of its half fields of view;
- a horizontal direction of travel u (ENU, unit) is expressed in the level
  body frame of the current heading (the body x axis projected on the
  horizontal plane; roll and pitch left out, as the pre-flight check
  ``coverage_check`` does, so that a beam of a narrow vertical field still
  counts while the vehicle leans): d = (u . b1, u . b2, 0);
- d has data when some beam refreshed within ``NO_DATA_TIMEOUT_S`` has d in
  its field of view (sensor frame: ``x > 0``, ``|y| <= tan(h/2) x``,
  ``|z| <= tan(v/2) x``);
- a velocity command whose horizontal direction has no data keeps only its
  vertical part (``block_no_data``).

Pure: vehicle times in, no clock, no I/O.
"""

from __future__ import annotations

import math

#: A beam older than this (s, vehicle time) is no data (PX4 drops a range stream after 0.5 s).
NO_DATA_TIMEOUT_S = 0.5
#: Horizontal speeds below this (m/s) have no direction to check.
MIN_SPEED_M_S = 1e-3
_FOV_EPS = 1e-9


class BeamFreshness:
    """The beams that have reported, with the time of their last evidence."""

    def __init__(self) -> None:
        self._beams: dict[int, tuple] = {}

    def __len__(self) -> int:
        return len(self._beams)

    def on_evidence(self, t_s: float, sensor_id: int, R_flu_sensor, hfov_rad: float, vfov_rad: float) -> None:
        """Sensor ``sensor_id`` gave evidence at vehicle time ``t_s`` (``R_flu_sensor``:
        row-major 9-tuple sensor -> body FLU; full fields of view, rad)."""
        self._beams[int(sensor_id)] = (float(t_s), tuple(float(x) for x in R_flu_sensor),
                                       math.tan(0.5 * max(0.0, hfov_rad)), math.tan(0.5 * max(0.0, vfov_rad)))

    def has_data(self, t_s: float, R_enu_flu, u_enu) -> bool:
        """Whether the horizontal direction of ``u_enu`` (ENU, any length) has fresh data.

        ``R_enu_flu``: row-major 9-tuple body FLU -> ENU (the current attitude).
        True for a (near) vertical ``u_enu``: the check is horizontal only.
        """
        ux, uy = float(u_enu[0]), float(u_enu[1])
        h = math.hypot(ux, uy)
        if h < MIN_SPEED_M_S:
            return True
        ux, uy = ux / h, uy / h
        # heading: body x projected on the horizontal plane (column 0 of R)
        fx, fy = R_enu_flu[0], R_enu_flu[3]
        fn = math.hypot(fx, fy)
        if fn < 1e-9:   # body x vertical: take body y for the heading's left
            lx, ly = R_enu_flu[1], R_enu_flu[4]
            ln = math.hypot(lx, ly)
            fx, fy = ly / ln, -lx / ln
        else:
            fx, fy = fx / fn, fy / fn
        # level body frame: b1 = (fx, fy, 0), b2 = e_z x b1 = (-fy, fx, 0)
        d = (ux * fx + uy * fy, -ux * fy + uy * fx, 0.0)
        for t_b, R, th, tv in self._beams.values():
            if t_s - t_b > NO_DATA_TIMEOUT_S:
                continue
            # sensor frame: R^T d
            x = R[0] * d[0] + R[3] * d[1] + R[6] * d[2]
            y = R[1] * d[0] + R[4] * d[1] + R[7] * d[2]
            z = R[2] * d[0] + R[5] * d[1] + R[8] * d[2]
            if x > 0.0 and abs(y) <= (th + _FOV_EPS) * x and abs(z) <= (tv + _FOV_EPS) * x:
                return True
        return False


def block_no_data(v_enu, has_data: bool) -> list:
    """The velocity command (ENU m/s) with its horizontal part removed when its
    direction has no data (CP_GO_NO_DATA = 0); unchanged otherwise."""
    if has_data:
        return [float(v_enu[0]), float(v_enu[1]), float(v_enu[2])]
    return [0.0, 0.0, float(v_enu[2])]
