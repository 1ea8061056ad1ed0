"""An added obstacle may move: its returns are read for an approach (``Replanner._place``),
and stay explained while they lie on its cells.

A re-route adds what it went round to the known map (``KnownMap.with_obstacle``), and the
added cells then explain that obstacle's returns. A worker standing where a re-route went
round it, who then walks at the vehicle, was explained by them until its return left the
cells (0.22 s at 1.3 m/s), and only then did the approach measurement start, needing its
0.3 s baseline (``closing.BASELINE_S``) more: fresh seed 20261224 along, flight 7, contact.

Here (the closed-loop test's field and ring, cast analytically): a 0.25 m worker, 1.8 m
tall, stands 2 m ahead of a vehicle hovering in the corridor, added to the known map as a
re-route adds it; at t = 1 s it walks at the vehicle at 1.3 m/s. Hand: its approach counts
once a beam has two returns ``BASELINE_S`` apart (the older may be from before it walked),
so by 1.0 + 0.3 + two sensor periods (0.1 s each); and the vehicle knows it by the time its
returns are unknown again (they leave the added cells). Without the rule the approach starts
``BASELINE_S`` after the first unknown return at the earliest.
Standing, it is never a mover, and its returns stay explained (no avoidance loop round an
obstacle already gone round).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from companion.replan import Replanner
from companion.replan.closing import BASELINE_S
from mavcore.mission.replan import ReplanConfig

from test_replan_closedloop import CORRIDOR_Y, ROW_BOXES, Cylinder, build_field, feed_ring, level_attitude

DT = 0.05            # frame (s); sensors every other frame: 0.1 s
HOVER = (8.0, CORRIDOR_Y, 1.5)
WALKER_X, START_S, SPEED = 10.0, 1.0, 1.3


def _watch(walks: bool, t_end: float = 3.0):
    """(first time an approach counts, first time a return near the worker is unknown), None
    where never; the vehicle hovers, the worker added to the known map as a re-route adds it."""
    field = build_field()
    # the worker's disc, as the re-route's footprint holds it (``reroute._footprint``: the cells under it)
    g = np.mgrid[-0.25:0.26:0.05, -0.25:0.26:0.05].reshape(2, -1).T
    disc = g[np.hypot(g[:, 0], g[:, 1]) <= 0.25] + (WALKER_X, CORRIDOR_Y)
    known = field.known.with_obstacle(disc, None, np.full(len(disc), 1.8))
    rp = Replanner(dataclasses.replace(ReplanConfig(), give_way=True), known, field.plan)
    R = level_attitude((1.0, 0.0, 0.0))
    approach = unknown = None
    k = 0
    t = 0.0
    while t <= t_end:
        x = WALKER_X - (SPEED * max(0.0, t - START_S) if walks else 0.0)
        bodies = ROW_BOXES + (Cylinder(x, CORRIDOR_Y, 0.25, 1.8),)
        rp.on_pose(t, HOVER, R)
        if k % 2 == 0:
            feed_ring(rp, t, HOVER, R, bodies)
        if approach is None and rp.closing.approach_m_s(t) > 0.0:
            approach = t
        pts = rp.memory.points()
        if unknown is None and len(pts) and (np.hypot(pts[:, 0] - x, pts[:, 1] - CORRIDOR_Y) < 0.5).any():
            unknown = t
        t = round(t + DT, 9)
        k += 1
    return approach, unknown


def test_a_worker_added_while_standing_is_measured_as_soon_as_it_walks():
    approach, unknown = _watch(True)
    assert approach is not None and unknown is not None
    assert approach <= START_S + BASELINE_S + 2 * 0.1 + 1e-9
    assert approach <= unknown


def test_a_worker_added_while_standing_stays_explained_while_it_stands():
    assert _watch(False) == (None, None)
