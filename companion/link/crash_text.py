"""The bundled SITL's crash announcement, read back from its STATUSTEXT.

The SITL (``sitl.collision.CrashEvent.text``) sends, with
MAV_SEVERITY_CRITICAL, one STATUSTEXT of at most 50 characters::

    CRASH: cylinder #1 at E10.00 N3.75 U1.20, 1.02 m/s

naming what was hit (``cylinder #k`` / ``box #k``, k numbering
``sim.obstacles`` from 1; ``walker #k`` / ``tractor #k``, k numbering
``sim.movers`` from 1; ``vine row``; ``terrain``), the vehicle centre at
the contact (ENU metres on the map) and its speed. Long numbers shorten it:
first ``CRASH: box #12 E-1234.57 N9876.54 U123.40 12.00m/s``, then fewer
decimals (``CRASH box #12 E-1234.6 ...``). ``parse_crash`` reads every form.
Pure: a string in, a named result out.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

_NUM = r"-?\d+(?:\.\d+)?"
_CRASH = re.compile(
    rf"^CRASH:? (?P<what>(?P<kind>cylinder|box|walker|tractor) #(?P<k>\d+)|vine row|terrain)(?: at)? "
    rf"E(?P<x>{_NUM}) N(?P<y>{_NUM}) U(?P<z>{_NUM}),? (?P<v>{_NUM}) ?m/s$")


@dataclass(frozen=True, slots=True)
class CrashReport:
    """A crash as the vehicle announced it.

    Attributes
    ----------
    what : str
        ``cylinder #1``, ``box #2``, ``vine row`` or ``terrain``.
    kind : str
        ``cylinder``, ``box``, ``row`` or ``terrain``.
    obstacle_index : int or None
        Index in ``sim.obstacles`` (0-based; for a walker or tractor, in
        ``sim.movers``); None for a row or the terrain.
    pos_enu_m : tuple (3,)
        Vehicle centre at the contact (ENU, m; rounded as sent).
    speed_m_s : float
        Speed at the contact (m/s).
    """

    what: str
    kind: str
    obstacle_index: int | None
    pos_enu_m: tuple[float, float, float]
    speed_m_s: float


def parse_crash(text: str) -> CrashReport | None:
    """The crash announced by a STATUSTEXT ``text``; None if it is not one."""
    m = _CRASH.match(text.strip("\0 "))
    if m is None:
        return None
    what = m["what"]
    if m["kind"]:
        kind, index = m["kind"], int(m["k"]) - 1
    else:
        kind, index = ("row" if what == "vine row" else "terrain"), None
    return CrashReport(what, kind, index, (float(m["x"]), float(m["y"]), float(m["z"])), float(m["v"]))
