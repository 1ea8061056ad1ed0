"""AUTO.MISSION: the stored MISSION_ITEM_INTs flown as position, velocity and
yaw targets for the onboard controller (pure: no I/O, no clock).

``MissionExecutor`` walks the items the way PX4's navigator does
(https://docs.px4.io/main/en/flight_modes_mc/mission.html,
https://docs.px4.io/main/en/flying/missions.html); its one entry point for a
flight-stack personality is ``start(state, seq)`` (then ``update`` every
frame). Items were converted to world ENU once (``NavItem``, built by
``nav_items`` from a converter such as ``mavcore.codec.mission_item_enu``).

=============================  ===============================================
item                           flown as
=============================  ===============================================
NAV_TAKEOFF (22)               climb at MPC_TKO_SPEED where the vehicle is to
                               the item's altitude; reached within
                               NAV_MC_ALT_RAD; param4 yaw (deg from north)
NAV_WAYPOINT (16)              a target point moving along the leg at the
                               mission speed, slowing to the corner speed;
                               reached when the vehicle is within param2
                               (acceptance radius; 0: NAV_ACC_RAD)
                               horizontally and NAV_MC_ALT_RAD vertically;
                               param1 hold time (s); param4 yaw
NAV_LOITER_TIME (19)           a way-point held param1 seconds
NAV_LOITER_UNLIM (17)          a way-point held until the mode changes
NAV_LAND (21)                  fly to the point (none: where it is), descend
                               at MPC_LAND_SPEED; reached on touchdown
NAV_RETURN_TO_LAUNCH (20)      reached at once; the stack enters AUTO.RTL
                               (``rtl_in_mission``, ArduCopter: flown here,
                               climb to RTL_ALT, home at WPNAV_SPEED, land;
                               reached on touchdown)
DO_CHANGE_SPEED (178)          param2 > 0: the mission speed (capped at
                               MPC_XY_VEL_MAX); -1, 0: unchanged; -2: back to
                               MPC_XY_CRUISE
DO_SET_ROI_LOCATION (195)      the nose points at the location from then on
                               (lat = lon = 0: ROI off); DO_SET_ROI_NONE (197)
                               ends it
DO_JUMP (177)                  to item param1, param2 times (-1: for ever),
                               then on past it; resolved when the mission
                               advances, never the current item (PX4)
=============================  ===============================================

Yaw: toward the ROI when one is set, else the item's param4 when finite
(``item_yaw``), else along the leg (PX4 MPC_YAW_MODE 0, ArduCopter
WP_YAW_BEHAVIOR 2). A mission that was landed when started without a
NAV_TAKEOFF first climbs to MIS_TAKEOFF_ALT (PX4; ``implicit_takeoff``).
After the last item the vehicle holds where it is, in the mission mode.

The stack's rules (``mavcore.autopilot.MissionRules``, one per personality)
say what differs: the first item flown (ArduPilot's item 0 is home), whether
param2/param4 are read, and where a RETURN_TO_LAUNCH item is flown.

MISSION_ITEM_REACHED: every item is reported when it completes (DO items at
once), DO_JUMP excepted; ``events`` holds the reached sequence numbers and
``current_changed`` tells the transport to send MISSION_CURRENT.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from mavcore.autopilot import MissionRules

from .onboard import Setpoint

NAV_WAYPOINT = 16
NAV_LOITER_UNLIM = 17
NAV_LOITER_TIME = 19
NAV_RETURN_TO_LAUNCH = 20
NAV_LAND = 21
NAV_TAKEOFF = 22
DO_CHANGE_SPEED = 178
DO_SET_ROI_LOCATION = 195
DO_SET_ROI_NONE = 197
DO_JUMP = 177

#: Items whose completion ArduCopter also announces ("Reached command #N").
ANNOUNCED_COMMANDS = frozenset({NAV_WAYPOINT, NAV_LOITER_TIME})

#: Positional items (the ones with a place to fly to).
NAV_COMMANDS = frozenset({NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TIME, NAV_LAND, NAV_TAKEOFF})
SUPPORTED_COMMANDS = NAV_COMMANDS | {NAV_RETURN_TO_LAUNCH, DO_CHANGE_SPEED, DO_SET_ROI_LOCATION,
                                     DO_SET_ROI_NONE, DO_JUMP}

#: Horizontal deceleration the leg target uses toward a corner (m/s^2); well
#: inside what MPC_TILTMAX_AIR allows (g tan 35 deg = 6.9 m/s^2).
CORNER_DECEL_M_S2 = 2.0

#: PX4 follows at most this many DO_JUMPs in a row without a flown item
#: (a loop of jumps is an invalid mission, not a hang).
MAX_CHAINED_JUMPS = 10


@dataclass(frozen=True, slots=True)
class NavItem:
    """One mission item for the executor: the command, its four params and
    its position in world ENU (m; None for items without one)."""

    seq: int
    command: int
    params: tuple[float, float, float, float]
    pos_enu_m: tuple[float, float, float] | None


@dataclass(frozen=True, slots=True)
class MissionStep:
    """What the mission asks for this frame.

    ``setpoint`` for the onboard controller (None with ``idle``: landed);
    ``action`` "rtl" when a RETURN_TO_LAUNCH item completes, else None."""

    setpoint: Setpoint | None
    idle: bool = False
    action: str | None = None


def nav_items(items: Sequence, item_enu: Callable) -> tuple[NavItem, ...]:
    """Stored ``MissionItem``s -> ``NavItem``s (``item_enu(item)``: ENU or None)."""
    return tuple(NavItem(int(it.seq), int(it.command),
                         (float(it.param1), float(it.param2), float(it.param3), float(it.param4)),
                         item_enu(it) if int(it.command) in NAV_COMMANDS | {DO_SET_ROI_LOCATION} else None)
                 for it in items)


def mission_problem(items: Sequence[NavItem], first_seq: int = 0) -> str | None:
    """Why the mission cannot be flown (the first problem), or None; the items
    before ``first_seq`` (ArduPilot's home) are not flown and not checked."""
    if len(items) <= first_seq:
        return "no mission stored"
    n = len(items)
    for it in items[first_seq:]:
        if it.command not in SUPPORTED_COMMANDS:
            return f"item {it.seq}: command {it.command} is not flown by this SITL"
        if it.command in (NAV_WAYPOINT, NAV_LOITER_TIME, NAV_LOITER_UNLIM, NAV_TAKEOFF) and it.pos_enu_m is None:
            return f"item {it.seq}: no position in a frame this SITL flies"
        if it.command == DO_JUMP:
            target = it.params[0]
            if not (math.isfinite(target) and target == int(target) and first_seq <= target < n
                    and target != it.seq):
                return f"item {it.seq}: DO_JUMP to {target:g}"
    return None


def heading_deg_to_yaw_enu(heading_deg: float) -> float:
    """Compass heading (deg from north, clockwise) -> ENU yaw (rad from east, CCW)."""
    return math.remainder(math.radians(90.0 - heading_deg), 2.0 * math.pi)


def carrot_step(carrot, target, speed_m_s: float, end_speed_m_s: float, dt: float):
    """Move a target point from ``carrot`` toward ``target`` (3D, m) for ``dt`` s.

    Speed: ``speed_m_s``, reduced near the end so that it arrives at
    ``end_speed_m_s`` with CORNER_DECEL_M_S2 (v^2 = v_end^2 + 2 a d).
    Returns (new point [x, y, z] list, velocity (3,) tuple, arrived bool).
    Floats, not arrays: it runs every sensor frame.
    """
    cx, cy, cz = float(carrot[0]), float(carrot[1]), float(carrot[2])
    tx, ty, tz = float(target[0]), float(target[1]), float(target[2])
    dx, dy, dz = tx - cx, ty - cy, tz - cz
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    v = min(speed_m_s, math.sqrt(end_speed_m_s * end_speed_m_s + 2.0 * CORNER_DECEL_M_S2 * dist))
    step = v * dt
    if dist <= max(step, 1e-9):
        return [tx, ty, tz], (0.0, 0.0, 0.0), True
    k, kv = step / dist, v / dist
    return [cx + dx * k, cy + dy * k, cz + dz * k], (dx * kv, dy * kv, dz * kv), False


class MissionExecutor:
    """The mission state machine (see the module docstring).

    Parameters
    ----------
    items : sequence of NavItem
    params : sitl.flightstack.Parameters
        Read live: NAV_ACC_RAD, NAV_MC_ALT_RAD, MPC_XY_CRUISE, MPC_XY_VEL_MAX,
        MPC_TKO_SPEED, MPC_LAND_SPEED, MIS_TAKEOFF_ALT.
    home_enu_m : (3,)
    rules : mavcore.autopilot.MissionRules
        The personality's (default: PX4's).
    """

    def __init__(self, items: Sequence[NavItem], params, home_enu_m, rules: MissionRules = MissionRules()) -> None:
        self.items = tuple(items)
        self.params = params
        self.home_enu_m = np.array(home_enu_m, dtype=float)
        self.rules = rules
        self.current = rules.first_seq
        self.finished = False
        #: Sequence numbers reached since the transport last looked (MISSION_ITEM_REACHED).
        self.events: list[int] = []
        self.current_changed = True
        self._jumps = [0] * len(self.items)
        self._speed = None
        self._roi = None
        self._carrot = [0.0, 0.0, 0.0]        # the moving target point (ENU, m)
        self._leg_start = (0.0, 0.0, 0.0)
        self._leg_dir = (0.0, 0.0)
        self._leg_end_v = 0.0
        self._yaw = 0.0
        self._hold_s = 0.0
        self._landing = False
        self._takeoff_z: float | None = None
        self._entered = False
        self._rtl_z: float | None = None         # in-mission return: its altitude once started

    # ------------------------------------------------------------------ control
    def start(self, state, seq: int | None = None) -> str | None:
        """Fly from item ``seq`` (None: the current one; from 0 again once
        finished), the vehicle being where ``state`` says. Returns why the
        mission cannot be flown, or None."""
        first = self.rules.first_seq
        why = mission_problem(self.items, first)
        if why is not None:
            return why
        if seq is not None:
            if not 0 <= int(seq) < len(self.items):
                return f"no item {int(seq)}"
            self._set_current(max(int(seq), first))
        elif self.finished:
            self._jumps = [0] * len(self.items)
            self._set_current(first)
        self.finished = False
        self.resume(state)
        self._resolve_jumps()
        self._takeoff_z = None
        if (state.landed and self.rules.implicit_takeoff
                and self.items[self.current].command != NAV_TAKEOFF):
            self._takeoff_z = float(self.home_enu_m[2]) + self.params["MIS_TAKEOFF_ALT"]
        return None

    def resume(self, state) -> None:
        """Re-anchor at the vehicle (mode entered again, controller taking over)."""
        self._carrot = [float(v) for v in state.pos_enu_m]
        self._yaw = float(state.yaw_enu_rad)
        self._entered = False
        self._landing = False
        self._rtl_z = None

    def starts_with_takeoff(self, seq: int | None = None) -> bool:
        """The first positional item flown from ``seq`` (None: where ``start``
        would begin) is a NAV_TAKEOFF (ArduPilot's ``starts_with_takeoff_cmd``)."""
        i = (self.rules.first_seq if self.finished else self.current) if seq is None else int(seq)
        for it in self.items[max(i, self.rules.first_seq):]:
            if it.command in NAV_COMMANDS or it.command == NAV_RETURN_TO_LAUNCH:
                return it.command == NAV_TAKEOFF
        return False

    def set_current(self, seq: int) -> bool:
        """MISSION_SET_CURRENT: True if ``seq`` exists."""
        if not 0 <= int(seq) < len(self.items):
            return False
        self._set_current(max(int(seq), self.rules.first_seq))
        self.finished = False
        self._entered = False
        return True

    def _set_current(self, seq: int) -> None:
        if seq != self.current:
            self.current_changed = True
        self.current = seq
        self._entered = False

    @property
    def landing(self) -> bool:
        """Descending on a NAV_LAND item (EXTENDED_SYS_STATE: LANDING)."""
        return self._landing

    def pop_events(self) -> list[int]:
        ev, self.events = self.events, []
        return ev

    # ------------------------------------------------------------------ the tick
    def update(self, state, dt: float) -> MissionStep:
        """Advance to this frame; the targets for the onboard controller."""
        if self._takeoff_z is not None:
            sp = self._climb(state, dt, self._takeoff_z)
            if sp is not None:
                return MissionStep(sp)
            self._takeoff_z = None
        for _ in range(len(self.items) + 1):   # DO items complete in the same frame
            if self.finished:
                return self._finished_step(state)
            it = self.items[self.current]
            step = self._item_step(it, state, dt)
            if step is not None:
                return step
        return self._finished_step(state)

    def _finished_step(self, state) -> MissionStep:
        if state.landed:   # after a NAV_LAND (or re-armed on the ground after one): stay down
            return MissionStep(None, idle=True)
        return MissionStep(self._hold_setpoint())

    def _item_step(self, it: NavItem, state, dt: float) -> MissionStep | None:
        """The step of the current item, or None when it completed at once."""
        c = it.command
        if c == DO_CHANGE_SPEED:
            v = it.params[1]
            if v > 0:
                self._speed = min(v, self.params["MPC_XY_VEL_MAX"])
            elif v == -2:
                self._speed = None
        elif c == DO_SET_ROI_LOCATION:
            self._roi = None if it.pos_enu_m is None else tuple(float(v) for v in it.pos_enu_m)
        elif c == DO_SET_ROI_NONE:
            self._roi = None
        elif c == NAV_RETURN_TO_LAUNCH:
            if self.rules.rtl_in_mission:
                step = self._rtl_step(it, state, dt)
                if step is not None:
                    return step
            else:
                self._complete(it)
                self.finished = True
                return MissionStep(self._hold_setpoint(), action="rtl")
        elif c == NAV_TAKEOFF:
            if not self._entered:
                self._entered = True
                if self.rules.item_yaw and math.isfinite(it.params[3]):
                    self._yaw = heading_deg_to_yaw_enu(it.params[3])
            sp = self._climb(state, dt, it.pos_enu_m[2])
            if sp is not None:
                return MissionStep(sp)
        elif c == NAV_LAND:
            step = self._land_step(it, state, dt)
            if step is not None:
                return step
        else:   # WAYPOINT, LOITER_TIME, LOITER_UNLIM
            step = self._waypoint_step(it, state, dt)
            if step is not None:
                return step
        self._complete(it)
        return None

    def _complete(self, it: NavItem) -> None:
        """``it`` reached: report it, move to the next item (through DO_JUMPs)."""
        self.events.append(it.seq)
        self._entered = False
        self._landing = False
        self._rtl_z = None
        if self.current + 1 >= len(self.items):
            self.finished = True
            return
        self._set_current(self.current + 1)
        self._resolve_jumps()

    def _resolve_jumps(self) -> None:
        for _ in range(MAX_CHAINED_JUMPS):
            it = self.items[self.current]
            if it.command != DO_JUMP:
                return
            i, repeat = self.current, it.params[1]
            if repeat < 0 or self._jumps[i] < repeat:
                self._jumps[i] += 1
                self._set_current(int(it.params[0]))
            elif i + 1 < len(self.items):
                self._set_current(i + 1)
            else:
                self.finished = True
                return
        self.finished = True   # a loop of jumps: stop and hold

    # ------------------------------------------------------------------ items
    def _speed_m_s(self) -> float:
        return self._speed if self._speed is not None else self.params["MPC_XY_CRUISE"]

    def _yaw_toward(self, pos, it: NavItem | None, leg) -> float:
        if self._roi is not None:
            dx, dy = self._roi[0] - pos[0], self._roi[1] - pos[1]
            if math.hypot(dx, dy) > 0.1:
                self._yaw = math.atan2(dy, dx)
            return self._yaw
        if it is not None and self.rules.item_yaw and math.isfinite(it.params[3]):
            self._yaw = heading_deg_to_yaw_enu(it.params[3])
        elif leg is not None and math.hypot(leg[0], leg[1]) > 0.1:
            self._yaw = math.atan2(leg[1], leg[0])
        return self._yaw

    def _hold_setpoint(self) -> Setpoint:
        return Setpoint(tuple(self._carrot), (0.0, 0.0, 0.0), None, self._yaw, None)

    def _climb(self, state, dt: float, z_target: float) -> Setpoint | None:
        """Vertical climb where the vehicle is; None once at ``z_target``."""
        c = self._carrot
        z = float(state.pos_enu_m[2])
        if not state.landed and (z >= z_target or (c[2] >= z_target - 1e-9
                                                   and abs(z - z_target) <= self.params["NAV_MC_ALT_RAD"])):
            c[2] = max(c[2], min(z, z_target)) if z >= z_target else c[2]
            return None
        v = self.params["MPC_TKO_SPEED"]
        climbing = c[2] < z_target
        c[2] = min(c[2] + v * dt, z_target) if climbing else z_target
        yaw = self._yaw_toward(c, None, None) if self._roi is not None else self._yaw
        return Setpoint(tuple(c), (0.0, 0.0, v if climbing else 0.0), None, yaw, None)

    def _end_speed(self, it: NavItem, target) -> float:
        """Speed at which the target point may pass ``target``: the cosine of
        the turn onto the next leg times the mission speed (0 before a stop)."""
        if it.command != NAV_WAYPOINT or it.params[0] > 0:
            return 0.0
        nxt = next((j for j in self.items[self.current + 1:] if j.command in NAV_COMMANDS), None)
        if nxt is None or nxt.command != NAV_WAYPOINT or nxt.pos_enu_m is None:
            return 0.0
        a = np.asarray(target, dtype=float) - np.asarray(self._leg_start)
        b = np.asarray(nxt.pos_enu_m, dtype=float) - np.asarray(target, dtype=float)
        na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
        if na < 1e-6 or nb < 1e-6:
            return 0.0
        return self._speed_m_s() * max(0.0, float(a @ b) / (na * nb))

    def _fly_to(self, it: NavItem, target, state, dt: float) -> tuple[Setpoint, bool]:
        """One frame toward ``target``; (setpoint, vehicle within acceptance)."""
        if not self._entered:   # a new leg: its start and corner speed, once
            self._entered = True
            self._leg_start = tuple(self._carrot)
            self._leg_dir = (target[0] - self._carrot[0], target[1] - self._carrot[1])
            self._hold_s = 0.0
            self._leg_end_v = self._end_speed(it, target)
        self._carrot, vel, _ = carrot_step(self._carrot, target, self._speed_m_s(), self._leg_end_v, dt)
        yaw = self._yaw_toward(state.pos_enu_m, it, self._leg_dir)
        p = state.pos_enu_m
        acc = (it.params[1] if self.rules.item_acceptance and it.command == NAV_WAYPOINT and it.params[1] > 0
               else self.params["NAV_ACC_RAD"])
        inside = (math.hypot(p[0] - target[0], p[1] - target[1]) <= acc
                  and abs(p[2] - target[2]) <= self.params["NAV_MC_ALT_RAD"])
        return Setpoint(tuple(self._carrot), vel, None, yaw, None), inside

    def _waypoint_step(self, it: NavItem, state, dt: float) -> MissionStep | None:
        sp, inside = self._fly_to(it, it.pos_enu_m, state, dt)
        if it.command == NAV_LOITER_UNLIM:
            return MissionStep(sp)
        hold = it.params[0] if it.command in (NAV_WAYPOINT, NAV_LOITER_TIME) else 0.0
        if inside and not (hold > 0):
            return None
        if inside or self._hold_s > 0:
            self._hold_s += dt
            if self._hold_s >= hold:
                return None
        return MissionStep(sp)

    def _land_step(self, it: NavItem, state, dt: float) -> MissionStep | None:
        if not self._landing:
            target = it.pos_enu_m
            if target is None:
                target = (float(state.pos_enu_m[0]), float(state.pos_enu_m[1]), float(self._carrot[2]))
            target = (target[0], target[1], float(self._carrot[2]))   # at the current height first
            sp, inside = self._fly_to(it, target, state, dt)
            arrived = self._carrot[0] == target[0] and self._carrot[1] == target[1]
            if not (inside and arrived):   # descend on the land point itself, as PX4
                return MissionStep(sp)
            self._landing = True
        if state.landed:
            return None
        self._carrot[2] = float(state.pos_enu_m[2])
        yaw = self._yaw_toward(state.pos_enu_m, it, None)
        return MissionStep(Setpoint((self._carrot[0], self._carrot[1], math.nan),
                                    (0.0, 0.0, -self.params["MPC_LAND_SPEED"]), None, yaw, None))

    def _rtl_step(self, it: NavItem, state, dt: float) -> MissionStep | None:
        """RETURN_TO_LAUNCH flown inside the mission mode (ArduCopter's
        ``do_RTL``: ModeRTL run from AUTO): climb to RTL_ALT above home when
        lower, fly home at the return speed (the mission's speed change and
        ROI end), land there; None on touchdown."""
        if self._rtl_z is None:
            self._rtl_z = max(float(state.pos_enu_m[2]), float(self.home_enu_m[2]) + self.params["RTL_RETURN_ALT"])
            self._speed = None
            self._roi = None
        if not self._landing and not self._entered:
            sp = self._climb(state, dt, self._rtl_z)
            if sp is not None:
                return MissionStep(sp)
        home = NavItem(it.seq, NAV_LAND, (0.0, 0.0, 0.0, math.nan), tuple(float(v) for v in self.home_enu_m))
        return self._land_step(home, state, dt)
