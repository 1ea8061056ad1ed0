"""The ``Autopilot`` interface: what differs between flight stacks on the wire.

A personality is pure data plus small pure functions (no I/O, no clock):
mode names and ``custom_mode`` numbers, the behaviour each mode stands for in
the bundled SITL, arming and take-off rules, parameter names (and their units
against the SI values the SITL works in), the message set and its rates, how
offboard/guided control is entered and kept alive, and what happens when it
stops (docs/flying-a-real-vehicle.md gives the stack's documentation for
each).

Behaviours (``ModeDef.behaviour``) are the SITL's stack-independent mode
kinds: ``MANUAL`` (no RC exists: holds), ``POSCTL`` (holds), ``TAKEOFF``,
``LOITER``, ``MISSION``, ``RTL``, ``LAND``, ``OFFBOARD`` (tracks the
companion's setpoints: PX4 OFFBOARD, ArduCopter GUIDED); None: a mode the
stack has and the SITL refuses.
"""

from __future__ import annotations

from dataclasses import dataclass

#: MAV_MODE_FLAG_CUSTOM_MODE_ENABLED (MAVLink common).
MODE_FLAG_CUSTOM_MODE_ENABLED = 1

BEHAVIOURS = ("MANUAL", "POSCTL", "TAKEOFF", "LOITER", "MISSION", "RTL", "LAND", "OFFBOARD")


