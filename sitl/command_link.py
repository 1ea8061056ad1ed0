"""COMMAND_LONG and COMMAND_INT on the vehicle: each command through
``mavcore.services.command.CommandServer`` (the rule table, then the
vehicle's handler, ``sitl.commands``), its COMMAND_ACK and the messages that
follow it to the link and requester it came from.

A command without a handler is counted (the server's link report); one the
rules refuse is counted and said (the server's ``refuse``).
"""

from __future__ import annotations

from mavcore import codec
from mavcore.link import command_rules as rules
from mavcore.services.command import ack_message

from .vehicle_id import COMPONENT_ID, SYSTEM_ID


class CommandLink:
    """The COMMAND_LONG / COMMAND_INT handlers.

    Parameters
    ----------
    commands : mavcore.services.command.CommandServer
    stack : sitl.flightstack.FlightStack
        Armed or not (with ``state``: whether the vehicle is on the ground).
    state : callable
        ``() -> NavState``: what the flight stack knows now.
    unsupported : collections.Counter
        MAV_CMD -> times asked for without a handler.
    refuse : callable
        The server's ``(kind, why)`` refusal count and text.
    """

    def __init__(self, commands, stack, state, unsupported, refuse) -> None:
        self.commands, self.stack, self.state = commands, stack, state
        self.unsupported, self.refuse = unsupported, refuse

    def handlers(self) -> dict:
        """Message type -> ``(link, msg)`` handler, for the server's receive table."""
        return {"COMMAND_LONG": self.on_command_long, "COMMAND_INT": self.on_command_int}

    def on_command_long(self, link, msg) -> None:
        if not codec.addressed_to_us(msg, SYSTEM_ID, COMPONENT_ID):
            return
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        self._command(link, msg, int(msg.command), params)

    def on_command_int(self, link, msg) -> None:
        if not codec.addressed_to_us(msg, SYSTEM_ID, COMPONENT_ID):
            return
        params = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
        self._command(link, msg, int(msg.command), params, int(msg.frame))

    def _command(self, link, msg, command: int, params, int_frame: int | None = None) -> None:
        landed = command in self.commands.handlers and (not self.stack.armed or self.state().landed)
        reply = self.commands.handle(command, params, int_frame, landed)
        if reply.unsupported:
            self.unsupported[command] += 1
        elif reply.refused is not None:
            self.refuse(rules.command_name(command), reply.refused)
        link.reply(ack_message(link.mav, command, reply, msg.get_srcSystem(), msg.get_srcComponent()))
        for m in reply.after:
            link.reply(m)
