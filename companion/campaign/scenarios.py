"""Scenarios: spec + index -> one flight's scenario (a small dict), deterministically.

Scenario ``i`` draws from ``numpy.random.default_rng(SeedSequence([seed, i]))``
(PCG64): it depends on the spec, its seed and ``i`` only, not on how many
flights are run or in what order. Movers (``movers:``) draw from their own
generator, ``SeedSequence([seed, i, 15])`` (``companion.campaign.movers``). Draws use float64 arithmetic on the
generator's output (``lo + (hi - lo) * u``); the values written are rounded
(obstacles to the millimetre, everything else to 1e-6) so that the last-bit
differences of ``cos``/``sin`` (wind direction) or of the planned path
(obstacle centres) between machines do not show in the scenario file.

The scenario file (YAML, ``DIR/scenarios/NNNN.yaml``, read by ``companion
demo --scenario``) holds: ``campaign``, ``scenario`` (the index), ``mission``
(a bundled name or an absolute path), ``seed`` (the SITL's), ``cut_s``,
``control`` and ``overrides`` (merged into the base mission: mappings merge
key by key, anything else replaces). Its hash is the first 16 hex digits of
the SHA-256 of its canonical JSON (sorted keys, no spaces, ASCII).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mavcore.errors import CampaignError
from .placement import DRAWS_PER_OBSTACLE, Placement, cumulative, footprint_free, propose_obstacle, segment_mask
from .spec import CampaignSpec, StartSpec, dim_range, is_continuous

#: tries of the rejection sampling of a launch point on free cells
START_TRIES = 10_000


@dataclass(frozen=True)
class Field:
    """What the obstacle placement needs of one base mission (computed once per campaign).

    grid : OccupancyGrid of the mission
    path : (N, 3) ENU m, the flown (cut) trajectory
    cum : (N,) m, arc length over the segments allowed by the spec's placement rule
    """

    grid: object
    path: np.ndarray
    cum: np.ndarray


def mission_ref(name: str, base_dir: str, source: str = "<spec>") -> str:
    """A bundled mission name stays a name; anything else is a path made absolute."""
    from ..bundled import missions_dir

    if "/" not in name and not name.endswith((".yaml", ".yml")) and (missions_dir() / name / "mission.yaml").exists():
        return name
    p = Path(name)
    p = p if p.is_absolute() else Path(base_dir) / p
    if p.is_dir():
        p = p / "mission.yaml"
    if not p.is_file():
        raise CampaignError(f"{source}: key 'missions'", f"{name}: no such bundled mission or mission file")
    return str(p.resolve())


def mission_path(ref: str) -> Path:
    from ..bundled import missions_dir

    p = Path(ref)
    return p if p.is_absolute() else missions_dir() / ref / "mission.yaml"


def load_fields(spec: CampaignSpec) -> dict[str, Field]:
    """The I/O edge: load and plan every base mission (needed only with ``obstacles`` or ``start``)."""
    from mavcore.mission import load_mission
    from .placement import flown_path

    fields = {}
    for name in spec.missions:
        ref = mission_ref(name, spec.base_dir, spec.source)
        if ref in fields:
            continue
        if spec.obstacles is None and spec.movers is None and spec.start is None:
            fields[ref] = None
            continue
        grid, path, _ = flown_path(load_mission(mission_path(ref)), spec.cut_s)
        placement = spec.obstacles.placement if spec.obstacles is not None else "path"
        fields[ref] = Field(grid, path, cumulative(path, segment_mask(path, placement)))
    return fields


class _Draws:
    """Named draws: from ``unit`` (a point of the unit cube, the search) where it names the draw,
    else from the generator."""

    def __init__(self, rng: np.random.Generator, unit: dict[str, float] | None = None) -> None:
        self.rng = rng
        self.unit = unit or {}

    def uniform(self, name: str, lo: float, hi: float) -> float:
        if name in self.unit:
            return lo + (hi - lo) * float(self.unit[name])
        return float(self.rng.uniform(lo, hi))

    def choice(self, seq):
        return seq[int(self.rng.integers(len(seq)))] if len(seq) > 1 else seq[0]


def _placement(spec: CampaignSpec) -> Placement:
    o = spec.obstacles
    return Placement(kinds=tuple(o.kinds), radius_m=dim_range(o.cylinder_radius_m), side_m=dim_range(o.box_side_m),
                     yaw_deg=dim_range(o.box_yaw_deg), height_m=dim_range(o.height_m), offset_m=o.offset_m,
                     keep_out_m=o.keep_out_m, margin_m=o.margin_m)


def continuous_dims(spec: CampaignSpec) -> list[str]:
    """Names of the continuous dimensions (what ``--search`` moves in [0, 1]), in a fixed order.

    Obstacles: ``count`` max obstacles of ``DRAWS_PER_OBSTACLE`` draws each
    (arc length, offset, height, kind, sizes); a point whose obstacle is
    rejected (near launch or end, not on free cells) flies without it.
    """
    names = []
    if spec.obstacles is not None:
        names += [f"obstacle{k}.{j}" for k in range(spec.obstacles.count[1]) for j in range(DRAWS_PER_OBSTACLE)]
    if spec.sensors is not None:
        for key in ("velocity_std_m_s", "position_std_m", "gyro_bias_rad_s", "range_std_m",
                    "range_dropout_probability"):
            d = getattr(spec.sensors, key)
            if d is not None and is_continuous(d):
                names.append(f"sensors.{key}")
    if spec.wind is not None:
        for key in ("speed_m_s", "direction_deg", "gust_std_m_s"):
            if is_continuous(getattr(spec.wind, key)):
                names.append(f"wind.{key}")
    if spec.link is not None:
        for key in ("loss", "delay_min_ms", "jitter_ms"):
            if is_continuous(getattr(spec.link, key)):
                names.append(f"link.{key}")
    if spec.start is not None:
        for key in ("offset_m", "direction_deg"):
            if is_continuous(getattr(spec.start, key)):
                names.append(f"start.{key}")
    return names


def _start_point(st: StartSpec, f: Field, dr: _Draws, search: bool, source: str) -> list[float] | None:
    """The launch point [x, y] (ENU m, rounded to the mm): ``offset_m`` from the flown
    trajectory's first point towards ``direction_deg``, a disk of ``margin_m`` on free cells.

    Monte Carlo: rejection-sampled (CampaignError when ``START_TRIES`` draws all fail);
    search: one proposal, None (the default launch point) when it is rejected."""
    x0, y0 = float(f.path[0, 0]), float(f.path[0, 1])
    for _ in range(1 if search else START_TRIES):
        r = dr.uniform("start.offset_m", *dim_range(st.offset_m))
        a = math.radians(dr.uniform("start.direction_deg", *dim_range(st.direction_deg)))
        x, y = round(x0 + r * math.cos(a), 3) + 0.0, round(y0 + r * math.sin(a), 3) + 0.0
        if footprint_free(f.grid, {"type": "cylinder", "x": x, "y": y, "radius": st.margin_m}, 0.0):
            return [x, y]
    if search:
        return None
    raise CampaignError(f"{source}: key 'start'", f"no launch point on free cells in {START_TRIES} draws")


def scenario(spec: CampaignSpec, fields: dict[str, Field], index: int,
             unit: dict[str, float] | None = None) -> dict:
    """The scenario of flight ``index`` (see the module docstring).

    ``unit``: for the falsification search, values in [0, 1] of (some of)
    ``continuous_dims(spec)``; the obstacle count is then its maximum and a
    rejected obstacle is left out. Without it: Monte Carlo, every draw from
    the index's generator.
    """
    rng = np.random.default_rng(np.random.SeedSequence([spec.seed, index]))
    dr = _Draws(rng, unit)
    refs = list(fields)
    ref = dr.choice(refs)
    control = dr.choice(spec.control)
    sim_seed = int(rng.integers(0, 2**31 - 1))
    sim: dict = {}
    if spec.obstacles is not None:
        o = spec.obstacles
        f = fields[ref]
        p = _placement(spec)
        if unit is None:
            from .placement import random_obstacle

            n = int(rng.integers(o.count[0], o.count[1] + 1))
            try:
                obstacles = [random_obstacle(rng, f.grid, f.path, f.cum, p) for _ in range(n)]
            except ValueError as exc:
                raise CampaignError(f"{spec.source}: key 'obstacles'", f"{ref}: {exc}") from None
        else:
            obstacles = []
            for k in range(o.count[1]):
                j = iter(range(DRAWS_PER_OBSTACLE))
                ob = propose_obstacle(lambda lo, hi, k=k: dr.uniform(f"obstacle{k}.{next(j)}", lo, hi),
                                      f.grid, f.path, f.cum, p)
                if ob is not None:
                    obstacles.append(ob)
        sim["obstacles"] = obstacles
    if spec.movers is not None:
        from .movers import scenario_movers

        sim["movers"] = scenario_movers(spec.seed, index, fields[ref].path, spec.movers)
    if spec.sensors is not None:
        s = spec.sensors
        profile = dr.choice(s.profiles)
        if profile != "none":
            sim["sensor_profile"] = profile
        noise = {}
        for key in ("velocity_std_m_s", "position_std_m", "gyro_bias_rad_s", "range_std_m"):
            d = getattr(s, key)
            if d is None:
                continue
            v = round(dr.uniform(f"sensors.{key}", *dim_range(d)), 6)
            noise[key] = [v, v, v] if key == "gyro_bias_rad_s" else v
        if noise:
            sim["noise"] = noise
    if spec.wind is not None:
        w = spec.wind
        speed = dr.uniform("wind.speed_m_s", *dim_range(w.speed_m_s))
        direction = math.radians(dr.uniform("wind.direction_deg", *dim_range(w.direction_deg)))
        sim["wind"] = {"mean_enu_m_s": [round(speed * math.cos(direction), 6) + 0.0,
                                        round(speed * math.sin(direction), 6) + 0.0, 0.0],
                       "gust_std_m_s": round(dr.uniform("wind.gust_std_m_s", *dim_range(w.gust_std_m_s)), 6),
                       "gust_time_constant_s": w.gust_time_constant_s, "drag_n_s_m": w.drag_n_s_m}
    # Drawn after everything above, so that adding these keys to a spec moves no earlier draw.
    if spec.sensors is not None and spec.sensors.range_dropout_probability is not None:
        d = spec.sensors.range_dropout_probability
        v = round(dr.uniform("sensors.range_dropout_probability", *dim_range(d)), 6)
        sim.setdefault("noise", {})["range_dropout_probability"] = v
    link = None
    if spec.link is not None:
        L = spec.link
        loss = round(dr.uniform("link.loss", *dim_range(L.loss)), 6)
        d0 = round(dr.uniform("link.delay_min_ms", *dim_range(L.delay_min_ms)), 6)
        jitter = round(dr.uniform("link.jitter_ms", *dim_range(L.jitter_ms)), 6)
        link = {"loss": loss, "delay_ms": [d0, round(d0 + jitter, 6)]}
    if spec.start is not None:
        start = _start_point(spec.start, fields[ref], dr, unit is not None, spec.source)
        if start is not None:
            sim["start_enu_m"] = start
    overrides = {"sim": sim} if sim else {}
    if sim.get("movers"):
        overrides["replan"] = {"give_way": True}    # people and machines move here: bound the closing speed
    out = {"campaign": spec.name, "scenario": int(index), "mission": ref, "seed": sim_seed,
           "cut_s": spec.cut_s, "control": control, "overrides": overrides}
    if link is not None:
        out["link"] = link
    return out


def canonical_json(s: dict) -> str:
    """The scenario's canonical serialisation (what its hash is taken of)."""
    return json.dumps(s, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)


