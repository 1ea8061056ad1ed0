"""The SITL's flight-stack shell: arming, PX4-style modes, setpoint
generation for takeoff/land/hold/return, offboard and actuator-stream
freshness and failsafes. It reads its parameters from a
``mavcore.services.params.Parameters`` store; the parameter and mission
protocols themselves are ``mavcore.services``.

Pure: no sockets, no clock. Everything is timed by the vehicle time handed
in (``now_us``); the transport (``sitl.server``) turns MAVLink messages into
calls here and the results back into MAVLink. World ENU, SI units; the
MAVLink codec (``mavcore.codec``) does every NED/wire-unit conversion.

Modes (PX4 main/sub modes, ``custom_mode = main << 16 | sub << 24``)
--------------------------------------------------------------------
=============  ==========  ====================================================
mode           main/sub    behaviour here
=============  ==========  ====================================================
MANUAL         1/0         no RC exists: behaves as POSCTL with centred sticks
POSCTL         3/0         holds the position where it was entered
AUTO.TAKEOFF   4/2         climbs at MPC_TKO_SPEED to the takeoff altitude,
                           then AUTO.LOITER at that point
AUTO.LOITER    4/3         holds a point (Hold); the boot mode
AUTO.MISSION   4/4         flies the stored mission (``sitl.mission_exec``);
                           entered by the mode change or MAV_CMD_MISSION_START;
                           DENIED without a flyable mission
AUTO.RTL       4/5         climbs to RTL_RETURN_ALT above home if lower, flies
                           at MPC_XY_CRUISE to the closest of home and the rally
                           points (``sitl.rally``), then AUTO.LAND
AUTO.LAND      4/6         descends at MPC_LAND_SPEED holding x, y
OFFBOARD       6/0         tracks SET_POSITION_TARGET_LOCAL_NED, or the body
                           rates and thrust of SET_ATTITUDE_TARGET with its
                           inner rate loop (``sitl.rate_control``) while they
                           are the newer kind; entry needs a setpoint stream
                           already present (PX4 rule)
=============  ==========  ====================================================

Other PX4 modes (ALTCTL, ACRO, STABILIZED, ...) are refused with DENIED.

Failsafes (announced by STATUSTEXT)
-----------------------------------
- Actuator stream: HIL_ACTUATOR_CONTROLS override the onboard controller
  while armed and fresh (received within COM_HIL_TMO of vehicle time). When
  the stream goes stale the onboard controller takes over with the current
  mode's setpoint, re-anchored where the vehicle is (hold where it is; an
  OFFBOARD stream that is still fresh keeps being tracked).
- Offboard loss: in OFFBOARD, no setpoint for COM_OF_LOSS_T -> AUTO.LOITER
  (hold where it is) for COM_FAIL_ACT_T, then COM_OBL_ACT (0 land, 1 keep
  holding, 2 return). A mode change by the user ends the failsafe.
- Geofence (``sitl.fence``, uploaded as MAV_MISSION_TYPE_FENCE): armed and
  in the air, leaving the allowed area triggers GF_ACTION once per breach
  (0 none, 1 warning, 2 AUTO.LOITER where it is, 3 AUTO.RTL, 4 flight
  termination is not simulated: AUTO.LAND, 5 AUTO.LAND); arming outside it
  is refused.
- Landing: landed for COM_DISARM_LAND after having flown -> disarm; armed on
  the ground without taking off for COM_DISARM_PRFLT -> disarm (PX4).

Crash (issue 8; the simulation detects it, ``sitl.collision``)
-------------------------------------------------------------
``crash(now_us, event)``: STATUSTEXT CRITICAL ``event.text`` ("CRASH:
cylinder #1 at E10.00 N3.75 U1.20, 1.02 m/s"), the motors are cut (the
output is "disarmed" from then on), HEARTBEAT ``system_status`` is
MAV_STATE_EMERGENCY until the stack is rebuilt, the vehicle is disarmed
("Disarmed (crashed)") once it has come to rest, and arming, take-off,
landing, return and mode changes are refused (DENIED, "... denied:
crashed"). A disarm request is accepted at any time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from mavcore.codec import RateSetpoint
from mavcore.autopilot import PX4_AUTOPILOT, READ_ONLY_PARAMS, Autopilot, ParamSpec  # noqa: F401 (re-exported)
from mavcore.services.params import Parameters  # noqa: F401 (re-exported)

from .collision import CrashEvent, landing_intended
from .fence import Fence
from .mission_exec import MissionExecutor, carrot_step
from .onboard import Setpoint
from .rally import return_destination

# MAVLink enum values used by the stack (named once, from the common dialect).
RESULT_ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
RESULT_TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
RESULT_DENIED = mavlink.MAV_RESULT_DENIED
RESULT_UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED
RESULT_FAILED = mavlink.MAV_RESULT_FAILED

SEVERITY_CRITICAL = mavlink.MAV_SEVERITY_CRITICAL
SEVERITY_WARNING = mavlink.MAV_SEVERITY_WARNING
SEVERITY_NOTICE = mavlink.MAV_SEVERITY_NOTICE
SEVERITY_INFO = mavlink.MAV_SEVERITY_INFO

PARAM_TYPE_REAL32 = mavlink.MAV_PARAM_TYPE_REAL32
PARAM_TYPE_INT32 = mavlink.MAV_PARAM_TYPE_INT32

#: Normalised motor command while armed on the ground (props spinning, no lift).
IDLE_MOTOR_CMD = 0.05

#: Horizontal acceptance radius of the return leg (m).
RTL_ACCEPT_RADIUS_M = 0.5

#: Largest tilt (rad) at which arming is allowed without force.
ARM_MAX_TILT_RAD = math.radians(30.0)



class FlightMode(Enum):
    """PX4 flight modes the SITL knows, valued (main_mode, sub_mode)."""

    MANUAL = (1, 0)
    POSCTL = (3, 0)
    TAKEOFF = (4, 2)
    LOITER = (4, 3)
    MISSION = (4, 4)
    RTL = (4, 5)
    LAND = (4, 6)
    OFFBOARD = (6, 0)

    @property
    def main(self) -> int:
        return self.value[0]

    @property
    def sub(self) -> int:
        return self.value[1]

    @classmethod
    def from_px4(cls, main_mode: int, sub_mode: int) -> "FlightMode | None":
        """The mode of a PX4 (main, sub) pair; None if unknown.

        MANUAL, POSCTL and OFFBOARD ignore the sub mode (PX4 sends 0).
        """
        for m in cls:
            if m.main == main_mode and (m.main != 4 and m.sub == 0 or m.sub == sub_mode):
                return m
        return None

    @property
    def label(self) -> str:
        """PX4's name of the mode (``FlightStack.label`` names it for the stack flown)."""
        return {1: "MANUAL", 3: "POSCTL", 6: "OFFBOARD"}.get(self.main) or f"AUTO.{self.name}"


