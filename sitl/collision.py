"""Crash detection of the SITL (issue 8): the vehicle sphere against the
unknown obstacles and the vine rows, and touchdowns on the terrain.

Pure: positions and velocities in (world ENU, m, m/s), named results out;
the distances come from ``mavcore.geometry`` (the same functions the
companion's flight report uses for its true clearance).

Contacts (obstacles, rows)
--------------------------
Swept: each sensor frame the centre moves along the chord ``p0 -> p1`` (a
4 ms frame at 1 kHz physics deviates from its chord by micrometres), and a
contact is the first point of the chord where the centre's signed distance
to a solid drops to the vehicle radius. The search is conservative
advancement (sphere tracing): the signed distance is 1-Lipschitz, so
stepping along the chord by the current gap never steps over a solid, however
thin, at any speed. A coarse broad phase keeps it cheap at 250 frames a
second: obstacles are bucketed on a 4 m grid by their inflated footprint
(one dictionary lookup per frame), and the rows are skipped while the
distance-transform bound of the grid (one table lookup) exceeds the radius
plus the chord.

Touchdowns (terrain)
--------------------
The plant's landing gear is its centre of mass (``sitl.plant``): a
touchdown is the centre reaching the terrain. It is a crash when faster than
``touchdown_max_down_m_s`` downward or ``touchdown_max_horizontal_m_s``
sideways (``CollisionConfig``), or, when the vehicle was not landing, faster
than ``touchdown_unplanned_max_m_s``. Whether it was landing is the flight
stack's call (``FlightStack.landing_intended``): AUTO.LAND, disarmed or
idling, or an active setpoint that asks for the ground (a position within
``LANDING_SETPOINT_TOL_M`` of the terrain, or a descent without a position).

A crash is reported as a ``CrashEvent``; its ``text`` is the STATUSTEXT the
SITL sends (at most 50 characters, one MAVLink chunk).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mavcore.geometry import Box, Cylinder, SceneGeometry
from mavcore.mission.sim import CollisionConfig

#: Broad-phase bucket edge (m).
BUCKET_M = 4.0
#: Longest chord (m) the buckets are inflated for; longer frames check every obstacle.
MAX_CHORD_M = 1.0
#: A gap below this (m) is contact.
CONTACT_EPS_M = 1e-6
_MAX_ITERS = 200

#: A setpoint this close to the terrain (m) asks for a landing.
LANDING_SETPOINT_TOL_M = 0.2

STATUSTEXT_MAX_CHARS = 50


@dataclass(frozen=True, slots=True)
class Contact:
    """First contact along a chord.

    Attributes
    ----------
    fraction : float
        Where along the chord (0: its start, 1: its end).
    kind : str
        ``"cylinder"``, ``"box"`` or ``"row"``.
    obstacle_index : int or None
        Index in ``sim.obstacles`` (0-based); None for a row.
    """

    fraction: float
    kind: str
    obstacle_index: int | None


@dataclass(frozen=True, slots=True)
class CrashEvent:
    """A crash, as the SITL reports it.

    Attributes
    ----------
    time_us : int
        Vehicle time of the contact (us since boot).
    kind : str
        What was hit: ``"cylinder"``, ``"box"``, ``"row"``, ``"terrain"``, or a
        mover: ``"walker"``, ``"tractor"``.
    obstacle_index : int or None
        Index in ``sim.obstacles`` (0-based; the text numbers from 1); for a
        mover, its index in ``sim.movers``.
    pos_enu_m : tuple (3,)
        Vehicle centre at the contact (world ENU, m).
    vel_enu_m_s : tuple (3,)
        Vehicle velocity at the contact (world ENU, m/s).
    """

    time_us: int
    kind: str
    obstacle_index: int | None
    pos_enu_m: tuple
    vel_enu_m_s: tuple

    @property
    def speed_m_s(self) -> float:
        return math.sqrt(sum(v * v for v in self.vel_enu_m_s))

    @property
    def what(self) -> str:
        """``cylinder #1`` (numbered from 1 in ``sim.obstacles`` order), ``vine row``, ``terrain``."""
        if self.obstacle_index is not None:
            return f"{self.kind} #{self.obstacle_index + 1}"
        return "vine row" if self.kind == "row" else self.kind

    @property
    def text(self) -> str:
        """The STATUSTEXT: ``CRASH: cylinder #1 at E10.00 N3.75 U1.20, 1.02 m/s``
        (vehicle centre, ENU metres on the map; speed at contact), shortened
        (fewer words, then fewer decimals) to fit 50 characters."""
        w = self.what
        for fmt, nd in (("CRASH: {w} at E{x} N{y} U{z}, {v} m/s", 2), ("CRASH: {w} E{x} N{y} U{z} {v}m/s", 2),
                        ("CRASH {w} E{x} N{y} U{z} {v}m/s", 1), ("CRASH {w} E{x} N{y} U{z} {v}m/s", 0)):
            x, y, z, v = (f"{round(c, nd) + 0.0:.{nd}f}" for c in (*self.pos_enu_m, self.speed_m_s))  # no "-0.00"
            t = fmt.format(w=w, x=x, y=y, z=z, v=v)
            if len(t) <= STATUSTEXT_MAX_CHARS:
                return t
        return t[:STATUSTEXT_MAX_CHARS]


