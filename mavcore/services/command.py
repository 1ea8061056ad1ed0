"""The MAVLink command protocol, both sides, as pure state machines.

https://mavlink.io/en/services/command.html: a client sends COMMAND_LONG
(or COMMAND_INT); the vehicle answers every command it receives with one
COMMAND_ACK carrying a MAV_RESULT (MAV_RESULT_IN_PROGRESS first for a long
one, then the final result). A client that hears no ACK sends the command
again with ``confirmation`` incremented; the vehicle treats a repeat like
the first.

- ``CommandServer`` (the SITL, ``sitl.server``): checks a command against
  ``mavcore.link.command_rules``, runs its handler and says what the ACK
  carries (``CommandReply``), exactly one ACK per command received.
- ``CommandClient`` (the companion, ``companion.flight.core``): one command
  with its re-sends, its wait for a final ACK, a back-off on
  TEMPORARILY_REJECTED, and an ``effect`` that ends it without an ACK (the
  vehicle was seen doing what was asked) on the caller's clock.

No sockets, no clock.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from mavcore.errors import CommandRejected, LinkError
from mavcore.link import command_rules as rules

from .base import ClientTransaction, elapsed_s

#: Sends of a command before the client gives up (8 round trips over a link
#: losing 20 % each way all fail 0.03 % of the time: 1 - 0.8^2 = 36 % each).
COMMAND_SENDS = 8
#: Wait after TEMPORARILY_REJECTED before the next send (s, caller's clock).
TEMP_REJECT_WAIT_S = 0.5


# --- server side (the vehicle) ----------------------------------------------------


@dataclass(frozen=True, slots=True)
class CommandReply:
    """What one received command gets: the ACK's ``result``, the messages
    that follow the ACK (``after``), and why it was refused by the rules
    (``refused``, for the vehicle's STATUSTEXT) or None; ``unsupported``:
    no handler (MAV_RESULT_UNSUPPORTED)."""

    result: int
    after: tuple = ()
    refused: str | None = None
    unsupported: bool = False


class CommandServer:
    """The vehicle's command table: MAV_CMD -> ``handler(params, int_frame)``.

    A handler returns ``(MAV_RESULT, messages to send after the ACK or None)``;
    it may raise ValueError / OverflowError / TypeError on parameters it cannot
    use (DENIED); any other exception is a fault of the vehicle (FAILED): the
    peer still gets its one ACK.
    """

    def __init__(self, handlers: dict) -> None:
        self.handlers = dict(handlers)

    def handle(self, command: int, params, int_frame: int | None = None, landed: bool = False) -> CommandReply:
        """One COMMAND_LONG (``int_frame`` None) or COMMAND_INT (its frame); ``params``: param1..7."""
        handler = self.handlers.get(command)
        if handler is None:
            return CommandReply(mavlink.MAV_RESULT_UNSUPPORTED, unsupported=True)
        why = rules.command_problem(command, params, int_frame=int_frame, landed=landed)
        if why is not None:      # even from an allowed controller
            return CommandReply(mavlink.MAV_RESULT_DENIED, refused=why)
        try:
            result, after = handler(params, int_frame)
        except (ValueError, OverflowError, TypeError):   # unusable parameters
            return CommandReply(mavlink.MAV_RESULT_DENIED)
        except Exception:   # a fault of ours: still exactly one ACK (command protocol)
            return CommandReply(mavlink.MAV_RESULT_FAILED)
        return CommandReply(result, tuple(after or ()))


def ack_message(mav, command: int, reply: CommandReply, requester_system: int, requester_component: int):
    """The COMMAND_ACK of ``reply``, addressed to the requester."""
    return mav.command_ack_encode(command, reply.result, 0, 0, requester_system, requester_component)


# --- client side (the companion) ------------------------------------------------


def command_long(mav, target_system: int, target_component: int, command: int, params=(), confirmation: int = 0):
    """COMMAND_LONG with ``params`` padded to seven with zeros (floats)."""
    p = [float(x) for x in params]
    p += [0.0] * (7 - len(p))
    return mav.command_long_encode(target_system, target_component, command, min(confirmation, 255), *p[:7])


class CommandClient(ClientTransaction):
    """Send one command and wait for its final COMMAND_ACK.

    Each send waits ``timeout_s`` (restarted by an IN_PROGRESS ACK) for the
    ACK of ``command``; without one the command is sent again, ``sends``
    times in all, then the command fails with ``LinkError`` (``optional``:
    it ends with None instead). TEMPORARILY_REJECTED waits
    ``TEMP_REJECT_WAIT_S`` and sends again, ``temp_retries`` times. ACCEPTED
    ends it with the ACK; any other result with ``CommandRejected`` (or None
    when ``optional``). ``effect_seen`` passed to ``due``/``tick`` while an ACK
    is awaited ends it with None: the vehicle did what was asked, its ACKs
    were lost.
    """

    AWAIT_ACK, BACK_OFF = "await", "back-off"

    def __init__(self, mav, target_system: int, target_component: int, command: int, params=(), what: str = "",
                 timeout_s: float = 1.0, sends: int = COMMAND_SENDS, temp_retries: int = 0,
                 optional: bool = False) -> None:
        self.mav = mav
        self.ts, self.tc = int(target_system), int(target_component)
        self.command = int(command)
        self.params = tuple(params)
        self.what = what
        self.timeout_s = float(timeout_s)
        self.max_sends = int(sends)
        self.temp_retries = int(temp_retries)
        self.optional = bool(optional)
        self.sends = 0
        self.temps = 0
        self.state = self.AWAIT_ACK
        self._t0: float | None = None

    def _send(self, now_s) -> list:
        m = command_long(self.mav, self.ts, self.tc, self.command, self.params, self.sends)
        self.sends += 1
        self.state = self.AWAIT_ACK
        self._t0 = now_s
        return [m]

    def start(self, now_s: float | None) -> list:
        return self._send(now_s)

    def _fail(self, error: Exception) -> None:
        self._finish(None, None if self.optional else error)

    def on_message(self, m, now_s: float | None) -> list:
        if self.done or self.state != self.AWAIT_ACK or m.get_type() != "COMMAND_ACK" or m.command != self.command:
            return []
        result = m.result
        if result == mavlink.MAV_RESULT_IN_PROGRESS:
            self._t0 = now_s          # the final ACK comes later
        elif result == mavlink.MAV_RESULT_ACCEPTED:
            self._finish(m)
        elif result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED and self.temps < self.temp_retries:
            self.temps += 1
            self.state = self.BACK_OFF
            self._t0 = now_s
        else:
            self._fail(CommandRejected(self.command, int(result), self.what))
        return []

    def due(self, now_s: float | None, effect_seen: bool = False) -> bool:
        if self.done:
            return False
        if self.state == self.BACK_OFF:
            return elapsed_s(now_s, self._t0) >= TEMP_REJECT_WAIT_S
        return effect_seen or elapsed_s(now_s, self._t0) > self.timeout_s

    def tick(self, now_s: float | None, effect_seen: bool = False) -> list:
        if not self.due(now_s, effect_seen):
            return []
        if self.state == self.BACK_OFF:
            return self._send(now_s)
        if effect_seen:
            self._finish(None)
            return []
        if self.sends >= self.max_sends:
            what = f" ({self.what})" if self.what else ""
            self._fail(LinkError(f"no COMMAND_ACK for command {self.command}{what} after {self.sends} tries"))
            return []
        return self._send(now_s)