def scenario_hash(s: dict) -> str:
    """First 16 hex digits of the SHA-256 of ``canonical_json(s)``."""
    return hashlib.sha256(canonical_json(s).encode("ascii")).hexdigest()[:16]


def scenario_params(s: dict) -> dict:
    """Flat parameter columns of the results table."""
    sim = (s.get("overrides") or {}).get("sim") or {}
    obstacles = sim.get("obstacles")
    wind = sim.get("wind") or {}
    noise = sim.get("noise") or {}
    mean = wind.get("mean_enu_m_s") or [0.0, 0.0, 0.0]
    gb = noise.get("gyro_bias_rad_s")
    return {
        "n_obstacles": None if obstacles is None else len(obstacles),
        "max_obstacle_height_m": max((o["height"] for o in obstacles), default=None) if obstacles else None,
        "obstacles": None if obstacles is None else json.dumps(obstacles, separators=(",", ":")),
        "wind_east_m_s": mean[0], "wind_north_m_s": mean[1],
        "wind_speed_m_s": math.hypot(mean[0], mean[1]),
        "gust_std_m_s": wind.get("gust_std_m_s"),
        "sensor_profile": sim.get("sensor_profile"),
        "velocity_std_m_s": noise.get("velocity_std_m_s"),
        "position_std_m": noise.get("position_std_m"),
        "gyro_bias_rad_s": None if gb is None else gb[0],
        "range_std_m": noise.get("range_std_m"),
        "range_dropout_probability": noise.get("range_dropout_probability"),
        "link_loss": (s.get("link") or {}).get("loss"),
        "link_delay_min_ms": ((s.get("link") or {}).get("delay_ms") or [None, None])[0],
        "link_delay_max_ms": ((s.get("link") or {}).get("delay_ms") or [None, None])[1],
        "start_x_m": (sim.get("start_enu_m") or [None, None])[0],
        "start_y_m": (sim.get("start_enu_m") or [None, None])[1],
    }


def scenario_yaml(s: dict) -> str:
    """The scenario file's text (floats written with repr by PyYAML: they read back bit for bit)."""
    import yaml

    head = (f"# scenario {s['scenario']} of campaign {s['campaign']}, hash {scenario_hash(s)}\n"
            f"# reproduce: companion demo --scenario THIS_FILE\n")
    return head + yaml.safe_dump(s, sort_keys=False, default_flow_style=None, width=120)