def _bound_xy(solid) -> float:
    """Horizontal radius (m) of a solid's footprint about its axis."""
    if isinstance(solid, Cylinder):
        return solid.radius_m
    return math.hypot(solid.half_x_m, solid.half_y_m)


class CollisionMonitor:
    """Swept contacts and touchdown rules for one vehicle sphere in one scene.

    Parameters
    ----------
    scene : SceneGeometry
        Obstacles, rows and terrain (``World.geometry``).
    radius_m : float
        Vehicle sphere radius (``mavcore.mission.sim.vehicle_radius_m``).
    config : CollisionConfig
        Touchdown limits.
    """

    def __init__(self, scene: SceneGeometry, radius_m: float, config: CollisionConfig) -> None:
        self.scene = scene
        self.radius_m = float(radius_m)
        self.config = config
        self._buckets: dict[tuple[int, int], tuple[int, ...]] = {}
        grow = self.radius_m + MAX_CHORD_M
        acc: dict[tuple[int, int], list[int]] = {}
        for k, ob in enumerate(scene.obstacles):
            b = _bound_xy(ob) + grow
            for i in range(math.floor((ob.x_m - b) / BUCKET_M), math.floor((ob.x_m + b) / BUCKET_M) + 1):
                for j in range(math.floor((ob.y_m - b) / BUCKET_M), math.floor((ob.y_m + b) / BUCKET_M) + 1):
                    acc.setdefault((i, j), []).append(k)
        self._buckets = {key: tuple(v) for key, v in acc.items()}
        self._all = tuple(range(len(scene.obstacles)))

    # ------------------------------------------------------------------ contacts
    def sweep(self, p0, p1) -> Contact | None:
        """First contact of the sphere moving its centre along ``p0 -> p1``
        (ENU, m) with an obstacle or a row; None if the chord is clear."""
        x1, y1, z1 = p1
        scene = self.scene
        r = self.radius_m
        x0, y0, z0 = p0
        dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        cand = ()
        if scene.obstacles:
            if length <= MAX_CHORD_M:
                cand = self._buckets.get((math.floor(x1 / BUCKET_M), math.floor(y1 / BUCKET_M)), ())
            else:
                cand = self._all
        rows = scene.rows
        # 1-Lipschitz: no point of the chord is nearer than the bound at p1 minus the chord
        near_rows = rows is not None and rows.any and rows.lower_bound_m(x1, y1, z1) - length <= r
        if not cand and not near_rows:
            return None
        if length > 0.0:
            dx, dy, dz = dx / length, dy / length, dz / length
        best: Contact | None = None
        if cand:
            obs = scene.obstacles

            def f(x, y, z):
                d, k = math.inf, None
                for i in cand:
                    di = obs[i].signed_distance_m(x, y, z)
                    if di < d:
                        d, k = di, i
                return d, k

            hit = self._advance(f, x0, y0, z0, dx, dy, dz, length)
            if hit is not None:
                t, k = hit
                best = Contact(t / length if length > 0 else 0.0,
                               "cylinder" if isinstance(obs[k], Cylinder) else "box", k)
        if near_rows:
            reach = r + length

            def g(x, y, z):
                return rows.signed_distance_m(x, y, z, reach), None

            hit = self._advance(g, x0, y0, z0, dx, dy, dz, length, reach)
            if hit is not None:
                frac = hit[0] / length if length > 0 else 0.0
                if best is None or frac < best.fraction:
                    best = Contact(frac, "row", None)
        return best

    def _advance(self, f, x0, y0, z0, dx, dy, dz, length, give_up_m=math.inf):
        """Conservative advancement of the sphere along the chord; (metres
        along, index) of the first contact or None. ``f`` is 1-Lipschitz;
        a distance above ``give_up_m`` means no contact on this chord."""
        r = self.radius_m
        t = 0.0
        for _ in range(_MAX_ITERS):
            d, k = f(x0 + dx * t, y0 + dy * t, z0 + dz * t)
            if d > give_up_m:
                return None
            gap = d - r
            if gap <= CONTACT_EPS_M:
                return t, k
            t += gap
            if t > length:
                return None
        return t, k   # a chord grazing within micrometres for 200 steps: call it contact

    # ------------------------------------------------------------------ touchdowns
    def touchdown_is_crash(self, vel_enu_m_s, landing: bool) -> bool:
        """Whether a touchdown with the velocity just before it (ENU, m/s) is a
        crash (see the module notes); ``landing``: the vehicle was landing."""
        vx, vy, vz = (float(c) for c in vel_enu_m_s)
        cfg = self.config
        if -vz > cfg.touchdown_max_down_m_s or math.hypot(vx, vy) > cfg.touchdown_max_horizontal_m_s:
            return True
        return not landing and math.sqrt(vx * vx + vy * vy + vz * vz) > cfg.touchdown_unplanned_max_m_s

    # ------------------------------------------------------------------ after a crash
    def rest_height_m(self, x: float, y: float, z: float) -> float:
        """Where a body dropped at (x, y, z) comes to rest (m, ENU z): the
        highest of the terrain and the tops of the obstacles and row cells
        under (x, y) that are not above z."""
        scene = self.scene
        best = scene.height(x, y)
        for ob in scene.obstacles:
            if ob.base_z_m <= z + CONTACT_EPS_M and best < ob.top_z_m <= z + CONTACT_EPS_M:
                if (isinstance(ob, Box) and _inside_box_xy(ob, x, y)) or (
                        isinstance(ob, Cylinder) and math.hypot(x - ob.x_m, y - ob.y_m) <= ob.radius_m):
                    best = ob.top_z_m
        top = scene.rows.top_at_m(x, y) if scene.rows is not None else None
        if top is not None and best < top <= z + CONTACT_EPS_M:
            best = top
        return min(best, z)


def _inside_box_xy(box: Box, x: float, y: float) -> bool:
    c, s = math.cos(box.yaw_rad), math.sin(box.yaw_rad)
    ex, ey = x - box.x_m, y - box.y_m
    return abs(c * ex + s * ey) <= box.half_x_m and abs(-s * ex + c * ey) <= box.half_y_m


def landing_intended(landing_mode: bool, setpoint, ground_z_m: float) -> bool:
    """Whether a touchdown now would be a landing the vehicle asked for.

    Parameters
    ----------
    landing_mode : bool
        The flight stack is landing (AUTO.LAND), disarmed or idling.
    setpoint : Setpoint or None
        The active setpoint (``sitl.onboard.Setpoint``, ENU); None: none.
    ground_z_m : float
        Terrain height under the vehicle (m).
    """
    if landing_mode or setpoint is None:
        return True
    pos = setpoint.pos_enu_m
    z = math.nan if pos is None else float(pos[2])
    if math.isfinite(z):
        return z <= ground_z_m + LANDING_SETPOINT_TOL_M
    vel = setpoint.vel_enu_m_s
    vz = math.nan if vel is None else float(vel[2])
    return not vz > 0.0   # descending, or no vertical demand at all
