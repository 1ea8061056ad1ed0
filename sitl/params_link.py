"""The vehicle's parameters on the link: their initial values, the
PARAM_* handlers and what a set changes in the simulation.

The store and the protocol are ``mavcore.services.params`` (``Parameters``,
``ParamServer``: list, read, set, INT32 encoding per autopilot); this module
gives them the SITL's initial values (the sensor model's noise, the onboard
controller's limits, the hover thrust), answers PARAM_REQUEST_LIST /
PARAM_REQUEST_READ on the link they came from, sends the value a PARAM_SET
leaves to every peer, and pushes the values into the onboard controller,
collision prevention and the sensors (``apply``).

No sockets of its own: the links are passed in with each message; the
server's links, STATUSTEXT and its own reaction to a change are callables.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mavcore import codec
from mavcore.services.params import Parameters, ParamServer

from .collision_prevention import CollisionPreventionConfig
from .flightstack import SEVERITY_WARNING
from .onboard import OnboardGains
from .rate_control import hover_thrust
from .vehicle_id import COMPONENT_ID, SYSTEM_ID


def vehicle_parameters(autopilot, mission, sim, lockstep: bool) -> Parameters:
    """The autopilot's parameter set with the SITL's initial values.

    Parameters
    ----------
    autopilot : mavcore.autopilot.Autopilot
    mission : Mission
        The vehicle (hover thrust).
    sim : sitl.sim.Simulation
        Its sensor model gives the SIM_* noise parameters.
    lockstep : bool
        SIM_LOCKSTEP.
    """
    md = sim.sensors.model
    g = OnboardGains()
    return Parameters.for_autopilot(autopilot, initial={
        "SIM_VEC_VAR": md.accel_rel_std ** 2, "SIM_GYRO_VAR": md.gyro_std_rad_s ** 2,
        "SIM_POS_STD": md.position_std_xy_m, "SIM_POSZ_STD": md.position_std_z_m,
        "SIM_VEL_STD": md.velocity_std_m_s, "SIM_RNG_STD": md.range_std_m,
        "SIM_LOCKSTEP": int(bool(lockstep)),
        "MPC_THR_HOVER": hover_thrust(mission.vehicle),
        "MPC_XY_VEL_MAX": g.max_speed_xy_m_s, "MPC_Z_VEL_MAX_UP": g.max_speed_up_m_s,
        "MPC_Z_VEL_MAX_DN": g.max_speed_down_m_s,
        "MPC_TILTMAX_AIR": math.degrees(g.max_tilt_rad)})


class VehicleParams:
    """The PARAM_* handlers and the parameters' effect on the simulation.

    Parameters
    ----------
    params : mavcore.services.params.Parameters
    autopilot : mavcore.autopilot.Autopilot
        Its INT32 encoding (``param_bytewise``).
    sim : sitl.sim.Simulation
    collision_prevention : sitl.collision_prevention.CollisionPrevention
    links : callable
        ``() -> list of links``: every link, for the value a set leaves.
    say : callable
        The server's ``(severity, text)`` STATUSTEXT.
    changed : callable
        ``()``: the server's reaction to a changed value (``apply`` and its own).
    """

    def __init__(self, params, autopilot, sim, collision_prevention, links, say, changed) -> None:
        self.params, self.sim, self.collision_prevention = params, sim, collision_prevention
        self.links, self.say, self.changed = links, say, changed
        #: The protocol (``mavcore.services.params``).
        self.server = ParamServer(params, autopilot.param_bytewise)

    def handlers(self) -> dict:
        """Message type -> ``(link, msg)`` handler, for the server's receive table."""
        return {
            "PARAM_REQUEST_LIST": self.on_list,
            "PARAM_REQUEST_READ": self.on_read,
            "PARAM_SET": self.on_set,
        }

    def on_list(self, link, msg) -> None:
        if not codec.addressed_to_us(msg, SYSTEM_ID, COMPONENT_ID):
            return
        for i in self.server.request_list():
            link.reply(self.server.value_message(link.mav, i))

    def on_read(self, link, msg) -> None:
        if not codec.addressed_to_us(msg, SYSTEM_ID, COMPONENT_ID):
            return
        r = self.server.request_read(msg.param_id, msg.param_index)
        if r.index is not None:
            link.reply(self.server.value_message(link.mav, r.index))

    def on_set(self, link, msg) -> None:
        if not codec.addressed_to_us(msg, SYSTEM_ID, COMPONENT_ID):
            return
        r = self.server.set(msg.param_id, msg.param_value, msg.param_type)
        if r.warning is not None:
            self.say(SEVERITY_WARNING, r.warning)
        if r.applied:
            self.changed()
        if r.index is None:
            return
        for l in (self.links() if r.to_all else (link,)):
            if l.has_peer:
                l.send(self.server.value_message(l.mav, r.index))

    def apply(self) -> None:
        """Push the parameter values into the onboard controller, collision
        prevention, the thrust model and the sensors."""
        p = self.params
        sim = self.sim
        ctl = sim.onboard
        ctl.gains = dataclasses.replace(
            ctl.gains, max_speed_xy_m_s=p["MPC_XY_VEL_MAX"], max_speed_up_m_s=p["MPC_Z_VEL_MAX_UP"],
            max_speed_down_m_s=p["MPC_Z_VEL_MAX_DN"], max_tilt_rad=math.radians(p["MPC_TILTMAX_AIR"]))
        cp = self.collision_prevention
        cp.configure(CollisionPreventionConfig(p["CP_DIST"], p["CP_DELAY"], bool(p["CP_GO_NO_DATA"]),
                                               p["MPC_ACC_HOR"]))
        ctl.velocity_limit = cp.limit if cp.cfg.enabled else None
        sim.thrust_model_factor = float(p["THR_MDL_FAC"])
        s = sim.sensors
        s.acc_rel_std = math.sqrt(p["SIM_VEC_VAR"])
        s.mag_std = math.sqrt(p["SIM_VEC_VAR"]) * float(np.linalg.norm(s.mag_earth))
        s.gyro_std = math.sqrt(p["SIM_GYRO_VAR"])
        s.gnss.pos_std_xy_m = p["SIM_POS_STD"]
        s.gnss.pos_std_z_m = p["SIM_POSZ_STD"]
        s.gnss.vel_std_m_s = p["SIM_VEL_STD"]
        s.range_std = p["SIM_RNG_STD"]
        if p["SIM_RNG_HZ"] > 0:   # 0 leaves the configured (or SET_MESSAGE_INTERVAL) rates alone
            for rf in s.rangefinders:
                rf.period_us = max(sim.sensor_period_us, int(round(1e6 / p["SIM_RNG_HZ"])))