def _has_mode(autopilot: Autopilot, mode: "FlightMode") -> bool:
    try:
        autopilot.wire_mode(mode.name)
        return True
    except KeyError:
        return False


# --- parameters ---------------------------------------------------------------


#: The PX4 parameter set (``mavcore.autopilot.px4``): PX4 names where PX4 has
#: the parameter; SIM_* are the simulator's own (noise and lockstep), applied
#: by ``sitl.server``. Inside the stack parameters are read by these names,
#: in SI units, whatever the personality (``Parameters`` aliases).
PARAM_SPECS: tuple[ParamSpec, ...] = PX4_AUTOPILOT.param_specs


# --- the flight stack ----------------------------------------------------------


@dataclass(frozen=True, slots=True)
class NavState:
    """What the flight stack knows of the vehicle (world ENU, SI).

    Attributes
    ----------
    pos_enu_m, vel_enu_m_s : (3,)
    yaw_enu_rad : float
        Heading of body x (from east, CCW).
    tilt_rad : float
        Angle between body z and world z.
    landed : bool
        Ground contact (the SITL's land detector is the plant's contact flag).
    """

    pos_enu_m: np.ndarray
    vel_enu_m_s: np.ndarray
    yaw_enu_rad: float
    tilt_rad: float
    landed: bool


@dataclass(frozen=True, slots=True)
class CommandResult:
    """A command's MAV_RESULT and, when refused, why."""

    result: int
    reason: str = ""

    @property
    def accepted(self) -> bool:
        return self.result == RESULT_ACCEPTED


@dataclass(frozen=True, slots=True)
class StatusEvent:
    """A STATUSTEXT to announce (MAV_SEVERITY, text)."""

    severity: int
    text: str


@dataclass(frozen=True, slots=True)
class StackOutput:
    """What drives the motors this frame.

    Attributes
    ----------
    armed : bool
        False: motors stopped.
    motor_override : tuple of 4 float, or None
        Fresh HIL_ACTUATOR_CONTROLS: fly exactly these.
    idle : bool
        Armed on the ground with no climb demanded: ``IDLE_MOTOR_CMD``.
    setpoint : Setpoint or None
        Otherwise the onboard controller tracks this.
    reset_controller : bool
        The onboard controller takes over now: clear its integrators first.
    rates : RateSetpoint or None
        OFFBOARD on attitude-rate setpoints: the inner rate loop flies these
        (``setpoint`` is then the mode's position setpoint, for telemetry).
    """

    armed: bool
    motor_override: tuple | None
    idle: bool
    setpoint: Setpoint | None
    reset_controller: bool
    rates: RateSetpoint | None = None


_DISARMED_OUTPUT = StackOutput(False, None, False, None, False)


@dataclass(frozen=True, slots=True)
class ReceivedTarget:
    """An offboard setpoint and its vehicle receive time."""

    setpoint: Setpoint
    time_us: int


def setpoint_from_target(target) -> Setpoint:
    """``codec.PositionTarget`` (per-axis NaN) -> onboard ``Setpoint``
    (an all-NaN group becomes None)."""

    def group(v):
        return None if np.all(np.isnan(v)) else v

    return Setpoint(group(target.pos_enu_m), group(target.vel_enu_m_s), group(target.acc_enu_m_s2),
                    target.yaw_enu_rad, target.yaw_rate_enu_rad_s)


@dataclass
class _Anchor:
    """Where the current mode's setpoint is anchored (mutable, internal)."""

    pos: np.ndarray = field(default_factory=lambda: np.zeros(3))
    yaw: float = 0.0
    z_ref: float = 0.0
    target_z: float = 0.0
    phase: int = 0
    dest: np.ndarray = field(default_factory=lambda: np.zeros(3))   # where AUTO.RTL goes
    dest_rally: bool = False


