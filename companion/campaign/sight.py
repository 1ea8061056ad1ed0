"""How long each moving obstacle had been in the vehicle's line of sight when it came
closest (campaign columns ``mover_in_sight_s``, ``mover_sighted_m``).

A worker who steps out of a vine row within the vehicle's stopping distance cannot
be avoided by any rangefinder: the canopy hides them until then. A campaign that
draws walkers across the rows flies some such encounters, and a crash there says
nothing about the avoidance. This figure tells them apart from the ones the
companion should have avoided: it is measured on the simulator's truth, after the
flight, from the recorded track (ODOMETRY) and the mission's geometry.

Line of sight. At vehicle time t the vehicle's centre ``p`` (the SITL's true
position) sees mover k when the segment from ``p`` to the point of the mover's
solid nearest ``p`` (``mavcore.movers.mover_solid``: a walker a vertical
cylinder, a tractor a box) meets no row (extruded to the canopy), no static
obstacle (``sim.obstacles``) and no terrain, and that point is within the
rangefinders' reach (the longest ``max_m`` of ``sim.rangefinders``, the default
suite's ring otherwise). The segment is marched on the scene's signed distances
(sphere tracing, exact for 1-Lipschitz distances): a distance below ``HIT_M``
before the last ``END_M`` of the segment is an occluder. Other movers do not
occlude.

Figures per mover, from samples every ``PERIOD_S`` of vehicle time:

- ``min_clearance_m``: the vehicle sphere's smallest sampled clearance to it, and
  ``t_s`` when;
- ``in_sight_s``: how long it had been in sight without a break at that moment (0
  when hidden then);
- ``sighted_m``: the clearance when that sight began (None when hidden).

A vehicle at v m/s braking at a_b after a lag t_l needs about v^2 / (2 a_b) + v t_l
of room to stop (``docs/replan.md``); a mover first seen closer than that, or in
sight for less than the time the vehicle needs to stop, met a vehicle that could
not have stopped for it.
"""

from __future__ import annotations

import math

import numpy as np

from mavcore.geometry import Box, Cylinder, SceneGeometry, terrain_distance_m
from mavcore.movers import mover_pose, mover_solid

#: Vehicle time (s) between two samples of the track.
PERIOD_S = 0.1
#: A signed distance (m) below this along the segment is an occluder.
HIT_M = 1e-3
#: The last part (m) of the segment, at the mover's surface, is not tested.
END_M = 0.05
#: Sphere-tracing steps before a segment is taken as clear (a grazing ray; in sight is
#: the answer that never calls a crash unavoidable that was not).
MAX_STEPS = 256


def nearest_point(solid, px: float, py: float, pz: float) -> tuple[float, float, float]:
    """The point of a ``Cylinder`` or ``Box`` (``mavcore.geometry``) nearest (px, py, pz)
    (the point itself when inside)."""
    if isinstance(solid, Cylinder):
        dx, dy = px - solid.x_m, py - solid.y_m
        r = math.hypot(dx, dy)
        s = solid.radius_m / r if r > solid.radius_m else 1.0
        return solid.x_m + s * dx, solid.y_m + s * dy, min(max(pz, solid.base_z_m), solid.top_z_m)
    if isinstance(solid, Box):
        c, s = math.cos(solid.yaw_rad), math.sin(solid.yaw_rad)
        dx, dy = px - solid.x_m, py - solid.y_m
        u = min(max(c * dx + s * dy, -solid.half_x_m), solid.half_x_m)
        w = min(max(-s * dx + c * dy, -solid.half_y_m), solid.half_y_m)
        return solid.x_m + c * u - s * w, solid.y_m + s * u + c * w, min(max(pz, solid.base_z_m), solid.top_z_m)
    raise TypeError(f"no nearest point for {type(solid).__name__}")


def _occluder_distance(scene: SceneGeometry, x: float, y: float, z: float) -> float:
    d = terrain_distance_m(x, y, z, scene.height)
    if scene.rows is not None:
        d = min(d, scene.rows.signed_distance_m(x, y, z, max_m=d))
    for ob in scene.obstacles:
        d = min(d, ob.signed_distance_m(x, y, z))
    return d


