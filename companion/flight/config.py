"""How the companion flies (``RunnerConfig``): phases, rates, bounds, reactions."""

from __future__ import annotations

import math
from dataclasses import dataclass

#: What the companion does when a flight must stop early (violation, SIGINT/SIGTERM).
FAILURE_ACTIONS = ("land", "hold")
#: What ``companion fly --attach`` does with a vehicle that is already flying.
ATTACH_ACTIONS = ("refuse", "resume", "land")


#: The ``--control`` modes: who flies the inner loop.
CONTROL_MODES = ("companion", "rates", "vehicle")


@dataclass(frozen=True)
class RunnerConfig:
    """How the runner flies (vehicle-clock seconds unless said otherwise).

    Attributes
    ----------
    control : str
        "companion" (geometric controller answers each frame with motor
        commands), "rates" (its outer part answers each frame with body rates
        and thrust, SET_ATTITUDE_TARGET; the vehicle's rate loop flies) or
        "vehicle".
    setpoint_hz : float
        SET_POSITION_TARGET_LOCAL_NED rate (>= 20 Hz as PX4 requires).
    preflight_s : float
        Setpoint streaming before OFFBOARD is requested.
    climb_speed_m_s : float
        Peak speed of the vertical climb.
    transfer_speed_m_s : float
        Peak speed of the level transfer to the first point.
    hold_s, hover_s : float
        Hover before and after the trajectory.
    settle_s : float
        Tracking errors count from ``settle_s`` after the trajectory start.
    landing_timeout_s : float
        Vehicle time allowed for landing and disarming.
    link_timeout_s : float
        Wall-clock seconds without any message (or without the vehicle
        clock advancing) before the link counts as lost.
    command_timeout_s : float
        Vehicle time to wait for a COMMAND_ACK or a mission-protocol answer
        before re-sending.
    request_truth : bool
        Ask the vehicle for its ground-truth ODOMETRY every frame (the
        bundled SITL's; used for the report's error statistics only).
    mute_streams : tuple of int
        Message ids to switch off (interval -1) at setup: telemetry the
        runner does not use (leave empty when a ground station shares the
        vehicle's streams).
    low_rate_streams : tuple of (int, float)
        (message id, Hz) set at setup: position streams kept at a low rate
        for ground stations and log tools (GLOBAL_POSITION_INT, GPS_RAW_INT).
    spin_us : float
        Busy-poll this long (microseconds) for the vehicle's next frame
        before sleeping in the kernel; used only on a machine with two or
        more cores, where the vehicle runs on another.
    max_tracking_error_m : float
        A flight whose error (after ``settle_s``) exceeds this is not
        completed and is stopped (``on_failure``).
    on_failure : str
        "land" (command NAV_LAND) or "hold" (AUTO.LOITER, the vehicle holds
        where it is and the companion lets go): the reaction to a violation
        that leaves us in control and to SIGINT/SIGTERM.
    attach : str
        A vehicle already armed and flying at connection: "refuse" (do
        nothing, report), "resume" (fly the rest of the trajectory from the
        nearest way-point), "land".
    max_nav_age_s : float
        Position/velocity older than this against the sensor frame (vehicle
        clock) is stale: the flight is stopped.
    check_params : bool
        At set-up, read the parameters the personality declares
        (``Autopilot.param_checks``: offboard/guided loss timeouts and
        actions) and warn of each value outside what a flight needs
        (``FlightCore.param_warnings``, STATUSTEXT, the log); the flight goes on.
    """

    control: str = "companion"
    setpoint_hz: float = 50.0
    preflight_s: float = 1.0
    climb_speed_m_s: float = 1.0
    transfer_speed_m_s: float = 3.0
    hold_s: float = 1.0
    hover_s: float = 1.0
    settle_s: float = 5.0
    landing_timeout_s: float = 30.0
    link_timeout_s: float = 10.0
    command_timeout_s: float = 1.0
    request_truth: bool = True
    mute_streams: tuple[int, ...] = ()
    low_rate_streams: tuple[tuple[int, float], ...] = ((33, 5.0), (24, 5.0))
    spin_us: float = 300.0
    max_tracking_error_m: float = 0.5
    on_failure: str = "land"
    attach: str = "refuse"
    max_nav_age_s: float = 1.0
    check_params: bool = False

    def __post_init__(self) -> None:
        if self.control not in CONTROL_MODES:
            raise ValueError("control must be 'companion', 'rates' or 'vehicle'")
        if not self.setpoint_hz >= 20.0 or not math.isfinite(self.setpoint_hz):
            raise ValueError("setpoint_hz must be >= 20 (PX4 offboard)")
        if not self.spin_us >= 0.0:
            raise ValueError("spin_us must be >= 0")
        if self.on_failure not in FAILURE_ACTIONS:
            raise ValueError(f"on_failure must be one of {FAILURE_ACTIONS}")
        if self.attach not in ATTACH_ACTIONS:
            raise ValueError(f"attach must be one of {ATTACH_ACTIONS}")
        for name in ("max_tracking_error_m", "link_timeout_s", "command_timeout_s", "landing_timeout_s",
                     "max_nav_age_s", "climb_speed_m_s", "transfer_speed_m_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0")
        for name in ("preflight_s", "hold_s", "hover_s", "settle_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0")