class FlightStack:
    """PX4-like flight-stack state machine (see the module docstring).

    Parameters
    ----------
    params : Parameters
    home_enu_m : (3,)
        Home (takeoff and return point): the vehicle's start position.
    """

    def __init__(self, params: Parameters, home_enu_m, autopilot: Autopilot = PX4_AUTOPILOT) -> None:
        self.params = params
        self.autopilot = autopilot
        self.home_enu_m = np.array(home_enu_m, dtype=float)
        #: HEARTBEAT custom_mode and name of each behaviour under this personality.
        self._wire = {m: autopilot.wire_mode(m.name) for m in FlightMode if _has_mode(autopilot, m)}
        rule = autopilot.offboard_loss
        #: The mode held after an offboard loss (PX4: Hold; ArduCopter: GUIDED itself).
        self._loss_hold_mode = FlightMode[rule.leave_to] if rule.leave_to is not None else FlightMode.OFFBOARD
        self._by_command = autopilot.takeoff_by_command
        self.mode = FlightMode[autopilot.mode(autopilot.boot_mode).behaviour]
        self.armed = False
        self.events: list[StatusEvent] = []
        self._now_us = 0
        self._last_update_us: int | None = None
        self._anchor = _Anchor(self.home_enu_m.copy())
        self._need_anchor = True
        self._hold_sp: Setpoint | None = None
        self._offboard: ReceivedTarget | None = None
        self._rates: RateSetpoint | None = None
        self._rates_time_us = -(1 << 62)
        #: Setpoints received before this vehicle time are not flown (ArduCopter
        #: GUIDED drops its target on entry and at the end of a take-off).
        self._offboard_min_us = -(1 << 62)
        self._act_cmd: tuple | None = None
        self._act_time_us = -(1 << 62)
        self._override_active = False
        self._failsafe: str | None = None
        self._failsafe_t0_us = 0
        self._armed_t_us = 0
        self._airborne_since_arm = False
        self._landed_since_us: int | None = None
        self._land_announced = False
        self._takeoff_z: float | None = None
        self._state: NavState | None = None
        self._params_version = -1        # freshness limits (us), cached per parameter version
        self._hil_tmo_us = self._of_loss_us = 0.0
        self._out: StackOutput | None = None   # last output, reused while unchanged
        self.crash_event: CrashEvent | None = None
        #: What the transport stored (``sitl.server``): the mission to fly in
        #: AUTO.MISSION, the geofence and the rally points (ENU).
        self.mission: MissionExecutor | None = None
        self.fence: Fence | None = None
        self.rally_points: tuple = ()
        #: The vehicle is outside the geofence now (SYS_STATUS geofence health).
        self.fence_breached = False
        self._goto: tuple | None = None          # DO_REPOSITION: (target (3,), speed m/s, yaw)
        #: ArduCopter's ``auto_armed``: the mission's take-off may leave the ground
        #: (``MissionRules.auto_armed``; released by a GUIDED take-off or MISSION_START).
        self._auto_armed = False

    # ------------------------------------------------------------------ info
    @property
    def custom_mode(self) -> int:
        return self._wire[self.mode].custom_mode

    def label(self, mode: FlightMode) -> str:
        """The mode's name as the stack's tools print it ("AUTO.LOITER", "GUIDED")."""
        return self._wire[mode].name

    def mode_of(self, custom_mode: int) -> "FlightMode | None":
        """The behaviour of a SET_MODE/DO_SET_MODE ``custom_mode``; None: unknown or refused."""
        m = self.autopilot.decode_mode(custom_mode)
        return None if m is None or m.behaviour is None else FlightMode[m.behaviour]

    @property
    def crashed(self) -> bool:
        return self.crash_event is not None

    @property
    def system_status(self) -> int:
        if self.crash_event is not None:
            return mavlink.MAV_STATE_EMERGENCY
        if self._failsafe is not None:
            return mavlink.MAV_STATE_CRITICAL
        return mavlink.MAV_STATE_ACTIVE if self.armed else mavlink.MAV_STATE_STANDBY

    @property
    def landed_state(self) -> int:
        s = self._state
        if s is None or s.landed or not self.armed:
            return mavlink.MAV_LANDED_STATE_ON_GROUND
        if self.crash_event is not None:
            return mavlink.MAV_LANDED_STATE_IN_AIR   # falling
        if self.mode is FlightMode.TAKEOFF:
            return mavlink.MAV_LANDED_STATE_TAKEOFF
        if self.mode is FlightMode.LAND or (self.mode is FlightMode.MISSION and self.mission is not None
                                            and self.mission.landing):
            return mavlink.MAV_LANDED_STATE_LANDING
        return mavlink.MAV_LANDED_STATE_IN_AIR

    @property
    def override_active(self) -> bool:
        return self._override_active

    @property
    def failsafe(self) -> str | None:
        """Name of the active failsafe ("offboard") or None."""
        return self._failsafe

    def _limits(self) -> None:
        p = self.params
        self._params_version = p.version
        self._of_loss_us = p["COM_OF_LOSS_T"] * 1e6
        self._hil_tmo_us = p["COM_HIL_TMO"] * 1e6

    def offboard_fresh(self, now_us: int) -> bool:
        """A setpoint arrived within COM_OF_LOSS_T."""
        r = self._offboard
        if self._params_version != self.params.version:
            self._limits()
        return (r is not None and now_us - r.time_us <= self._of_loss_us
                or now_us - self._rates_time_us <= self._of_loss_us)

    def rates_active(self, now_us: int) -> bool:
        """OFFBOARD flies the attitude-rate setpoint: one arrived within
        COM_OF_LOSS_T and no position setpoint since (the newer kind wins, as
        PX4's offboard control mode follows the last setpoint message)."""
        r = self._offboard
        return (self._rates is not None and self.offboard_fresh(now_us)
                and now_us - self._rates_time_us <= self._of_loss_us
                and (r is None or r.time_us <= self._rates_time_us))

    def actuators_fresh(self, now_us: int) -> bool:
        if self._params_version != self.params.version:
            self._limits()
        return self._act_cmd is not None and now_us - self._act_time_us <= self._hil_tmo_us

    def pop_events(self) -> list[StatusEvent]:
        ev, self.events = self.events, []
        return ev

    def _say(self, severity: int, text: str) -> None:
        self.events.append(StatusEvent(severity, text))

    def crash(self, now_us: int, event: CrashEvent) -> None:
        """The vehicle crashed (see the module notes)."""
        if self.crash_event is not None:
            return
        self.crash_event = event
        self._failsafe = None
        self._override_active = False
        self._say(SEVERITY_CRITICAL, event.text)

    def _denied_crashed(self, what: str) -> CommandResult:
        self._say(SEVERITY_CRITICAL, f"{what} denied: crashed")
        return CommandResult(RESULT_DENIED, "crashed")

    def landing_intended(self, ground_z_m: float) -> bool:
        """Whether a touchdown now would be a landing asked for: disarmed,
        AUTO.LAND, idling, or an active setpoint at the ground
        (``sitl.collision.landing_intended``)."""
        o = self._out
        landing_mode = not self.armed or self.mode is FlightMode.LAND or o is None or o.idle
        return landing_intended(landing_mode, None if o is None else o.setpoint, ground_z_m)

    # ------------------------------------------------------------------ inputs
    def offboard_setpoint(self, now_us: int, target) -> None:
        """Record a decoded SET_POSITION_TARGET_LOCAL_NED (``codec.PositionTarget``)."""
        self._offboard = ReceivedTarget(setpoint_from_target(target), int(now_us))

    def rate_setpoint(self, now_us: int, sp: RateSetpoint) -> None:
        """Record a decoded SET_ATTITUDE_TARGET body-rate setpoint (``sitl.rate_control``)."""
        self._rates = sp
        self._rates_time_us = int(now_us)

    def actuator_controls(self, now_us: int, motor_cmd) -> None:
        """Record HIL_ACTUATOR_CONTROLS motor commands (4 floats in [0, 1]); None
        (a lockstep tick without commands) records nothing."""
        if motor_cmd is not None:
            self._act_cmd = motor_cmd if type(motor_cmd) is tuple else tuple(motor_cmd)
            self._act_time_us = int(now_us)

    # ------------------------------------------------------------------ commands
    def arm(self, now_us: int, state: NavState, force: bool = False) -> CommandResult:
        """MAV_CMD_COMPONENT_ARM_DISARM(1). ``force``: param2 == 21196."""
        if self.crash_event is not None:
            return self._denied_crashed("Arming")
        if self.armed:
            return CommandResult(RESULT_ACCEPTED)
        if not force:
            reason = self._prearm_failure(now_us, state)
            if reason:
                self._say(SEVERITY_CRITICAL, f"Arming denied: {reason}")
                return CommandResult(RESULT_DENIED, reason)
        self.armed = True
        self._armed_t_us = int(now_us)
        self._airborne_since_arm = not state.landed
        self._landed_since_us = int(now_us) if state.landed else None
        self._land_announced = False
        self._state = state
        self._enter(self.mode, state, announce=False)
        self._say(SEVERITY_INFO, "Armed" + (" (forced)" if force else "") + f" in {self.label(self.mode)}")
        return CommandResult(RESULT_ACCEPTED)

    def _prearm_failure(self, now_us: int, state: NavState) -> str:
        if not state.landed:
            return "not landed"
        if state.tilt_rad > ARM_MAX_TILT_RAD:
            return "vehicle not level"
        if self.mode in (FlightMode.LAND, FlightMode.RTL):
            return f"not armable in {self.label(self.mode)}"
        if (self.mode is FlightMode.OFFBOARD and self.autopilot.offboard_needs_stream
                and not self.offboard_fresh(now_us)):
            return "no offboard setpoint stream"
        if self.mode is FlightMode.MISSION and self.mission is None:
            return "no mission"
        if (self.mode is FlightMode.MISSION and self.autopilot.mission_rules.auto_armed
                and not int(self.params["AUTO_OPTIONS"]) & 1):
            return "Mode not armable"        # ArduCopter ModeAuto::allows_arming (AUTO_OPTIONS bit 0)
        if self.fence is not None and self.fence.breached(state.pos_enu_m[0], state.pos_enu_m[1]):
            return "vehicle outside geofence"
        return ""

    def disarm(self, now_us: int, state: NavState, force: bool = False, why: str = "") -> CommandResult:
        """MAV_CMD_COMPONENT_ARM_DISARM(0): refused in the air unless forced."""
        if not self.armed:
            return CommandResult(RESULT_ACCEPTED)
        if not state.landed and not force and self.crash_event is None:
            self._say(SEVERITY_CRITICAL, "Disarming denied: not landed")
            return CommandResult(RESULT_DENIED, "not landed")
        self.armed = False
        self._auto_armed = False
        self._override_active = False
        self._failsafe = None
        self._say(SEVERITY_INFO, "Disarmed" + (f" ({why})" if why else " (forced)" if force else ""))
        return CommandResult(RESULT_ACCEPTED)

    def set_mode(self, now_us: int, state: NavState, mode: FlightMode | None) -> CommandResult:
        """DO_SET_MODE / SET_MODE with a PX4 custom mode (None: unknown)."""
        if mode is None:
            return CommandResult(RESULT_DENIED, "unknown or unsupported mode")
        if self.crash_event is not None:
            return self._denied_crashed("Mode change")
        if mode is FlightMode.MISSION:
            return self.start_mission(now_us, state, None)
        if mode is FlightMode.OFFBOARD and self.autopilot.offboard_needs_stream and not self.offboard_fresh(now_us):
            self._say(SEVERITY_WARNING, "Offboard denied: no setpoint stream")
            return CommandResult(RESULT_TEMPORARILY_REJECTED, "no offboard setpoint stream")
        if mode is FlightMode.RTL and (not self.armed or state.landed):
            return CommandResult(RESULT_DENIED, "return needs a flying vehicle")
        if mode is FlightMode.TAKEOFF:
            return self.takeoff(now_us, state, None)
        if mode is self.mode and self._failsafe is None:
            return CommandResult(RESULT_ACCEPTED)
        self._failsafe = None
        self._enter(mode, state)
        return CommandResult(RESULT_ACCEPTED)

    def takeoff(self, now_us: int, state: NavState, target_z_enu_m: float | None) -> CommandResult:
        """MAV_CMD_NAV_TAKEOFF: climb to ``target_z_enu_m`` (None, or not above
        home: home + MIS_TAKEOFF_ALT; more than 150 m above home: DENIED). In the
        air below the vehicle: its own height (PX4 does not descend for a take-off).
        The parameters were checked by ``mavcore.link.command_rules`` first.

        Disarmed: switches to AUTO.TAKEOFF; arming then takes off (PX4).
        """
        if self.crash_event is not None:
            return self._denied_crashed("Takeoff")
        if self.autopilot.takeoff_by_command and not (self.armed and state.landed
                                                      and self.mode is FlightMode.OFFBOARD):
            # ArduCopter: a take-off needs the motors armed, in GUIDED, on the ground.
            why = "not armed" if not self.armed else "not landed" if not state.landed else \
                f"not in {self.autopilot.offboard_mode}"
            self._say(SEVERITY_WARNING, f"Takeoff refused: {why}")
            return CommandResult(RESULT_FAILED, why)
        home_z = float(self.home_enu_m[2])
        z_min = home_z + self.params["MIS_TAKEOFF_ALT"]
        z = z_min if target_z_enu_m is None else float(target_z_enu_m)
        if not math.isfinite(z) or z > home_z + 150.0:
            return CommandResult(RESULT_DENIED, "takeoff altitude out of range")
        if z <= home_z:
            # Not above home (e.g. param7 = 0, or a relative altitude sent
            # where PX4 expects AMSL): PX4 takes off to its minimum takeoff
            # altitude with a warning rather than refusing.
            self._say(SEVERITY_WARNING, f"Using minimum takeoff altitude: {z_min - home_z:.2f} m")
            z = z_min
        z_now = float(state.pos_enu_m[2])
        if self.armed and not state.landed and z < z_now:
            # In the air below where it is: PX4's navigator does not go down.
            self._say(SEVERITY_WARNING, "Already higher than takeoff altitude (not descending)")
            z = z_now
        self._takeoff_z = z
        self._failsafe = None
        self._auto_armed = self.armed       # ArduCopter Mode::do_user_takeoff: set_auto_armed(true)
        self._enter(FlightMode.TAKEOFF, state)
        return CommandResult(RESULT_ACCEPTED)

    def land(self, now_us: int, state: NavState) -> CommandResult:
        """MAV_CMD_NAV_LAND: AUTO.LAND where the vehicle is."""
        if self.crash_event is not None:
            return self._denied_crashed("Land")
        self._failsafe = None
        self._enter(FlightMode.LAND, state)
        return CommandResult(RESULT_ACCEPTED)

    def return_to_launch(self, now_us: int, state: NavState) -> CommandResult:
        """MAV_CMD_NAV_RETURN_TO_LAUNCH."""
        return self.set_mode(now_us, state, FlightMode.RTL)

    def start_mission(self, now_us: int, state: NavState, seq: int | None) -> CommandResult:
        """AUTO.MISSION from item ``seq`` (None: the current one): the mode
        change and MAV_CMD_MISSION_START. The one entry point a personality
        calls to fly the stored mission (``MissionExecutor.start``)."""
        if self.crash_event is not None:
            return self._denied_crashed("Mission")
        if (self.mission is not None and not self.autopilot.mission_rules.implicit_takeoff and self.armed
                and state.landed and not self.mission.starts_with_takeoff(seq)):
            # ArduCopter ModeAuto::init: armed on the ground, the first command must be a take-off
            self._say(SEVERITY_CRITICAL, "Auto: Missing Takeoff Cmd")
            return CommandResult(RESULT_DENIED, "missing takeoff command")
        why = "no mission stored" if self.mission is None else self.mission.start(state, seq)
        if why:
            self._say(SEVERITY_WARNING, f"Mission denied: {why}")
            return CommandResult(RESULT_DENIED, why)
        self._failsafe = None
        self._enter(FlightMode.MISSION, state, resume=False)
        return CommandResult(RESULT_ACCEPTED)

    def mission_start_command(self, now_us: int, state: NavState, first: float, last: float) -> CommandResult:
        """MAV_CMD_MISSION_START (param1 first item, param2 last item; NaN: unset).

        PX4: AUTO.MISSION from item ``first``. ArduCopter
        (GCS_MAVLINK_Copter::handle_MAV_CMD_MISSION_START): first/last other
        than 0 DENIED; AUTO as by the mode change (FAILED when that is
        refused), and the take-off released (``auto_armed``).
        """
        if not self.autopilot.mission_rules.auto_armed:
            return self.start_mission(now_us, state, None if math.isnan(first) else int(first))
        if any(math.isfinite(v) and v != 0 for v in (first, last)):
            return CommandResult(RESULT_DENIED, "first/last item not supported")
        r = self.set_mode(now_us, state, FlightMode.MISSION) if self.mode is not FlightMode.MISSION \
            else CommandResult(RESULT_ACCEPTED)
        if not r.accepted:
            return CommandResult(RESULT_FAILED, r.reason)
        self._auto_armed = self.armed
        return r

    def set_mission(self, mission: MissionExecutor | None, state: NavState | None) -> None:
        """A new stored mission (None: none). Flying the old one, the vehicle
        holds where it is (AUTO.LOITER), as after any mission change."""
        self.mission = mission
        if self.mode is FlightMode.MISSION and state is not None:
            self._enter(FlightMode.LOITER, state)
            self._say(SEVERITY_WARNING, "Mission changed: holding")

    def reposition(self, now_us: int, state: NavState, target_enu_m, speed_m_s: float,
                   yaw_enu_rad: float | None) -> CommandResult:
        """MAV_CMD_DO_REPOSITION: AUTO.LOITER, flying to ``target_enu_m`` at
        ``speed_m_s`` (<= 0: MPC_XY_CRUISE) and holding there (PX4's Hold)."""
        if self.crash_event is not None:
            return self._denied_crashed("Reposition")
        if not self.armed or state.landed:
            return CommandResult(RESULT_DENIED, "reposition needs a flying vehicle")
        self._failsafe = None
        self._enter(FlightMode.LOITER, state)
        v = speed_m_s if speed_m_s > 0 else self.params["MPC_XY_CRUISE"]
        yaw = self._anchor.yaw if yaw_enu_rad is None else float(yaw_enu_rad)
        self._goto = (np.array(target_enu_m, dtype=float), min(v, self.params["MPC_XY_VEL_MAX"]), yaw)
        return CommandResult(RESULT_ACCEPTED)

    # ------------------------------------------------------------------ modes
    def _enter(self, mode: FlightMode, state: NavState, announce: bool = True, resume: bool = True) -> None:
        changed = self._wire[mode] is not self._wire[self.mode]
        if mode is FlightMode.OFFBOARD and changed and self.autopilot.offboard_loss.leave_to is None:
            self._offboard_min_us = self._now_us   # GUIDED starts holding where it is
        self.mode = mode
        self._anchor_at(state, resume=resume)
        self._land_announced = False
        if announce and changed:
            self._say(SEVERITY_INFO, f"Mode {self.label(mode)}")

    def _anchor_at(self, state: NavState, hold_pos=None, resume: bool = True) -> None:
        """Anchor the mode's setpoint at the vehicle (or at ``hold_pos``)."""
        a = self._anchor
        self._goto = None
        if resume and self.mode is FlightMode.MISSION and self.mission is not None:
            self.mission.resume(state)
        a.pos = np.array(state.pos_enu_m if hold_pos is None else hold_pos, dtype=float)
        a.yaw = float(state.yaw_enu_rad)
        a.z_ref = float(state.pos_enu_m[2])
        a.phase = 0
        if self.mode is FlightMode.TAKEOFF:
            a.target_z = self._takeoff_z if self._takeoff_z is not None else (
                float(self.home_enu_m[2]) + self.params["MIS_TAKEOFF_ALT"])
        elif self.mode is FlightMode.RTL:
            a.target_z = max(float(state.pos_enu_m[2]),
                             float(self.home_enu_m[2]) + self.params["RTL_RETURN_ALT"])
            dest, a.dest_rally = return_destination(state.pos_enu_m, self.home_enu_m, self.rally_points)
            a.dest = np.array(dest, dtype=float)
        self._hold_sp = Setpoint(a.pos.copy(), np.zeros(3), None, a.yaw, None)

    # ------------------------------------------------------------------ the tick
    def update(self, now_us: int, state: NavState) -> StackOutput:
        """Advance the state machine to ``now_us`` and say what flies the vehicle."""
        now_us = int(now_us)
        dt = 0.0 if self._last_update_us is None else max(0.0, (now_us - self._last_update_us) * 1e-6)
        self._last_update_us = now_us
        self._now_us = now_us
        self._state = state
        p = self.params
        if self.fence is not None:   # also disarmed: SYS_STATUS reports the fence's health
            self._check_fence(state)

        if not self.armed:
            self._override_active = False
            return _DISARMED_OUTPUT
        if self.crash_event is not None:
            # motors cut; disarmed once at rest
            if state.landed:
                self.disarm(now_us, state, force=True, why="crashed")
            return _DISARMED_OUTPUT

        # --- landed bookkeeping and auto-disarm
        if state.landed:
            if self._landed_since_us is None:
                self._landed_since_us = now_us
            landed_s = (now_us - self._landed_since_us) * 1e-6
            if self._airborne_since_arm:
                t = p["COM_DISARM_LAND"]
                if t > 0 and landed_s >= t:
                    self.disarm(now_us, state, why="landed")
                    return StackOutput(False, None, False, None, False)
            else:
                t = p["COM_DISARM_PRFLT"]
                if t > 0 and landed_s >= t and self.mode is not FlightMode.TAKEOFF:
                    self.disarm(now_us, state, why="no takeoff")
                    return StackOutput(False, None, False, None, False)
        else:
            self._landed_since_us = None
            self._airborne_since_arm = True

        # --- actuator override freshness
        fresh = self.actuators_fresh(now_us)
        reset = False
        if fresh and not self._override_active:
            self._override_active = True
            self._say(SEVERITY_INFO, "Actuator override active")
        elif not fresh and self._override_active:
            self._override_active = False
            reset = True
            self._anchor_at(state)
            self._say(SEVERITY_WARNING, "Actuator stream lost: onboard controller holds")

        if self._failsafe is not None or (self.mode is FlightMode.OFFBOARD and not self.offboard_fresh(now_us)):
            self._offboard_loss(now_us, state)

        sp, idle = self._mode_setpoint(now_us, state, dt)
        if not self.armed:     # the mode disarmed (ArduCopter: the mission ended on the ground)
            return _DISARMED_OUTPUT
        o = self._out
        if self._override_active:
            cmd = self._act_cmd
            if o is not None and o.motor_override is cmd and o.setpoint is sp:
                return o   # frozen: reusing the last output equals building a new one
            o = self._out = StackOutput(True, cmd, False, sp, False)
            return o
        if self.mode is FlightMode.OFFBOARD and self.rates_active(now_us):
            o = self._out = StackOutput(True, None, False, sp, reset, self._rates)
            return o
        if (o is not None and o.motor_override is None and o.rates is None and o.setpoint is sp
                and o.idle is idle and o.reset_controller is reset):
            return o
        o = self._out = StackOutput(True, None, idle, sp, reset)
        return o

    def _has_target(self) -> bool:
        r = self._offboard
        return r is not None and r.time_us >= self._offboard_min_us

    def _offboard_loss(self, now_us: int, state: NavState) -> None:
        """The offboard/guided loss failsafe (``Autopilot.offboard_loss``)."""
        rule = self.autopilot.offboard_loss
        p = self.params
        if self.mode is FlightMode.OFFBOARD and self._failsafe is None and not self.offboard_fresh(now_us):
            if rule.leave_to is None and not self._has_target():
                return        # GUIDED holding with no target of ours: nothing to lose
            self._failsafe = "offboard"
            if rule.leave_to is not None:
                self._enter(FlightMode[rule.leave_to], state, announce=False)
                self._failsafe_t0_us = now_us
            else:             # kept in the mode, stopped where it is; timed from the last setpoint
                self._anchor_at(state)
                self._failsafe_t0_us = now_us if self._offboard is None else self._offboard.time_us
            self._say(SEVERITY_CRITICAL, "Failsafe: offboard setpoints lost, holding")
        elif (self._failsafe in ("offboard", "offboard-hold") and rule.leave_to is None
              and self.mode is FlightMode.OFFBOARD and self.offboard_fresh(now_us)):
            self._failsafe = None          # GUIDED: fresh setpoints are tracked again
            self._say(SEVERITY_INFO, "Offboard setpoints back")
        if self._failsafe == "offboard" and self.mode is self._loss_hold_mode:
            if (now_us - self._failsafe_t0_us) * 1e-6 >= p[rule.act_after_param]:
                action = self.autopilot.action_of(p[rule.action_param])
                if action == "land":
                    self._failsafe = None
                    self._enter(FlightMode.LAND, state, announce=False)
                    self._say(SEVERITY_CRITICAL, "Failsafe: landing")
                elif action == "rtl" and not state.landed:
                    self._failsafe = None
                    self._enter(FlightMode.RTL, state, announce=False)
                    self._say(SEVERITY_CRITICAL, "Failsafe: returning")
                else:
                    self._failsafe = "offboard-hold"

    def _mode_setpoint(self, now_us: int, state: NavState, dt: float) -> tuple[Setpoint | None, bool]:
        """Setpoint of the current mode and whether the motors should idle."""
        a = self._anchor
        p = self.params
        mode = self.mode
        if mode is FlightMode.OFFBOARD:
            if self._by_command and state.landed and not self._airborne_since_arm:
                return None, True      # ArduCopter GUIDED on the ground: idle until NAV_TAKEOFF
            r = self._offboard
            if self._failsafe is not None or r is None or r.time_us < self._offboard_min_us:
                return self._hold_sp, False
            sp = r.setpoint
            if sp.pos_enu_m is None and sp.vel_enu_m_s is None and sp.acc_enu_m_s2 is None:
                # Yaw-only setpoint: hold the position, turn as asked.
                sp = Setpoint(a.pos, np.zeros(3), None, sp.yaw_enu_rad, sp.yaw_rate_rad_s)
            return sp, False
        if mode is FlightMode.TAKEOFF:
            v = p["MPC_TKO_SPEED"]
            a.z_ref = min(a.z_ref + v * dt, a.target_z)
            climbing = a.z_ref < a.target_z
            if not climbing and abs(float(state.pos_enu_m[2]) - a.target_z) <= p["NAV_MC_ALT_RAD"]:
                hold = (a.pos[0], a.pos[1], a.target_z)
                ap = self.autopilot
                self.mode = FlightMode[ap.mode(ap.after_takeoff).behaviour]
                self._anchor_at(state, hold_pos=hold)
                self._offboard_min_us = self._now_us   # setpoints from before the take-off are not flown
                self._say(SEVERITY_INFO, f"Takeoff complete: Mode {ap.after_takeoff}")
                return self._hold_sp, False
            return Setpoint((a.pos[0], a.pos[1], a.z_ref), (0.0, 0.0, v if climbing else 0.0),
                            None, a.yaw, None), False
        if mode is FlightMode.LAND:
            if state.landed:
                if not self._land_announced:
                    self._land_announced = True
                    self._say(SEVERITY_INFO, "Landing detected")
                return None, True
            return Setpoint((a.pos[0], a.pos[1], math.nan), (0.0, 0.0, -p["MPC_LAND_SPEED"]),
                            None, a.yaw, None), False
        if mode is FlightMode.RTL:
            return self._rtl_setpoint(state, dt), False
        if mode is FlightMode.MISSION:
            return self._mission_setpoint(state, dt)
        if self._goto is not None:
            return self._goto_setpoint(dt), False
        # LOITER, POSCTL, MANUAL: hold; on the ground stay on the ground.
        if state.landed and self._hold_sp is not None and self._hold_sp.pos_enu_m[2] <= state.pos_enu_m[2] + 0.05:
            return None, True
        return self._hold_sp, False

    def _rtl_setpoint(self, state: NavState, dt: float) -> Setpoint:
        a = self._anchor
        p = self.params
        if a.phase == 0:   # climb where we are
            a.z_ref = min(a.z_ref + p["MPC_Z_VEL_MAX_UP"] * dt, a.target_z)
            if a.z_ref >= a.target_z and abs(float(state.pos_enu_m[2]) - a.target_z) < 0.5:
                a.phase = 1
            return Setpoint((a.pos[0], a.pos[1], a.z_ref), None, None, a.yaw, None)
        # fly to the destination (home or a rally point): a carrot moving at MPC_XY_CRUISE
        dest = a.dest
        d = dest[:2] - a.pos[:2]
        dist = float(math.hypot(d[0], d[1]))
        v = p["MPC_XY_CRUISE"]
        step = v * dt
        if dist <= step:
            a.pos[0], a.pos[1] = dest[0], dest[1]
            vel = (0.0, 0.0, 0.0)
        else:
            a.pos[:2] += d / dist * step
            vel = (d[0] / dist * v, d[1] / dist * v, 0.0)
        here = float(math.hypot(*(dest[:2] - np.asarray(state.pos_enu_m[:2]))))
        if dist <= step and here < RTL_ACCEPT_RADIUS_M:
            where = "rally point" if a.dest_rally else "home"
            self._enter(FlightMode.LAND, state, announce=False)
            self._say(SEVERITY_INFO, f"Return: {where} reached, landing")
        return Setpoint((a.pos[0], a.pos[1], a.target_z), vel, None, a.yaw, None)

    def _mission_setpoint(self, state: NavState, dt: float) -> tuple[Setpoint | None, bool]:
        if self.mission is None:   # pragma: no cover - set_mission leaves the mode first
            self._enter(FlightMode.LOITER, state)
            return self._hold_sp, False
        rules = self.autopilot.mission_rules
        if rules.auto_armed and state.landed and not self._auto_armed and not self.mission.finished:
            if not int(self.params["AUTO_OPTIONS"]) & 2:
                return None, True      # ArduCopter: motors idle until the take-off is released
            self._auto_armed = True    # AUTO_OPTIONS bit 1: take off without raising the throttle
        step = self.mission.update(state, dt)
        if rules.auto_armed and self.mission.finished and state.landed:
            # ArduCopter ModeAuto::exit_mission: the mission ended on the ground, disarm
            self.disarm(self._now_us, state, why="mission complete")
            return None, True
        if step.action == "rtl":
            if state.landed:
                self._enter(FlightMode.LAND, state)
                return None, True
            self._enter(FlightMode.RTL, state)
            return self._rtl_setpoint(state, dt), False
        return step.setpoint, step.idle

    def _goto_setpoint(self, dt: float) -> Setpoint:
        """DO_REPOSITION: the hold point moves toward the target."""
        a = self._anchor
        target, v, yaw = self._goto
        pos, vel, arrived = carrot_step(a.pos, target, v, 0.0, dt)
        a.pos = np.array(pos)
        a.yaw = yaw
        if arrived:
            self._goto = None
        self._hold_sp = Setpoint(a.pos.copy(), vel, None, yaw, None)
        return self._hold_sp

    def _check_fence(self, state: NavState) -> None:
        """Geofence failsafe: GF_ACTION once when the vehicle leaves the
        allowed area in the air (``fence_breached`` follows it always)."""
        p = state.pos_enu_m
        out = self.fence.breached(p[0], p[1])
        if out == self.fence_breached:
            return
        self.fence_breached = out
        if not out:
            self._say(SEVERITY_INFO, "Geofence: back inside")
            return
        action = int(self.params["GF_ACTION"])
        if state.landed or action == 0 or not self.armed or self.crash_event is not None:
            return
        what = {1: "", 2: ", holding", 3: ", returning", 4: ", landing", 5: ", landing"}[action]
        self._say(SEVERITY_CRITICAL, f"Geofence breached{what}")
        if action == 2:
            self._enter(FlightMode.LOITER, state, announce=False)
            self._failsafe = "geofence"
        elif action == 3:
            self._enter(FlightMode.RTL, state, announce=False)
        elif action in (4, 5):
            self._enter(FlightMode.LAND, state, announce=False)
