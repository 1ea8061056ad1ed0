"""What the companion's rangefinders see, as MAVLink OBSTACLE_DISTANCE (issue 15, deliverable 9).

A real PX4 or ArduPilot then has a second, independent layer: its collision
prevention (PX4 ``CP_DIST``, ``CP_DELAY``, ``CP_GO_NO_DATA``) limits the
setpoint velocity toward each sector; the bundled SITL does the same
(``sitl.collision_prevention``).

The message (MAVLink common, id 330): 72 ``uint16`` distances in cm, sector i
centred ``angle_offset + i * increment`` degrees from forward, clockwise,
in ``MAV_FRAME_BODY_FRD`` (vehicle-front aligned, as PX4 expects from
body-mounted sensors). ``UINT16_MAX``: unknown (no sensor looks there);
``max_distance + 1``: no obstacle. Here ``increment_f = 5``,
``angle_offset = 0`` (sector 0 centred on forward), so the 72 sectors close
the circle.

Packing (``pack_sectors``, pure): each fresh reading of a rangefinder whose
vertical field of view holds the horizontal plane (|elevation of its axis| <=
half its vertical field, and at most ``MAX_ELEVATION_RAD``; a beam looking
below the horizon sees the ground ahead, which PX4's collision prevention
would take for an obstacle: the low ring and the down-looking sensors are not
part of the horizontal picture) fills the sectors whose centres lie within its
horizontal field of view (the nearest one for a beam narrower than a
sector) with its horizontal distance (range x cos(elevation), rounded to
the cm), the smallest where several overlap; a beam with no return fills
them with "no obstacle" (``max_distance + 1``) when its own range is the
message's ``max_distance``, else with its own range (free up to there, no
further claim). Frames: inside, a beam's direction is a body FLU azimuth;
``mavcore.frames.azimuth_flu2frd_deg`` turns it into the message's angle.

Publishing (``ObstacleDistancePublisher``): timed by the vehicle's clock, at
most ``PUBLISH_HZ`` (PX4 expects about 10 Hz), from the readings of the last
``MAX_AGE_S`` (an older reading is no evidence: its sectors are unknown).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mavcore import frames

#: Sectors of OBSTACLE_DISTANCE and their width (deg).
N_SECTORS = 72
INCREMENT_DEG = 5.0
#: OBSTACLE_DISTANCE's "unknown / not used".
UNKNOWN_CM = 65535
#: Messages per second at most (PX4 expects ~10 Hz).
PUBLISH_HZ = 10.0
#: A reading older than this (s of vehicle time) is dropped from the picture.
MAX_AGE_S = 0.5
#: Beams further than this from level are left out, whatever their field (the down-looking ones).
MAX_ELEVATION_RAD = math.radians(30.0)
#: Slack (rad) of the "field holds the horizontal plane" test (a level ray of no field).
LEVEL_EPS_RAD = 1e-9
#: MAV_FRAME_BODY_FRD, MAV_DISTANCE_SENSOR_LASER.
FRAME_BODY_FRD = 12
SENSOR_TYPE_LASER = 0


@dataclass(frozen=True)
class SectorBeam:
    """One reading as the packer sees it.

    Attributes
    ----------
    azimuth_flu_rad : float
        Beam axis in the body's horizontal plane, from body x toward body y (FLU).
    hfov_rad : float
        Full horizontal field of view (0: a ray).
    horizontal_m : float
        Horizontal distance to the return (m); NaN: no return within ``max_m``.
    min_m, max_m : float
        The sensor's limits (m).
    """

    azimuth_flu_rad: float
    hfov_rad: float
    horizontal_m: float
    min_m: float
    max_m: float


@dataclass(frozen=True)
class ObstacleSectors:
    """The message's content (cm, sector 0 forward, clockwise, body FRD).

    Attributes
    ----------
    distances_cm : tuple of 72 int
    min_cm, max_cm : int
        ``min_distance``, ``max_distance``.
    """

    distances_cm: tuple
    min_cm: int
    max_cm: int
    increment_deg: float = INCREMENT_DEG
    angle_offset_deg: float = 0.0


def sector_beam(r) -> SectorBeam | None:
    """A ``SectorBeam`` from a decoded DISTANCE_SENSOR (``mavcore.codec.Range``);
    None for a beam whose vertical field does not hold the horizontal plane (or steeper
    than ``MAX_ELEVATION_RAD``), an unknown mounting, or a reading that is neither a
    range nor "no return" (too close, garbage)."""
    if r.R_flu_sensor is None:
        return None
    bx, by, bz = r.R_flu_sensor[0], r.R_flu_sensor[3], r.R_flu_sensor[6]   # first column: the beam
    level = math.hypot(bx, by)
    half_v = 0.5 * float(r.vfov_rad) if math.isfinite(r.vfov_rad) and r.vfov_rad > 0.0 else 0.0
    elevation = math.atan2(abs(bz), level)
    if not level > 0.0 or elevation > MAX_ELEVATION_RAD or elevation > half_v + LEVEL_EPS_RAD:
        return None
    if not (math.isfinite(r.min_m) and math.isfinite(r.max_m) and 0.0 <= r.min_m < r.max_m):
        return None
    if math.isfinite(r.distance_m):
        d = r.distance_m * level / math.sqrt(level * level + bz * bz)
    elif r.no_return:
        d = math.nan
    else:
        return None
    hfov = float(r.hfov_rad) if math.isfinite(r.hfov_rad) and r.hfov_rad > 0.0 else 0.0
    return SectorBeam(math.atan2(by, bx), hfov, d, float(r.min_m), float(r.max_m))


def pack_sectors(beams) -> ObstacleSectors | None:
    """The 72 sectors from the fresh readings (module docstring); None without any."""
    beams = list(beams)
    if not beams:
        return None
    max_cm = max(int(round(b.max_m * 100.0)) for b in beams)
    min_cm = min(int(round(b.min_m * 100.0)) for b in beams)
    out = np.full(N_SECTORS, UNKNOWN_CM, dtype=np.int64)
    centres = np.arange(N_SECTORS) * INCREMENT_DEG
    for b in beams:
        c = float(frames.azimuth_flu2frd_deg(b.azimuth_flu_rad))
        off = np.abs((centres - c + 180.0) % 360.0 - 180.0)
        hit = off <= 0.5 * math.degrees(b.hfov_rad) + 1e-9
        if not hit.any():
            hit[int(np.argmin(off))] = True
        own_max = int(round(b.max_m * 100.0))
        if math.isnan(b.horizontal_m):
            value = max_cm + 1 if own_max >= max_cm else own_max
        else:
            value = min(max(int(round(b.horizontal_m * 100.0)), 0), max_cm)
        out[hit] = np.minimum(out[hit], value)
    return ObstacleSectors(tuple(int(v) for v in out), min_cm, max_cm)


def encode_obstacle_distance(mav, time_usec: int, sectors: ObstacleSectors):
    """The OBSTACLE_DISTANCE message (pymavlink, ready for ``mav.send``)."""
    return mav.obstacle_distance_encode(int(time_usec), SENSOR_TYPE_LASER, list(sectors.distances_cm),
                                        int(sectors.increment_deg), int(sectors.min_cm), int(sectors.max_cm),
                                        float(sectors.increment_deg), float(sectors.angle_offset_deg),
                                        FRAME_BODY_FRD)


class ObstacleDistancePublisher:
    """Keeps each rangefinder's last usable reading; ``on_range`` returns the sectors
    to send when a message is due (vehicle clock), else None."""

    def __init__(self, rate_hz: float = PUBLISH_HZ, max_age_s: float = MAX_AGE_S) -> None:
        self.period_s = 1.0 / float(rate_hz)
        self.max_age_s = float(max_age_s)
        self._last: dict[int, tuple[float, SectorBeam]] = {}
        self._next_t = -math.inf
        self.sent = 0

    def on_range(self, t_s: float, r) -> ObstacleSectors | None:
        b = sector_beam(r)
        if b is not None:
            self._last[int(r.sensor_id)] = (t_s, b)
        if self._next_t - 2.0 * self.period_s <= t_s < self._next_t:
            return None     # not due (a clock that went back restarts the schedule)
        fresh = [beam for (t, beam) in self._last.values() if 0.0 <= t_s - t <= self.max_age_s]
        sectors = pack_sectors(fresh)
        if sectors is not None:
            self._next_t = t_s + self.period_s - 1e-9
            self.sent += 1
        return sectors
