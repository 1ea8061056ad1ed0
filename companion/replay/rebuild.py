"""Rebuild a recorded flight's ``FlightCore`` from its setup record (pure).

``companion fly``/``demo`` send their setup at connection as chunked
STATUSTEXT (``companion.flight.setup_record``): mission name and file
hashes, plan file hash, ``--cut``, control mode, runner overrides.
``SetupCollector`` finds it among a .tlog's records; ``build_core`` builds the
same core from it, the loaded mission and its flight plan (the caller loads the
files); ``setup_mismatches`` says which files differ from the recorded ones.
"""

from __future__ import annotations

from ..flight.config import RunnerConfig
from ..flight.core import FlightCore
from ..flight.setup_record import PREFIX, SETUP_TEXT_ID, parse_setup

#: The setup record format this replay understands.
SETUP_FORMAT = "companion-setup/1"
_FILE_KEYS = (("mission_sha", "mission file"), ("map_sha", "map file"), ("dem_sha", "DEM file"),
              ("plan_sha", "plan file"))


class SetupCollector:
    """Collects the setup record from the companion's STATUSTEXTs.

    ``feed(msg)`` with each decoded companion STATUSTEXT; ``setup`` is the
    parsed dict once every chunk is in (None before). ``complete`` tells
    whether the last chunk was seen.
    """

    def __init__(self) -> None:
        self._texts: list = []
        self.setup: dict | None = None
        self.complete = False

    def feed(self, msg) -> dict | None:
        if self.complete or getattr(msg, "id", 0) != SETUP_TEXT_ID:
            return self.setup
        text = str(msg.text)
        if not text.startswith(PREFIX):
            return None
        self._texts.append((text, SETUP_TEXT_ID, int(msg.chunk_seq)))
        try:
            self.setup = parse_setup(self._texts)
        except ValueError:          # not all chunks yet (or malformed: ``finish`` says which)
            return None
        self.complete = True
        return self.setup

    def finish(self) -> dict | None:
        """The setup, or None without any chunk. Raises ValueError when chunks
        were seen but the record is incomplete or not JSON."""
        if self.complete:
            return self.setup
        if not self._texts:
            return None
        return parse_setup(self._texts)   # raises with the reason


def _tuples(v):
    return tuple(_tuples(x) for x in v) if isinstance(v, list) else v


def runner_config(setup: dict) -> RunnerConfig:
    """The flight's ``RunnerConfig`` (control mode and the runner overrides it recorded).

    Raises
    ------
    ValueError
        An unknown or invalid key (a setup record from another version).
    """
    overrides = {k: _tuples(v) for k, v in dict(setup.get("runner") or {}).items()}
    try:
        return RunnerConfig(control=setup["control"], **overrides)
    except TypeError as exc:
        raise ValueError(f"runner settings this version does not know ({exc})") from None
    except KeyError:
        raise ValueError("no control mode") from None


def build_core(setup: dict, mission, flight_plan) -> FlightCore:
    """The ``FlightCore`` of the recorded flight.

    Parameters
    ----------
    setup : dict
        The recorded setup record.
    mission : mavcore.mission.Mission
        The mission loaded from the same file.
    flight_plan : companion.flight_plan.FlightPlan
        From ``companion.commands.fly.prepare`` with the same plan source,
        not yet cut: the recorded ``cut_s`` is applied here, as ``execute`` does.

    Raises
    ------
    ValueError
        The setup record is not one this version can replay.
    """
    from ..assembly import build_flight_core
    from ..flight_plan import sensor_coverage_gate, slowed_mission

    if setup.get("format") != SETUP_FORMAT:
        raise ValueError(f"setup record format {setup.get('format')!r}, expected {SETUP_FORMAT!r}")
    cfg = runner_config(setup)
    cut_s = setup.get("cut_s")
    if cut_s is not None:
        flight_plan = flight_plan.cut(float(cut_s), mission.trajectory)
    # the pre-flight sensor coverage check, as ``execute`` made it (recordings before it: refuse)
    flight_plan, coverage_doc = sensor_coverage_gate(mission, flight_plan, setup.get("sensor_gap", "refuse"))
    core = build_flight_core(slowed_mission(mission, coverage_doc["time_scale"]), flight_plan, cfg, setup)
    core.sensor_coverage = coverage_doc
    return core


def setup_mismatches(recorded: dict, current: dict) -> list[str]:
    """One line per input that differs between the recorded setup and ``current``
    (``companion.commands.fly.flight_setup`` of the files given to replay)."""
    out = []
    if recorded.get("mission") != current.get("mission"):
        out.append(f"mission name {current.get('mission')!r} differs from the recorded {recorded.get('mission')!r}")
    for key, what in _FILE_KEYS:
        a, b = recorded.get(key), current.get(key)
        if a != b and not (key == "plan_sha" and a is None and b is None):
            if key == "plan_sha" and a is None:
                out.append("the flight planned in flight (no plan file); replaying from --plan: the trajectory "
                           "from the plan's rounded way-points may differ in the last bits")
            elif key == "plan_sha" and b is None:
                out.append(f"the flight flew a plan file (sha {a}); none given")
            else:
                out.append(f"{what} differs from the recorded one (sha {b}, recorded {a})")
    if recorded.get("version") != current.get("version"):
        out.append(f"companion version {current.get('version')} replays a flight of version {recorded.get('version')}")
    return out
