"""The reference handed to the controller and the setpoint stream, one per frame.

``RefSample`` is the runner's per-frame reference (identical to the class
``companion/runner.py`` defines today; the runner is to import it from here).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class RefSample:
    """A reference sample: position and its four derivatives (ENU) and the pointing direction.

    ``p`` m, ``v`` m/s, ``a`` m/s^2, ``jerk`` m/s^3, ``snap`` m/s^4, ``s``
    unit pointing vector (eq. 21); all float tuples (3,). ``target``: the
    pointing target S_p handed to the controller (None: the mission's).
    """

    p: tuple
    v: tuple
    a: tuple
    jerk: tuple
    snap: tuple
    s: tuple
    target: tuple | None = None
