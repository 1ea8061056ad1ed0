"""What a controller tells the vehicle to do outside commands: the flight
mode (SET_MODE), offboard setpoints (SET_POSITION_TARGET_LOCAL_NED,
SET_ATTITUDE_TARGET as body rates and thrust) and the obstacle sectors of
collision prevention (OBSTACLE_DISTANCE).

Each message is checked (``mavcore.link.command_rules``,
``mavcore.codec``), decoded into the flight stack's frame (ENU, the stack's
own heading and position) and handed to the flight stack; an unusable one is
refused through the server (counted, one STATUSTEXT a second). Who may send
them was decided before (``sitl.auth``, in the server's dispatch); the
lockstep actuator answer (HIL_ACTUATOR_CONTROLS) is the server's.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

from mavcore import codec
from mavcore.link import command_rules as rules

from .vehicle_id import COMPONENT_ID, SYSTEM_ID


class VehicleSetpoints:
    """The SET_MODE, setpoint and OBSTACLE_DISTANCE handlers.

    Parameters
    ----------
    sim : sitl.sim.Simulation
        The vehicle clock (``time_us``).
    stack : sitl.flightstack.FlightStack
    collision_prevention : sitl.collision_prevention.CollisionPrevention
    state : callable
        ``() -> NavState``: what the flight stack knows now.
    refuse : callable
        The server's ``(kind, why)`` refusal count and text.
    """

    def __init__(self, sim, stack, collision_prevention, state, refuse) -> None:
        self.sim, self.stack, self.collision_prevention = sim, stack, collision_prevention
        self.state, self.refuse = state, refuse

    def handlers(self) -> dict:
        """Message type -> ``(link, msg)`` handler, for the server's receive table."""
        return {
            "SET_MODE": self.on_set_mode,
            "SET_POSITION_TARGET_LOCAL_NED": self.on_position_target,
            "SET_ATTITUDE_TARGET": self.on_attitude_target,
            "OBSTACLE_DISTANCE": self.on_obstacle_distance,
        }

    def on_set_mode(self, link, msg) -> None:
        if msg.target_system != SYSTEM_ID:
            return
        if not int(msg.base_mode) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            self.refuse("SET_MODE", f"base_mode {int(msg.base_mode)} without CUSTOM_MODE_ENABLED")
            return
        mode = self.stack.mode_of(msg.custom_mode)
        if mode is None:
            self.refuse("SET_MODE", f"unknown custom mode {int(msg.custom_mode)}")
            return
        self.stack.set_mode(self.sim.time_us, self.state(), mode)

    def on_position_target(self, link, msg) -> None:
        if not codec.addressed_to_us(msg, SYSTEM_ID, COMPONENT_ID):
            return
        why = rules.position_target_problem(
            msg.coordinate_frame, msg.type_mask,
            (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz, msg.afx, msg.afy, msg.afz), msg.yaw, msg.yaw_rate)
        if why is not None:
            self.refuse("SET_POSITION_TARGET_LOCAL_NED", why)
            return
        nav = self.state()   # the flight stack's own heading and position (estimate or truth)
        target = codec.decode_position_target(msg, nav.yaw_enu_rad, nav.pos_enu_m)
        if target is not None:
            self.stack.offboard_setpoint(self.sim.time_us, target)

    def on_attitude_target(self, link, msg) -> None:
        if not codec.addressed_to_us(msg, SYSTEM_ID, COMPONENT_ID):
            return
        sp, why = codec.decode_attitude_rates(msg)
        if why is not None:
            self.refuse("SET_ATTITUDE_TARGET", why)
            return
        self.stack.rate_setpoint(self.sim.time_us, sp)

    def on_obstacle_distance(self, link, msg) -> None:
        sectors = codec.decode_obstacle_distance(msg)
        if sectors is not None:
            self.collision_prevention.on_sectors(sectors, self.sim.time_us)
