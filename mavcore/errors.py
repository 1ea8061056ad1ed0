"""Typed errors of the companion.

Every error that a user can cause by bad input derives from ``InputError``;
the CLI turns it into one line ``<file>: <problem>`` and exit code 2.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad user input: a file, a key or a value that cannot be used.

    Parameters
    ----------
    source : str
        The file (and key or line where known) the problem is in.
    problem : str
        What is wrong, in one short clause.
    """

    def __init__(self, source: str, problem: str) -> None:
        super().__init__(f"{source}: {problem}")
        self.source = source
        self.problem = problem


class MissionError(InputError):
    """The mission YAML is missing, malformed or inconsistent."""


class MapError(InputError):
    """An occupancy grid or elevation model cannot be loaded or does not fit."""


class PlanError(InputError):
    """The planner cannot produce a plan from valid-looking input
    (no free space, DEM does not cover the path, ...)."""


class CommandRejected(RuntimeError):
    """The vehicle answered a COMMAND_LONG with a result other than ACCEPTED.

    Parameters
    ----------
    command : int
        MAV_CMD value.
    result : int
        MAV_RESULT value.
    """

    def __init__(self, command: int, result: int, what: str = "") -> None:
        super().__init__(f"command {command}{' (' + what + ')' if what else ''} rejected with MAV_RESULT {result}")
        self.command = command
        self.result = result


class LinkError(RuntimeError):
    """The MAVLink peer did not answer in time or the link failed."""


class UnsafeMessage(ValueError):
    """The companion refused to send a message that breaks
    ``mavcore.link.command_rules`` (a non-finite or out-of-range command
    parameter, setpoint or motor command): nothing was sent.

    Parameters
    ----------
    msg_type : str
        The MAVLink message type.
    problem : str
        What is wrong with it.
    """

    def __init__(self, msg_type: str, problem: str) -> None:
        super().__init__(f"refused to send {msg_type}: {problem}")
        self.msg_type = msg_type
        self.problem = problem


class CampaignError(InputError):
    """A campaign spec or scenario file is missing, malformed or inconsistent."""