@dataclass(frozen=True)
class ModeDef:
    """One flight mode: its name as the stack's tools print it, its HEARTBEAT
    ``custom_mode`` word, and the SITL behaviour it stands for."""

    name: str
    custom_mode: int
    behaviour: str | None


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: name (<= 16 chars), MAV_PARAM_TYPE, default, bounds, meaning."""

    name: str
    param_type: int
    default: float
    min: float
    max: float
    doc: str


@dataclass(frozen=True)
class ParamAlias:
    """An internal (SI) parameter exposed on the wire under the stack's name:
    wire value = internal value * ``wire_per_si`` (e.g. 100 for cm/s)."""

    internal: str
    wire: str
    wire_per_si: float = 1.0


@dataclass(frozen=True)
class ParamCheck:
    """A parameter the companion reads before flying (``--check-params``) and
    the values a flight under its setpoints needs (docs/flying-a-real-vehicle.md
    "Parameters to set"): a value outside them is a warning, not a refusal.

    ``allowed``: the acceptable values (None: any in [``min``, ``max``]), in
    the stack's units; ``why``: what the parameter guards, for the warning.
    """

    name: str
    why: str
    min: float = float("-inf")
    max: float = float("inf")
    allowed: tuple | None = None

    def problem(self, value) -> str | None:
        """None if ``value`` is acceptable, else what is expected (a short phrase)."""
        if value is None:
            return "not read (no PARAM_VALUE)"
        if self.allowed is not None:
            if value in self.allowed:
                return None
            return "expected " + " or ".join(f"{a:g}" for a in self.allowed)
        if self.min <= value <= self.max:
            return None
        return f"expected {self.min:g}..{self.max:g}"


@dataclass(frozen=True)
class OffboardLoss:
    """What the stack does when offboard/guided setpoints stop.

    Attributes
    ----------
    timeout_param : str
        Internal parameter: seconds without a setpoint before the loss.
    leave_to : str or None
        Behaviour entered at the loss (PX4: LOITER, the Hold mode); None: the
        mode is kept and the vehicle holds where it is (ArduCopter GUIDED).
    act_after_param : str or None
        Internal parameter: seconds after the loss before ``action``.
    action_param : str or None
        Internal parameter naming the action (``action_of`` maps its value).
    """

    timeout_param: str
    leave_to: str | None
    act_after_param: str | None
    action_param: str | None


@dataclass(frozen=True)
class MissionRules:
    """How the stack flies a stored mission in its mission mode (AUTO.MISSION,
    ArduCopter AUTO); the SITL's ``sitl.mission_exec`` reads these.

    Attributes
    ----------
    first_seq : int
        First item flown (ArduPilot: item 0 holds home and is never flown).
    item_acceptance : bool
        NAV_WAYPOINT param2 is the acceptance radius (PX4); False: the stack's
        radius parameter for every way-point (ArduCopter WPNAV_RADIUS).
    item_yaw : bool
        NAV_WAYPOINT / NAV_TAKEOFF param4 sets the heading (PX4); False: the
        nose follows the leg or the ROI (ArduCopter WP_YAW_BEHAVIOR 2).
    implicit_takeoff : bool
        Started on the ground without a NAV_TAKEOFF first, the stack climbs to
        its take-off altitude itself (PX4); False: entering the mission mode
        armed on the ground without one is refused ("Auto: Missing Takeoff Cmd").
    rtl_in_mission : bool
        NAV_RETURN_TO_LAUNCH is flown inside the mission mode and reached on
        touchdown (ArduCopter); False: it switches to the return mode (PX4).
    auto_armed : bool
        Armed on the ground in the mission mode the motors idle until the
        take-off is released (ArduCopter's ``auto_armed``: the pilot's
        throttle, MAV_CMD_MISSION_START, a GUIDED take-off, or AUTO_OPTIONS bit
        1); arming in the mission mode needs AUTO_OPTIONS bit 0; the vehicle
        disarms when the mission ends on the ground.
    reached_text : bool
        A way-point reached is also announced by STATUSTEXT "Reached command #N".
    """

    first_seq: int = 0
    item_acceptance: bool = True
    item_yaw: bool = True
    implicit_takeoff: bool = True
    rtl_in_mission: bool = False
    auto_armed: bool = False
    reached_text: bool = False


class Autopilot:
    """A flight stack's personality (one subclass instance per stack).

    Subclasses set the class attributes; the methods derive from them.
    """

    #: Registry key (``--autopilot``).
    key: str = ""
    #: HEARTBEAT ``autopilot`` (MAV_AUTOPILOT).
    mav_autopilot: int = 0
    #: HEARTBEAT ``type`` (MAV_TYPE_QUADROTOR).
    mav_type: int = 2
    #: AUTOPILOT_VERSION ``flight_sw_version``.
    flight_sw_version: int = 0
    modes: tuple[ModeDef, ...] = ()
    #: Mode at boot.
    boot_mode: str = ""
    #: The mode that tracks the companion's setpoints.
    offboard_mode: str = ""
    #: The mode attitude-rate setpoints (SET_ATTITUDE_TARGET, ``--control rates``,
    #: branch h17-rates) are flown in: PX4 OFFBOARD, ArduCopter GUIDED (and
    #: GUIDED_NOGPS without a position estimate). The hook for that control mode.
    attitude_mode: str = ""
    #: The mode the vehicle is in after a commanded take-off.
    after_takeoff: str = ""
    #: Entering the offboard mode needs a setpoint stream already present.
    offboard_needs_stream: bool = False
    #: Armed on the ground in the offboard mode, setpoints do not lift the
    #: vehicle: a MAV_CMD_NAV_TAKEOFF (in that mode, armed) does.
    takeoff_by_command: bool = False
    #: MAV_CMD_NAV_TAKEOFF param7 is relative to home (else AMSL).
    takeoff_alt_relative: bool = False
    #: The per-frame IMU message.
    imu_message: str = "HIGHRES_IMU"
    #: Telemetry streams and their default rates (message name -> Hz; 0: off).
    default_rates_hz: dict = {}
    #: Integer parameters travel byte-wise in PARAM_VALUE's float (PX4);
    #: False: as a C cast to float (ArduPilot).
    param_bytewise: bool = True
    param_specs: tuple[ParamSpec, ...] = ()
    param_aliases: tuple[ParamAlias, ...] = ()
    #: What the companion reads and checks before flying (``--check-params``).
    param_checks: tuple[ParamCheck, ...] = ()
    #: Internal parameters the stack has no parameter for: fixed values.
    fixed_params: dict = {}
    #: Behaviours reported as another mode (ArduCopter climbs inside GUIDED).
    report_as: dict = {}
    offboard_loss: OffboardLoss | None = None
    #: How the mission mode flies the stored mission.
    mission_rules: MissionRules = MissionRules()

    # --- modes ------------------------------------------------------------------
    def mode(self, name: str) -> ModeDef:
        """The mode called ``name``; KeyError if the stack has none."""
        for m in self.modes:
            if m.name == name:
                return m
        raise KeyError(f"{self.key}: no mode {name}")

    def custom_mode(self, name: str) -> int:
        return self.mode(name).custom_mode

    def decode_mode(self, custom_mode: int) -> ModeDef | None:
        """The mode of a HEARTBEAT/SET_MODE ``custom_mode``; None if unknown."""
        c = int(custom_mode)
        for m in self.modes:
            if m.custom_mode == c:
                return m
        return None

    def mode_name(self, custom_mode: int) -> str:
        m = self.decode_mode(custom_mode)
        return m.name if m is not None else f"MODE({int(custom_mode)})"

    def mode_for(self, behaviour: str) -> ModeDef:
        """The (first) mode standing for a SITL behaviour."""
        for m in self.modes:
            if m.behaviour == behaviour:
                return m
        raise KeyError(f"{self.key}: no mode for {behaviour}")

    def wire_mode(self, behaviour: str) -> ModeDef:
        """The mode the HEARTBEAT reports while the SITL flies ``behaviour``."""
        name = self.report_as.get(behaviour)
        return self.mode(name) if name is not None else self.mode_for(behaviour)

    def action_of(self, value: float) -> str:
        """The offboard-loss action parameter's value -> 'land' | 'rtl' | 'hold'."""
        raise NotImplementedError

    def custom_mode_from_params(self, param2: float, param3: float) -> int:
        """MAV_CMD_DO_SET_MODE param2/param3 -> ``custom_mode``."""
        raise NotImplementedError

    def set_mode_params(self, name: str) -> tuple[float, float, float]:
        """MAV_CMD_DO_SET_MODE param1..3 selecting mode ``name``."""
        raise NotImplementedError

    # --- parameters -------------------------------------------------------------
    def wire_name(self, internal: str) -> str:
        for a in self.param_aliases:
            if a.internal == internal:
                return a.wire
        return internal
