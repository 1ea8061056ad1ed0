"""Movers of a campaign scenario (``movers:`` of the spec -> ``sim.movers``).

A mover's path is placed relative to the base mission's flown (cut or whole)
trajectory, sampled every ``STEP_S`` (``placement.flown_path``): a point c
uniform in arc length on the corridors (the straight runs along the dominant
direction, ``placement.segment_mask(..., "rows")``) or on the headlands (the
rest), at least ``keep_out_m`` from the launch point and the end; u the
direction of travel there, n = u turned left. Then

- ``across``: from ``c - n L/2`` to ``c + n L/2`` (L = ``length_m``): a
  worker crossing the corridor (through the rows, which the SITL does not
  collide movers with: where a row has a gap);
- ``along``: from ``c`` to ``c - u L``: walking down the corridor toward the
  oncoming vehicle;
- ``headlands``: from ``c - u L/2`` to ``c + u L/2``: along the headland.

It sets off ``lead_s`` before the vehicle passes c: ``start_s = takeoff_s +
t_c - lead_s`` (t_c the trajectory time at c, ``takeoff_s`` the SITL's boot to
trajectory time), at least 0. A walker's speed is at most 1.5 m/s.

Pure: arrays and a ``numpy.random.Generator`` in, dicts (the scenario
file's ``sim.movers`` items, rounded to the millimetre) out.
"""

from __future__ import annotations

import numpy as np

from mavcore.mission.sim import WALKER_MAX_SPEED_M_S
from .placement import arc_point, cumulative, segment_mask

#: Sampling step (s) of the flown path (``placement.flown_path``'s default).
STEP_S = 0.05


def random_mover(rng: np.random.Generator, path: np.ndarray, m) -> dict | None:
    """One mover of the spec ``m`` (``companion.campaign.spec.MoverSpec``) drawn with
    ``rng``; None when the allowed part of the path is empty or the point is
    within ``keep_out_m`` of the launch or the end (the draw is not repeated:
    the scenario then has one mover fewer)."""
    mask = segment_mask(path, "headlands" if m.placement == "headlands" else "rows")
    cum = cumulative(path, mask)
    s = float(rng.uniform(0.0, 1.0)) * float(cum[-1])
    kind = m.kinds[int(rng.integers(len(m.kinds)))]
    lo, hi = (m.speed_m_s, m.speed_m_s) if not isinstance(m.speed_m_s, tuple) else m.speed_m_s
    speed = float(rng.uniform(lo, hi)) if hi > lo else float(lo)
    lo, hi = (m.lead_s, m.lead_s) if not isinstance(m.lead_s, tuple) else m.lead_s
    lead = float(rng.uniform(lo, hi)) if hi > lo else float(lo)
    if cum[-1] <= 0.0:
        return None
    at = arc_point(path, cum, s)
    if at is None:
        return None
    i, f, d, nd = at
    c = path[i, :2] + f * d
    if np.hypot(*(c - path[0, :2])) < m.keep_out_m or np.hypot(*(c - path[-1, :2])) < m.keep_out_m:
        return None
    u = d / nd
    n = np.array([-u[1], u[0]])
    L = m.length_m
    if m.placement == "across":
        a, b = c - 0.5 * L * n, c + 0.5 * L * n
    elif m.placement == "along":
        a, b = c, c - L * u
    else:
        a, b = c - 0.5 * L * u, c + 0.5 * L * u
    if kind == "walker":
        speed = min(speed, WALKER_MAX_SPEED_M_S)
    start = max(0.0, float(m.takeoff_s + (i + f) * STEP_S - lead))
    return {"type": kind, "path": [[round(float(a[0]), 3), round(float(a[1]), 3)],
                                   [round(float(b[0]), 3), round(float(b[1]), 3)]],
            "speed_m_s": round(speed, 3), "loop": bool(m.loop), "start_s": round(start, 3)}


def scenario_movers(seed: int, index: int, path: np.ndarray, m) -> list[dict]:
    """The movers of scenario ``index``: from their own generator,
    ``SeedSequence([seed, index, 15])``, so that adding ``movers:`` to a spec
    leaves every other draw of its scenarios as it was."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, index, 15]))
    n = int(rng.integers(m.count[0], m.count[1] + 1))
    out = []
    for _ in range(n):
        mv = random_mover(rng, path, m)
        if mv is not None:
            out.append(mv)
    return out
