"""The campaign spec (YAML): what varies from flight to flight, and how.

A dimension (``Dim``) is either a number (fixed) or a list ``[lo, hi]``
(uniform in it; ``lo < hi`` makes it a *continuous dimension* that
``--search`` optimises over). The spec is a frozen dataclass built by
``mavcore.config.from_dict`` (unknown keys rejected); errors are one line
``<file>: key '<dotted.key>': <problem>`` (``CampaignError``, exit code 2).
Schema: docs/campaign.md.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from mavcore.config import from_dict
from mavcore.errors import CampaignError
from mavcore.inputs import read_text

#: a fixed number, or [lo, hi]: uniform in it
Dim = float | tuple[float, float]

PROFILES = ("none", "icm42688p-bmm150-zedf9p")


def dim_range(d: Dim) -> tuple[float, float]:
    """(lo, hi) of a dimension; a fixed number is (x, x)."""
    if isinstance(d, tuple):
        return (float(d[0]), float(d[1]))
    return (float(d), float(d))


def is_continuous(d: Dim) -> bool:
    lo, hi = dim_range(d)
    return hi > lo


def _check_dim(name: str, d: Dim | None, lo_ok: float, hi_ok: float) -> None:
    if d is None:
        return
    lo, hi = dim_range(d)
    if not (lo <= hi):
        raise ValueError(f"{name}: [lo, hi] needs lo <= hi, got [{lo:g}, {hi:g}]")
    if lo < lo_ok or hi > hi_ok:
        raise ValueError(f"{name} must lie in [{lo_ok:g}, {hi_ok:g}], got {lo:g}..{hi:g}")


#: what ``obstacles.placement`` may name (``companion.campaign.placement`` places each)
PlacementName = Literal["path", "rows", "headlands", "entrances", "row_ends", "cluster"]
PLACEMENT_NAMES = typing.get_args(PlacementName)


@dataclass(frozen=True)
class ObstacleSpec:
    """Unknown obstacles (``sim.obstacles``) placed near the flown path.

    ``placement``: one name, or a list of names of which each obstacle draws
    one, uniformly (a name twice weighs twice). ``path`` anywhere on the
    flown trajectory (cut or whole); ``rows`` on its straight runs along the
    dominant direction (the corridors between the vine rows); ``headlands``
    on the rest (the turns between corridors); ``entrances`` on the first
    ``entrance_m`` of a corridor run the vehicle turns into. A centre is
    uniform in arc length on that part, moved up to ``offset_m`` across the
    direction of travel. ``row_ends``: within ``entrance_m`` along a corridor
    run of its end (or start) where the vehicle turns, and up to
    ``row_end_across_m`` across. ``cluster``: within ``cluster_m`` of the
    flight's previous obstacle (the first: as ``path``). Every centre is at
    least ``keep_out_m`` from the launch point and the end of the flown
    trajectory; the footprint grown by ``margin_m`` lies in free map cells
    (``companion.campaign.placement``).
    """

    count: tuple[int, int] = (0, 3)
    kinds: tuple[Literal["cylinder", "box"], ...] = ("cylinder", "box")
    cylinder_radius_m: Dim = (0.15, 0.4)
    box_side_m: Dim = (0.3, 1.0)
    box_yaw_deg: Dim = (0.0, 90.0)
    height_m: Dim = (0.8, 4.0)
    # a list tried first: a bad single name is then reported as "expected one of ..."
    placement: tuple[str, ...] | PlacementName = "path"
    offset_m: float = 0.8
    keep_out_m: float = 2.5
    margin_m: float = 0.05
    entrance_m: float = 3.0
    row_end_across_m: float = 1.5
    cluster_m: float = 2.0

    @property
    def placements(self) -> tuple[str, ...]:
        """``placement`` as a tuple of names."""
        return (self.placement,) if isinstance(self.placement, str) else tuple(self.placement)

    def __post_init__(self) -> None:
        if not 0 <= self.count[0] <= self.count[1] <= 20:
            raise ValueError(f"obstacles.count: need 0 <= min <= max <= 20, got {list(self.count)}")
        if not self.kinds:
            raise ValueError("obstacles.kinds: at least one kind")
        if not self.placements:
            raise ValueError("obstacles.placement: at least one placement")
        for i, name in enumerate(self.placements):
            if name not in PLACEMENT_NAMES:
                raise ValueError(f"obstacles.placement[{i}]: expected one of "
                                 f"{', '.join(repr(n) for n in PLACEMENT_NAMES)}, got {name!r}")
        _check_dim("obstacles.cylinder_radius_m", self.cylinder_radius_m, 0.01, 50.0)
        _check_dim("obstacles.box_side_m", self.box_side_m, 0.01, 500.0)
        _check_dim("obstacles.box_yaw_deg", self.box_yaw_deg, -360.0, 360.0)
        _check_dim("obstacles.height_m", self.height_m, 0.01, 100.0)
        for name in ("offset_m", "keep_out_m", "margin_m", "row_end_across_m"):
            v = getattr(self, name)
            if not 0 <= v <= 100:
                raise ValueError(f"obstacles.{name} must be in [0, 100] m, got {v:g}")
        for name in ("entrance_m", "cluster_m"):
            v = getattr(self, name)
            if not 0 < v <= 100:
                raise ValueError(f"obstacles.{name} must be in (0, 100] m, got {v:g}")


@dataclass(frozen=True)
class MoverSpec:
    """Moving obstacles (``sim.movers``) placed relative to the flown path's
    corridors or headlands (``companion.campaign.movers``): ``count`` per
    flight, each of a kind from ``kinds``, on a straight path of ``length_m``
    (``across`` or ``along`` a corridor, or along a ``headlands`` turn), at
    ``speed_m_s`` (a walker at most 1.5), setting off ``lead_s`` before the
    vehicle passes (``takeoff_s``: the SITL's boot to trajectory time)."""

    count: tuple[int, int] = (0, 1)
    kinds: tuple[Literal["walker", "tractor"], ...] = ("walker",)
    placement: Literal["across", "along", "headlands"] = "across"
    length_m: float = 6.0
    speed_m_s: Dim = (0.5, 1.5)
    lead_s: Dim = (1.0, 5.0)
    takeoff_s: float = 7.0
    loop: bool = False
    keep_out_m: float = 3.0

    def __post_init__(self) -> None:
        if not 0 <= self.count[0] <= self.count[1] <= 20:
            raise ValueError(f"movers.count: need 0 <= min <= max <= 20, got {list(self.count)}")
        if not self.kinds:
            raise ValueError("movers.kinds: at least one kind")
        _check_dim("movers.speed_m_s", self.speed_m_s, 0.01, 5.0)
        _check_dim("movers.lead_s", self.lead_s, -600.0, 600.0)
        for name, hi in (("length_m", 500.0), ("takeoff_s", 600.0), ("keep_out_m", 100.0)):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0 <= v <= hi):
                raise ValueError(f"movers.{name} must be in [0, {hi:g}], got {v:g}")
        if self.length_m <= 0:
            raise ValueError("movers.length_m must be > 0")


