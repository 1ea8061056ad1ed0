"""The simulated vehicle: what the SITL flies, stepped on the vehicle clock (no I/O).

``Vehicle`` owns the vehicle's state: the simulation (``sitl.sim.Simulation``:
plant, sensors, onboard estimator and position controller, inner rate loop,
movers, rangefinders, crash and contact rules), the flight stack
(``sitl.flightstack.FlightStack``: modes, arming, failsafes, missions), its
parameters, the battery and the collision prevention fed by
OBSTACLE_DISTANCE. ``step`` advances it one sensor frame: the flight stack
decides the command from what it knows (``nav_state``), the simulation flies
it (motors off, a motor override, body rates, idle, or the onboard
controller's setpoint), the battery drains.

``sitl.server.SitlServer`` holds one and drives it: links, pacing and
lockstep are the server's; what goes out about the vehicle is
``sitl.telemetry`` and the protocol parts (``sitl.commands``,
``sitl.mission_link``, ...), built over this object's pieces.
"""

from __future__ import annotations

import math

import numpy as np

from mavcore import autopilot as autopilots
from mavcore import codec
from mavcore.mission.schema import Mission

from .battery import Battery
from .collision_prevention import CollisionPrevention
from .flightstack import IDLE_MOTOR_CMD, FlightStack, NavState
from .params_link import vehicle_parameters
from .sim import Simulation
from .world import load_world

_ZERO4 = (0.0, 0.0, 0.0, 0.0)
_IDLE4 = (IDLE_MOTOR_CMD,) * 4


class Vehicle:
    """The simulated vehicle and its flight stack (see the module docstring).

    Parameters
    ----------
    mission : Mission
    seed : int
        The simulation's seed (noise, wind, gusts).
    physics_hz, sensor_hz : int
    start : (x_m, y_m, yaw_deg) or None
        Launch position (ENU metres on the map) and heading (ENU degrees);
        None: the mission's ``sim.start_enu_m`` or the default free cell.
    autopilot : str
        The personality (``mavcore.autopilot``: "px4", "ardupilot").
    lockstep : bool
        Whether lockstep with an actuator peer is allowed (SIM_LOCKSTEP).

    Attributes
    ----------
    frame : sitl.sim.SensorFrame or None
        The current sensor frame (None before ``start``).
    setpoint : flight stack setpoint or None
        What the flight stack commanded at the last ``step``.
    frames : int
        Frames stepped.
    """

    def __init__(self, mission: Mission, *, seed: int, physics_hz: int, sensor_hz: int,
                 start: tuple | None, autopilot: str, lockstep: bool) -> None:
        self.seed = seed
        start_xy, start_yaw = None, 0.0
        if start is not None:
            start_xy, start_yaw = start[:2], math.radians(start[2])
        self.sim = Simulation(mission, np.random.default_rng(seed), physics_hz=physics_hz, sensor_hz=sensor_hz,
                              world=load_world(mission), start_enu_m=start_xy, start_yaw_rad=start_yaw)
        self.autopilot = autopilots.get(autopilot)
        self.params = vehicle_parameters(self.autopilot, mission, self.sim, lockstep)
        self.origin = codec.GeoOrigin(mission.home.lat, mission.home.lon, mission.home.alt_m)
        self.home_enu_m = np.array(self.sim.truth.pos_enu_m, dtype=float)
        self.stack = FlightStack(self.params, self.home_enu_m, self.autopilot)
        self.sim.landing_intent = self.landing_intended   # asked at touchdowns (crash rules)
        self.battery = Battery(mission.energy)
        self.collision_prevention = CollisionPrevention()     # fed by OBSTACLE_DISTANCE, CP_* params
        self.frame = None
        self.setpoint = None
        self.frames = 0
        self._onboard_flying = False
        self._rates_flying = False

    @property
    def time_us(self) -> int:
        """The vehicle clock (us)."""
        return self.sim.time_us

    def start(self):
        """Frame 0, motors off (the clock's first frame); returns it."""
        self.frame = self.sim.step_frame(_ZERO4)
        return self.frame

    def step(self):
        """One sensor frame: the flight stack's command at the current frame,
        flown by the simulation, and the battery's drain over it; returns the
        new frame."""
        sim = self.sim
        frame = self.frame if self.frame is not None else sim.step_frame(_ZERO4)
        now = sim.time_us
        out = self.stack.update(now, self.nav_state(frame))
        self.setpoint = out.setpoint
        if not out.armed:
            self._onboard_flying = False
            frame = sim.step_frame(_ZERO4)
        elif out.motor_override is not None:
            self._onboard_flying = False
            frame = sim.step_frame(out.motor_override)
        elif out.rates is not None:
            if not self._rates_flying:
                sim.rates.reset()       # the inner rate loop takes over: a clean integrator
            self._onboard_flying = False
            frame = sim.step_rates(out.rates)
        elif out.idle or out.setpoint is None:
            self._onboard_flying = False
            frame = sim.step_frame(_IDLE4)
        else:
            if out.reset_controller or not self._onboard_flying:
                sim.onboard.reset()
            self._onboard_flying = True
            self.collision_prevention.set_time(now)
            frame = sim.step_onboard(out.setpoint)
        self._rates_flying = out.rates is not None
        self.frame = frame
        self.battery.drain(sim.plant.f, sim.dt_frame_s)
        self.frames += 1
        return frame

    def check_crash(self) -> bool:
        """Tell the flight stack of a crash the last frame detected (STATUSTEXT,
        EMERGENCY); True the first time, when the system status changed."""
        crash = self.sim.crash
        if crash is None or self.stack.crashed:
            return False
        self.stack.crash(self.sim.time_us, crash)
        return True

    def landing_intended(self) -> bool:
        """Whether a touchdown now would be a landing asked for (``FlightStack.landing_intended``)."""
        p = self.sim.plant.p
        return self.stack.landing_intended(self.sim.world.ground_height(p[0], p[1]))

    def nav_state(self, frame) -> NavState:
        """What the flight stack knows at ``frame``: the onboard estimate, or the
        truth with ``sim.onboard_state: truth``; ground contact stands for the
        land detector in both modes."""
        # Floats, not arrays: the truth is read from the plant (it only moves
        # in ``step_frame``, so between frames it is ``frame.truth``).
        pl = self.sim.plant
        e = frame.estimate
        if e is not None:
            return NavState(e.pos_enu_m, e.vel_enu_m_s, e.yaw_enu_rad, e.tilt_rad, bool(pl.landed))
        R = pl.R   # row-major 9-tuple, body FLU -> world ENU
        tilt = math.acos(max(-1.0, min(1.0, R[8])))
        return NavState(pl.p, pl.v, math.atan2(R[3], R[0]), tilt, bool(pl.landed))

    def state(self) -> NavState:
        """``nav_state`` of the current frame."""
        return self.nav_state(self.frame)