def line_of_sight(scene: SceneGeometry, p, q) -> bool:
    """True when the segment p -> q (ENU m) meets no row, static obstacle or terrain
    before its last ``END_M`` (module doc)."""
    px, py, pz = (float(c) for c in p)
    dx, dy, dz = float(q[0]) - px, float(q[1]) - py, float(q[2]) - pz
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    if length <= END_M:
        return True
    ux, uy, uz = dx / length, dy / length, dz / length
    s = 0.0
    for _ in range(MAX_STEPS):
        if s >= length - END_M:
            return True
        d = _occluder_distance(scene, px + s * ux, py + s * uy, pz + s * uz)
        if d < HIT_M:
            return False
        s += d
    return True


def mover_sight(movers, scene: SceneGeometry, t_s: np.ndarray, pos_enu_m: np.ndarray, radius_m: float,
                reach_m: float) -> list[dict]:
    """The figures of the module doc for each mover (``sim.movers``), from the vehicle's
    true track: ``t_s`` (n,) vehicle time (s, increasing) and ``pos_enu_m`` (n, 3)."""
    t_s = np.asarray(t_s, dtype=float)
    pos = np.asarray(pos_enu_m, dtype=float).reshape(-1, 3)
    out = []
    for cfg in movers:
        best = None
        since = sighted = None
        last = None
        for t, p in zip(t_s.tolist(), pos.tolist()):
            k = math.floor(t / PERIOD_S + 1e-9)      # the first sample of each period (no drift)
            if k == last:
                continue
            last = k
            pose = mover_pose(cfg, t)
            solid = mover_solid(cfg, pose, float(scene.height(pose.x_m, pose.y_m)))
            c = solid.signed_distance_m(*p) - radius_m
            q = nearest_point(solid, *p)
            seen = math.dist(p, q) <= reach_m and line_of_sight(scene, p, q)
            if not seen:
                since = sighted = None
            elif since is None:
                since, sighted = t, c
            if best is None or c < best["min_clearance_m"]:
                best = {"min_clearance_m": c, "t_s": t, "in_sight_s": 0.0 if since is None else t - since,
                        "sighted_m": sighted}
        out.append(best or {"min_clearance_m": None, "t_s": None, "in_sight_s": None, "sighted_m": None})
    return out


def track_of(tlog_path) -> tuple[np.ndarray, np.ndarray]:
    """The vehicle's true track in a .tlog: (t_s (n,), ENU positions (n, 3)) of the SITL's
    ODOMETRY (system 1, component 1; NED there, ENU here)."""
    from mavcore.frames import ned2enu
    from ..link.tlog import read_tlog

    t, p = [], []
    for r in read_tlog(tlog_path):
        m = r.msg
        if m.get_type() == "ODOMETRY" and m.get_srcSystem() == 1 and m.get_srcComponent() == 1:
            t.append(m.time_usec * 1e-6)
            p.append(ned2enu((m.x, m.y, m.z)))
    return np.asarray(t, dtype=float), np.asarray(p, dtype=float).reshape(-1, 3)


def flight_sight(mission, track) -> dict | None:
    """The campaign's columns for a flight with movers: the figures of the mover that came
    closest (``mover_in_sight_s``, ``mover_sighted_m``); None without movers or track.
    ``track``: the flight's true track (``track_of``)."""
    sim = mission.sim
    if sim is None or not sim.movers:
        return None
    from mavcore.geometry import scene_from_maps
    from mavcore.maps.field import load_mission_maps
    from mavcore.maps.heightfield import HeightField
    from mavcore.mission.sim import default_rangefinders, vehicle_radius_m

    t, p = track
    if not len(t):
        return None
    grid, dem = load_mission_maps(mission)
    scene = scene_from_maps(grid, dem, tuple(sim.obstacles), sim.canopy_height_m)
    if dem is not None:      # the scalar lookup: the sight marches one point at a time
        scene = SceneGeometry(scene.obstacles, scene.rows, HeightField(dem))
    reach = max(rf.max_m for rf in (sim.rangefinders or default_rangefinders()))
    figs = [f for f in mover_sight(sim.movers, scene, t, p, vehicle_radius_m(sim, mission.vehicle.arm_m), reach)
            if f["min_clearance_m"] is not None]
    if not figs:
        return None
    f = min(figs, key=lambda f: f["min_clearance_m"])
    return {"mover_in_sight_s": round(f["in_sight_s"], 3),
            "mover_sighted_m": None if f["sighted_m"] is None else round(f["sighted_m"], 3)}
