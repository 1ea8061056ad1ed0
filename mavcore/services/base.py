"""What every client state machine of ``mavcore.services`` shares (pure).

A client transaction (send a command, upload a mission, read a parameter)
is driven from outside with three calls, all taking the caller's clock
``now_s`` (seconds; the companion passes vehicle time, a test may pass
wall time; ``None`` before the clock is known reads as "no time passed"):

- ``start(now_s)``: the messages that open the transaction;
- ``on_message(msg, now_s)``: a decoded message from the vehicle; returns
  the messages to send in answer (messages not of this protocol: ``[]``);
- ``due(now_s, effect_seen)`` / ``tick(now_s, effect_seen)``: whether time
  (or an effect seen elsewhere, e.g. a mode change that shows a command
  was obeyed) calls for an action, and that action's messages.

When ``done`` the transaction has its ``outcome()``: the result, or the
typed error (``CommandRejected``, ``LinkError``, ...) raised there.
"""

from __future__ import annotations


def elapsed_s(now_s: float | None, t0_s: float | None) -> float:
    """``now_s - t0_s``; 0 while either is unknown."""
    return (now_s - t0_s) if (now_s is not None and t0_s is not None) else 0.0


class ClientTransaction:
    """Base of the client state machines: the finished state and its outcome."""

    done: bool = False
    _result = None
    _error: Exception | None = None

    def _finish(self, result=None, error: Exception | None = None) -> None:
        self.done = True
        self._result = result
        self._error = error

    def outcome(self):
        """The result of a finished transaction; raises its error if it failed."""
        if not self.done:
            raise RuntimeError("transaction not finished")
        if self._error is not None:
            raise self._error
        return self._result