@dataclass(frozen=True)
class SensorSpec:
    """Sensor profile (``sim.sensor_profile``, ``none`` = the mission's) and
    noise levels (``sim.noise``; gyro bias: the same on the three axes)."""

    profiles: tuple[Literal["none", "icm42688p-bmm150-zedf9p"], ...] = ("none",)
    velocity_std_m_s: Dim | None = None
    position_std_m: Dim | None = None
    gyro_bias_rad_s: Dim | None = None
    range_std_m: Dim | None = None
    range_dropout_probability: Dim | None = None

    def __post_init__(self) -> None:
        if not self.profiles:
            raise ValueError("sensors.profiles: at least one profile")
        _check_dim("sensors.velocity_std_m_s", self.velocity_std_m_s, 0.0, 10.0)
        _check_dim("sensors.position_std_m", self.position_std_m, 0.0, 10.0)
        _check_dim("sensors.gyro_bias_rad_s", self.gyro_bias_rad_s, -1.0, 1.0)
        _check_dim("sensors.range_std_m", self.range_std_m, 0.0, 5.0)
        _check_dim("sensors.range_dropout_probability", self.range_dropout_probability, 0.0, 1.0)


@dataclass(frozen=True)
class WindSpec:
    """Mean wind (``sim.wind``): horizontal speed and the direction it blows
    *to* (ENU degrees from east, counter-clockwise), gusts and the drag that
    makes it act on the vehicle."""

    speed_m_s: Dim = 0.0
    direction_deg: Dim = (0.0, 360.0)
    gust_std_m_s: Dim = 0.0
    gust_time_constant_s: float = 2.0
    drag_n_s_m: float = 0.3

    def __post_init__(self) -> None:
        _check_dim("wind.speed_m_s", self.speed_m_s, 0.0, 30.0)
        _check_dim("wind.direction_deg", self.direction_deg, -360.0, 720.0)
        _check_dim("wind.gust_std_m_s", self.gust_std_m_s, 0.0, 15.0)
        if not 0 < self.gust_time_constant_s <= 3600:
            raise ValueError("wind.gust_time_constant_s must be in (0, 3600] s")
        if not 0 <= self.drag_n_s_m <= 10:
            raise ValueError("wind.drag_n_s_m must be in [0, 10] N s/m")


