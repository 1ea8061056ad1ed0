"""Scenarios: spec + index -> one flight's scenario (a small dict), deterministically.

Scenario ``i`` draws from ``numpy.random.default_rng(SeedSequence([seed, i]))``
(PCG64): it depends on the spec, its seed and ``i`` only, not on how many
flights are run or in what order. Movers (``movers:``) draw from their own
generator, ``SeedSequence([seed, i, 15])`` (``companion.campaign.movers``), and
so does the choice of the whole trajectory (``whole_fraction > 0`` only):
``SeedSequence([seed, i, 16])``, one ``random() < whole_fraction``. Draws use float64 arithmetic on the
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
from .placement import (DRAWS_PER_OBSTACLE, Placement, Sites, cumulative, footprint_free, obstacle_site,
                        pick_placement, placement_sites, propose_obstacle)
from .spec import CampaignSpec, StartSpec, dim_range, is_continuous

#: tries of the rejection sampling of a launch point on free cells
START_TRIES = 10_000


@dataclass(frozen=True)
class Field:
    """What the obstacle placement needs of one base mission (computed once per campaign).

    grid : OccupancyGrid of the mission
    path : (N, 3) ENU m, the flown (cut) trajectory
    cum : (N,) m, arc length along it (the ``path`` placement's part: all of it)
    whole : the same of the whole trajectory, when the spec flies some flights whole
        (``whole_fraction > 0``); else None
    sites : the other placements' parts of ``path`` (``placement.placement_sites``);
        None: computed where needed
    """

    grid: object
    path: np.ndarray
    cum: np.ndarray
    whole: Field | None = None
    sites: Sites | None = None


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
    """The I/O edge: load and plan every base mission (needed only with ``obstacles``, ``movers``
    or ``start``), once each: its flown path cut at ``cut_s`` and, with ``whole_fraction > 0``,
    the whole one too."""
    from mavcore.mission import load_mission
    from .placement import planned, sampled_path

    fields = {}
    for name in spec.missions:
        ref = mission_ref(name, spec.base_dir, spec.source)
        if ref in fields:
            continue
        if spec.obstacles is None and spec.movers is None and spec.start is None:
            fields[ref] = None
            continue
        mission = load_mission(mission_path(ref))
        grid, fp = planned(mission)
        whole = None
        if spec.whole_fraction > 0 and spec.cut_s is not None:
            whole = _field(spec, grid, sampled_path(fp, mission, None)[0])
        fields[ref] = _field(spec, grid, sampled_path(fp, mission, spec.cut_s)[0], whole)
    return fields


def _field(spec: CampaignSpec, grid, path: np.ndarray, whole: Field | None = None) -> Field:
    """The Field of one flown path; the placements' parts where the spec's obstacles need more than ``path``."""
    o = spec.obstacles
    sites = None
    if o is not None and set(o.placements) - {"path", "cluster"}:
        sites = placement_sites(path, o.entrance_m)
    return Field(grid, path, cumulative(path), whole, sites)


def flown_field(field: Field | None, whole: bool) -> Field | None:
    """The Field of the trajectory a flight flies: the whole one, or the cut one."""
    if field is None or not whole:
        return field
    if field.whole is None:
        raise ValueError("the field has no whole trajectory (load_fields plans it when whole_fraction > 0)")
    return field.whole


def flies_whole(spec: CampaignSpec, index: int) -> bool:
    """Whether flight ``index`` flies the whole trajectory: ``random() < whole_fraction`` from
    ``SeedSequence([seed, index, 16])``, drawn only when ``whole_fraction > 0``."""
    if spec.whole_fraction <= 0 or spec.cut_s is None:
        return False
    rng = np.random.default_rng(np.random.SeedSequence([spec.seed, index, 16]))
    return bool(rng.random() < spec.whole_fraction)


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
                     keep_out_m=o.keep_out_m, margin_m=o.margin_m, names=o.placements, entrance_m=o.entrance_m,
                     row_end_across_m=o.row_end_across_m, cluster_m=o.cluster_m)


def continuous_dims(spec: CampaignSpec) -> list[str]:
    """Names of the continuous dimensions (what ``--search`` moves in [0, 1]), in a fixed order.

    Obstacles: ``count`` max obstacles of ``DRAWS_PER_OBSTACLE`` draws each
    (the placement's two, height, kind, sizes), each preceded by
    ``obstacle{k}.placement`` (which of the spec's placements) when the spec
    names several; a point whose obstacle is rejected (near launch or end,
    not on free cells) flies without it.
    """
    names = []
    if spec.obstacles is not None:
        several = len(spec.obstacles.placements) > 1
        for k in range(spec.obstacles.count[1]):
            names += [f"obstacle{k}.placement"] if several else []
            names += [f"obstacle{k}.{j}" for j in range(DRAWS_PER_OBSTACLE)]
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


def _random_obstacles(rng: np.random.Generator, f: Field, p: Placement, n: int) -> list[dict]:
    """Monte Carlo: ``n`` obstacles, each its placement (one draw, with several) then
    rejection-sampled there (ValueError naming the placement when none fits)."""
    from .placement import random_obstacle

    obstacles: list[dict] = []
    for _ in range(n):
        name = pick_placement(rng.uniform, p.names)
        site = obstacle_site(name, f.path, f.cum, f.sites, obstacles[-1] if obstacles else None, p)
        try:
            obstacles.append(random_obstacle(rng, f.grid, f.path, f.cum, p, site=site))
        except ValueError as exc:
            raise ValueError(f"placement {name}: {exc}") from None
    return obstacles


def _search_obstacles(dr: _Draws, f: Field, p: Placement, n: int) -> list[dict]:
    """The search: ``n`` obstacles from the point's ``obstacle{k}.*`` coordinates; a rejected one
    is left out (a ``cluster`` obstacle gathers round the last one kept)."""
    obstacles: list[dict] = []
    for k in range(n):
        name = pick_placement(lambda lo, hi, k=k: dr.uniform(f"obstacle{k}.placement", lo, hi), p.names)
        site = obstacle_site(name, f.path, f.cum, f.sites, obstacles[-1] if obstacles else None, p)
        j = iter(range(DRAWS_PER_OBSTACLE))
        ob = propose_obstacle(lambda lo, hi, k=k: dr.uniform(f"obstacle{k}.{next(j)}", lo, hi),
                              f.grid, f.path, f.cum, p, site)
        if ob is not None:
            obstacles.append(ob)
    return obstacles


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
    whole = flies_whole(spec, index)
    f = flown_field(fields[ref], whole)
    sim: dict = {}
    if spec.obstacles is not None:
        o = spec.obstacles
        p = _placement(spec)
        if unit is None:
            n = int(rng.integers(o.count[0], o.count[1] + 1))
            try:
                obstacles = _random_obstacles(rng, f, p, n)
            except ValueError as exc:
                raise CampaignError(f"{spec.source}: key 'obstacles'", f"{ref}: {exc}") from None
        else:
            obstacles = _search_obstacles(dr, f, p, o.count[1])
        sim["obstacles"] = obstacles
    if spec.movers is not None:
        from .movers import scenario_movers

        sim["movers"] = scenario_movers(spec.seed, index, f.path, spec.movers)
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
        start = _start_point(spec.start, f, dr, unit is not None, spec.source)
        if start is not None:
            sim["start_enu_m"] = start
    overrides = {"sim": sim} if sim else {}
    if sim.get("movers"):
        overrides["replan"] = {"give_way": True}    # people and machines move here: bound the closing speed
    out = {"campaign": spec.name, "scenario": int(index), "mission": ref, "seed": sim_seed,
           "cut_s": None if whole else spec.cut_s, "control": control, "overrides": overrides}
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
