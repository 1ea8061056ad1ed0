"""The SITL vehicle's commands: what each MAV_CMD does (the handlers of
``mavcore.services.command.CommandServer``).

Each handler takes the command's param1..7 (and the COMMAND_INT frame, None
for COMMAND_LONG) and returns ``(MAV_RESULT, messages after the ACK or
None)``; the protocol around them (the rule table, exactly one ACK, DENIED on
unusable parameters, FAILED on a fault) is the ``CommandServer``'s. The
flight stack does the flying (``sitl.flightstack``); the stream intervals are
the ``StreamSchedule``'s (``mavcore.services.telemetry``); the rangefinder
stream and the messages a request asks for are the ``VehicleTelemetry``'s.

No sockets, no clock: the vehicle time is the simulation's.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from mavcore import codec

from . import mission_store


class VehicleCommands:
    """The MAV_CMDs the SITL executes.

    Parameters
    ----------
    sim : sitl.sim.Simulation
    stack : sitl.flightstack.FlightStack
    autopilot : mavcore.autopilot.Autopilot
    origin : codec.GeoOrigin
    home_enu_m : (3,) array
    streams : mavcore.services.telemetry.StreamSchedule
    telemetry : sitl.telemetry.VehicleTelemetry
    state : callable
        ``() -> NavState``: what the flight stack knows now.
    mav : callable
        ``() -> MAVLink``: the encoder of the messages that follow an ACK.
    """

    def __init__(self, sim, stack, autopilot, origin, home_enu_m, streams, telemetry, state, mav) -> None:
        self.sim, self.stack, self.autopilot = sim, stack, autopilot
        self.origin, self.home_enu_m = origin, home_enu_m
        self.streams, self.telemetry = streams, telemetry
        self.state, self.mav = state, mav

    def table(self) -> dict:
        """MAV_CMD -> handler, for ``CommandServer``."""
        return {
            mavlink.MAV_CMD_COMPONENT_ARM_DISARM: self.arm,
            mavlink.MAV_CMD_NAV_TAKEOFF: self.takeoff,
            mavlink.MAV_CMD_NAV_LAND: self.land,
            mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: self.rtl,
            mavlink.MAV_CMD_DO_SET_MODE: self.set_mode,
            mavlink.MAV_CMD_SET_MESSAGE_INTERVAL: self.set_interval,
            mavlink.MAV_CMD_GET_MESSAGE_INTERVAL: self.get_interval,
            mavlink.MAV_CMD_REQUEST_MESSAGE: self.request_message,
            mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self.capabilities,
            mavlink.MAV_CMD_GET_HOME_POSITION: self.home,
            mavlink.MAV_CMD_MISSION_START: self.mission_start,
            mavlink.MAV_CMD_DO_REPOSITION: self.reposition,
        }

    def arm(self, p, int_frame=None):
        now, st = self.sim.time_us, self.state()
        force = p[1] == codec.ARM_FORCE_MAGIC
        if p[0] == 1.0:
            r = self.stack.arm(now, st, force)
        elif p[0] == 0.0:
            r = self.stack.disarm(now, st, force)
        else:
            return mavlink.MAV_RESULT_DENIED, None
        return r.result, None

    def takeoff(self, p, int_frame=None):
        if self.autopilot.takeoff_alt_relative:     # ArduCopter: metres above home
            z = float(self.home_enu_m[2]) + float(p[6]) if math.isfinite(p[6]) else None
        else:
            z = codec.decode_takeoff_altitude(p[6], self.origin.alt_m)
        return self.stack.takeoff(self.sim.time_us, self.state(), z).result, None

    def land(self, p, int_frame=None):
        return self.stack.land(self.sim.time_us, self.state()).result, None

    def rtl(self, p, int_frame=None):
        return self.stack.return_to_launch(self.sim.time_us, self.state()).result, None

    def set_mode(self, p, int_frame=None):
        if not all(math.isfinite(x) for x in p[:3]):
            return mavlink.MAV_RESULT_DENIED, None
        if not int(p[0]) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return mavlink.MAV_RESULT_DENIED, None
        mode = self.stack.mode_of(self.autopilot.custom_mode_from_params(p[1], p[2]))
        return self.stack.set_mode(self.sim.time_us, self.state(), mode).result, None

    def set_interval(self, p, int_frame=None):
        mid, iv = int(p[0]), p[1]
        if mid != mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR:
            return self.streams.set_interval(mid, iv, self.sim.time_us), None
        if not math.isfinite(iv):
            return mavlink.MAV_RESULT_DENIED, None
        iv = int(iv)
        self.telemetry.ranges_off = iv < 0
        for rf in self.sim.sensors.rangefinders:
            rf.period_us = max(1, int(round(1e6 / rf.cfg.rate_hz))) if iv <= 0 else max(self.streams.period_us, iv)
        return mavlink.MAV_RESULT_ACCEPTED, None

    def get_interval(self, p, int_frame=None):
        mid = int(p[0])
        iv = self.streams.get_interval(mid)
        if iv is None:
            return mavlink.MAV_RESULT_UNSUPPORTED, None
        return mavlink.MAV_RESULT_ACCEPTED, [self.mav().message_interval_encode(mid, iv)]

    def request_message(self, p, int_frame=None):
        if not math.isfinite(p[0]):
            return mavlink.MAV_RESULT_DENIED, None
        mid = int(p[0])
        if mid == mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR:
            # the latest reading of each rangefinder (no extra ray cast: that
            # would draw noise from the simulation's generator)
            tb = self.sim.time_us // 1000
            msgs = [codec.distance_sensor(self.mav(), tb, r) for _, r in sorted(self.telemetry.last_ranges.items())]
            return (mavlink.MAV_RESULT_ACCEPTED if msgs else mavlink.MAV_RESULT_FAILED), msgs or None
        enc = self.telemetry.encoders.get(mid)
        if enc is None or self.telemetry.frame is None:
            return mavlink.MAV_RESULT_UNSUPPORTED, None
        m = enc()
        if m is None:
            return mavlink.MAV_RESULT_FAILED, None
        return mavlink.MAV_RESULT_ACCEPTED, [m]

    def capabilities(self, p, int_frame=None):
        return mavlink.MAV_RESULT_ACCEPTED, [self.telemetry.version()]

    def home(self, p, int_frame=None):
        return mavlink.MAV_RESULT_ACCEPTED, [self.telemetry.home()]

    def mission_start(self, p, int_frame=None):
        return self.stack.mission_start_command(self.sim.time_us, self.state(), p[0], p[1]).result, None

    def reposition(self, p, int_frame=None):
        """DO_REPOSITION (MAVSDK ``goto_location``): ``mission_store.reposition_target``."""
        nav = self.state()
        target, speed, yaw = mission_store.reposition_target(self.origin, self.home_enu_m, nav.pos_enu_m, p,
                                                             int_frame)
        return self.stack.reposition(self.sim.time_us, nav, target, speed, yaw).result, None