@dataclass(frozen=True)
class LinkSpec:
    """A lossy, jittery link between the companion and the SITL
    (``sitl.relay.UdpRelay``): such a flight runs in real time over UDP.
    Each datagram, each direction, is dropped with probability ``loss`` or
    delayed uniformly in [``delay_min_ms``, ``delay_min_ms`` + ``jitter_ms``]."""

    loss: Dim = 0.0
    delay_min_ms: Dim = 0.0
    jitter_ms: Dim = 0.0

    def __post_init__(self) -> None:
        _check_dim("link.loss", self.loss, 0.0, 0.9)
        _check_dim("link.delay_min_ms", self.delay_min_ms, 0.0, 1000.0)
        _check_dim("link.jitter_ms", self.jitter_ms, 0.0, 1000.0)


@dataclass(frozen=True)
class StartSpec:
    """The launch point (``sim.start_enu_m``): ``offset_m`` from under the
    first point of the flown trajectory, towards ``direction_deg`` (ENU,
    from east, counter-clockwise); a disk of radius ``margin_m`` about it
    lies on free map cells (rejection-sampled)."""

    offset_m: Dim = (0.0, 1.0)
    direction_deg: Dim = (0.0, 360.0)
    margin_m: float = 0.5

    def __post_init__(self) -> None:
        _check_dim("start.offset_m", self.offset_m, 0.0, 100.0)
        _check_dim("start.direction_deg", self.direction_deg, -360.0, 720.0)
        if not 0 <= self.margin_m <= 10:
            raise ValueError(f"start.margin_m must be in [0, 10] m, got {self.margin_m:g}")


@dataclass(frozen=True)
class CampaignSpec:
    """A campaign: base missions, the distributions, the flights and a seed.

    ``whole_fraction``: the probability that a flight flies the whole
    trajectory (its scenario's ``cut_s`` null) instead of the first ``cut_s``
    seconds, drawn from the flight's own generator (``companion.campaign.scenarios``).
    """

    name: str
    missions: tuple[str, ...]
    flights: int
    seed: int = 0
    cut_s: float | None = None
    whole_fraction: float = 0.0
    control: tuple[Literal["companion", "vehicle"], ...] = ("companion",)
    keep_completed_fraction: float = 0.1
    obstacles: ObstacleSpec | None = None
    movers: MoverSpec | None = None
    sensors: SensorSpec | None = None
    wind: WindSpec | None = None
    link: LinkSpec | None = None
    start: StartSpec | None = None
    base_dir: str = dataclasses.field(default=".", init=False, compare=False)   # set by load_spec
    source: str = dataclasses.field(default="<spec>", init=False, compare=False)  # set by load_spec

    def __post_init__(self) -> None:
        if not self.missions:
            raise ValueError("missions: at least one base mission")
        if not 1 <= self.flights <= 10_000_000:
            raise ValueError(f"flights must be in [1, 1e7], got {self.flights}")
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")
        if self.cut_s is not None and not (math.isfinite(self.cut_s) and self.cut_s > 0):
            raise ValueError(f"cut_s must be > 0 s or null, got {self.cut_s}")
        if not 0 <= self.whole_fraction <= 1:
            raise ValueError(f"whole_fraction must be in [0, 1], got {self.whole_fraction:g}")
        if self.whole_fraction > 0 and self.cut_s is None:
            raise ValueError("whole_fraction needs a cut_s: with cut_s null every flight flies the whole trajectory")
        if not self.control:
            raise ValueError("control: at least one of companion, vehicle")
        if not 0 <= self.keep_completed_fraction <= 1:
            raise ValueError("keep_completed_fraction must be in [0, 1]")


def spec_from_dict(data, source: str) -> CampaignSpec:
    """Validate a parsed spec (``CampaignError`` naming ``source`` and the key)."""
    return from_dict(CampaignSpec, data, source, "", CampaignError)


def load_spec(path: str | Path) -> CampaignSpec:
    """Read and validate a campaign spec YAML; mission paths resolve against its directory."""
    p = Path(path)
    from mavcore.inputs_yaml import parse_yaml   # PyYAML on first use
    data = parse_yaml(read_text(p, CampaignError, "campaign spec"), str(p), CampaignError)
    if not isinstance(data, dict):
        raise CampaignError(str(p), "expected a mapping of campaign keys at the top level")
    spec = spec_from_dict(data, str(p))
    return with_source(spec, p)


def with_source(spec: CampaignSpec, path: str | Path) -> CampaignSpec:
    """``spec`` remembering its file (mission paths resolve against its directory)."""
    object.__setattr__(spec, "base_dir", str(Path(path).resolve().parent))
    object.__setattr__(spec, "source", str(path))
    return spec
