"""The flight's outcome and safety monitor: a pure state machine.

A flight is ``completed`` only if, from the moment our arming was accepted
until we commanded the landing, the vehicle stayed armed, airborne (after the
climb), in the mode we asked for, out of EMERGENCY, did not crash, and the
tracking error stayed within the configured bound; and it then landed and
disarmed. Anything else is a *violation*. The first one is kept, with its time
(vehicle clock) and values, and decides the reaction the flight loop takes
(``Violation.action``):

- ``end``: nothing left to do for us (crashed, disarmed under us);
- ``release``: somebody else took the vehicle (a mode we did not ask for):
  stop commanding, do not fight the pilot, watch until it is on the ground;
- ``land``: we still hold the vehicle but the flight is unsafe (tracking
  error beyond the bound, on the ground in flight, a sensor stream gone
  stale): command LAND (or hold, by configuration).

The monitor holds a handful of values; it reads nothing but its arguments.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from mavcore.autopilot.px4 import AUTO_SUB_MODES as PX4_AUTO_SUB_MODES  # noqa: F401 (re-exported)
from mavcore.autopilot.px4 import MAIN_MODES as PX4_MAIN_MODES  # noqa: F401 (re-exported)
from mavcore.autopilot.px4 import mode_name as px4_mode_name

MAV_STATE_CRITICAL = 5
MAV_STATE_EMERGENCY = 6
MAV_SEVERITY_CRITICAL = 2
MAV_LANDED_STATE_ON_GROUND = 1


@dataclass(frozen=True)
class MonitorConfig:
    """Bounds of a flight that counts as completed.

    Attributes
    ----------
    max_tracking_error_m : float
        Largest position error against the flown reference (m) during the
        trajectory phase, after ``settle_s``.
    settle_s : float
        Seconds after the trajectory start before the bound applies.
    climb_grace_s : float
        After arming, the vehicle may report ON_GROUND this long (the climb
        starting) before that counts as "on the ground in flight".
    max_nav_age_s : float
        A position/velocity sample older than this (vehicle clock) against
        the sensor frame means the navigation stream is gone stale.
    """

    max_tracking_error_m: float = 0.5
    settle_s: float = 5.0
    climb_grace_s: float = 5.0
    max_nav_age_s: float = 1.0

    def __post_init__(self) -> None:
        for name in ("max_tracking_error_m", "climb_grace_s", "max_nav_age_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0")
        if not (math.isfinite(self.settle_s) and self.settle_s >= 0):
            raise ValueError("settle_s must be a finite number >= 0")


@dataclass(frozen=True)
class Violation:
    """The first thing that went wrong.

    Attributes
    ----------
    t_s : float or None
        Vehicle time (s) when it was seen; None before the vehicle clock was known.
    kind : str
        ``crash``, ``disarmed``, ``mode_change``, ``emergency``, ``on_ground``,
        ``tracking``, ``nav_stale``, ``interrupted``, ``command_rejected``,
        ``link``, ``vehicle_not_ready``, ``attached``, ``no_route``, ``replan_timeout``,
        ``output`` (the .tlog could not be written: ``FlightCore.output_fault``).
    detail : str
        One human-readable line.
    action : str
        ``end``, ``release`` or ``land`` (module docstring).
    values : dict
        The numbers behind it.
    """

    t_s: float | None
    kind: str
    detail: str
    action: str
    values: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"t_s": self.t_s, "kind": self.kind, "detail": self.detail, "action": self.action,
                "values": dict(self.values)}


class FlightMonitor:
    """Watches the vehicle between our arming and our landing command.

    Call ``armed(t, mode)`` when our arming is accepted (``mode``: the
    custom_mode we set; ``mode_name`` names it, the autopilot's personality), ``climbed(t)`` once the vehicle is meant to be
    airborne, ``landing(t)`` when we command the landing (from then on the
    vehicle may change mode, touch down and disarm), and feed it the
    vehicle's messages through the ``on_*`` methods.
    """

    def __init__(self, cfg: MonitorConfig = MonitorConfig()) -> None:
        self.cfg = cfg
        self.first: Violation | None = None
        self.crash: dict | None = None
        self.watching = False
        self._t_arm: float | None = None
        self._mode: int | None = None
        self._landing = False
        self._emergency_seen = False
        #: custom_mode -> readable name (``companion.flight.core`` sets the vehicle's personality's).
        self.mode_name = px4_mode_name

    # --- our own steps -----------------------------------------------------
    def armed(self, t_s: float, custom_mode: int | None) -> None:
        self._t_arm = t_s
        self._mode = custom_mode
        self.watching = True

    def landing(self, t_s: float) -> None:
        """We commanded the landing: mode changes, touchdown and disarming are expected now."""
        self._landing = True

    def expect_mode(self, custom_mode: int | None) -> None:
        self._mode = custom_mode

    @property
    def ok(self) -> bool:
        return self.first is None

    def fail(self, t_s: float | None, kind: str, detail: str, action: str = "land", **values) -> Violation:
        """Record a violation found outside the monitor (command rejected, interrupted...)."""
        v = Violation(t_s, kind, detail, action, values)
        if self.first is None:
            self.first = v
        return v

    # --- the vehicle's messages ---------------------------------------------
    def on_heartbeat(self, t_s: float | None, armed: bool, custom_mode: int, system_status: int) -> Violation | None:
        if system_status == MAV_STATE_EMERGENCY and not self._emergency_seen:
            if self.watching or self.crash is not None:
                # seen only once reported: an EMERGENCY before our arming must not hide one in flight
                self._emergency_seen = True
                return self._violate(t_s, "emergency", "vehicle reports MAV_STATE_EMERGENCY", "end",
                                     system_status=system_status)
        if not self.watching or self._landing:
            return None
        if not armed:
            return self._violate(t_s, "disarmed", "vehicle disarmed in flight (not by us)", "end")
        if self._mode is not None and custom_mode != self._mode:
            return self._violate(t_s, "mode_change",
                                 f"vehicle left {self.mode_name(self._mode)} for {self.mode_name(custom_mode)} "
                                 f"(not asked by us)", "release",
                                 expected=self.mode_name(self._mode), got=self.mode_name(custom_mode))
        return None

    def on_statustext(self, t_s: float | None, severity: int, text: str) -> Violation | None:
        if severity <= MAV_SEVERITY_CRITICAL and text.upper().startswith("CRASH"):
            if self.crash is None:
                self.crash = {"t_s": t_s, "text": text}
            return self._violate(t_s, "crash", text, "end")
        return None

    def on_landed_state(self, t_s: float, landed_state: int) -> Violation | None:
        if not self.watching or self._landing or self._t_arm is None:
            return None
        if landed_state == MAV_LANDED_STATE_ON_GROUND and t_s - self._t_arm > self.cfg.climb_grace_s:
            return self._violate(t_s, "on_ground", "vehicle on the ground during the flight", "land")
        return None

    def on_tracking(self, t_s: float, t_traj_start_s: float, err_m: float, source: str) -> Violation | None:
        if not self.watching or self._landing or t_s < t_traj_start_s + self.cfg.settle_s:
            return None
        bound = self.cfg.max_tracking_error_m
        if not err_m <= bound:   # NaN counts as beyond the bound
            return self._violate(t_s, "tracking",
                                 f"position error {err_m:.3f} m beyond the {bound:g} m bound ({source})", "land",
                                 error_m=err_m, bound_m=bound, source=source)
        return None

    def on_nav_age(self, t_s: float, nav_t_s: float | None) -> Violation | None:
        if not self.watching or self._landing or nav_t_s is None:
            return None
        age = t_s - nav_t_s
        if age > self.cfg.max_nav_age_s:
            return self._violate(t_s, "nav_stale", f"position/velocity {age:.2f} s old", "land", age_s=age)
        return None

    def _violate(self, t_s, kind, detail, action, **values) -> Violation:
        v = Violation(t_s, kind, detail, action, values)
        if self.first is None:
            self.first = v
            return v
        # A later crash is worth knowing even after another violation.
        return v if kind == "crash" else None
