"""The obstacle scenarios (missions/obstacle-low, missions/obstacle-tall)
against the flat-rectangle plan: what the geometry says about them, and
what ``companion demo`` without its replanner (``replan.enabled: false``)
makes of one: the crash the SITL reports (with it: tests/test_replan_e2e.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from companion.cli import main
from companion.bundled import missions_dir
from companion.commands.fly import EXIT_FAILED
from mavcore.geometry import scene_from_maps
from companion.link.tlog import read_tlog
from mavcore.maps import load_dem, load_ogm
from mavcore.mission.loader import load_mission
from mavcore.mission.sim import vehicle_radius_m
from companion.planner import plan_mission


def _scene(name):
    m = load_mission(missions_dir() / name / "mission.yaml")
    scene = scene_from_maps(load_ogm(m.map_path), load_dem(m.dem_path), m.sim.obstacles, m.sim.canopy_height_m)
    return m, scene, vehicle_radius_m(m.sim, m.vehicle.arm_m)


@pytest.fixture(scope="module")
def planned_path():
    """Trajectory positions of the flat-rectangle plan every 0.5 s (the scenarios fly the same plan)."""
    plan = plan_mission(load_mission(missions_dir() / "flat-rectangle" / "mission.yaml"))
    tr = plan.trajectory
    return tr.sample(np.arange(tr.t0, tr.tf, 0.5)).p


def test_flat_rectangle_plan_keeps_the_vehicle_off_the_rows(planned_path):
    """No false positive: mid-corridor the row faces are 1.25 - 0.2 = 1.05 m
    away, so the 0.442 m sphere keeps 0.608 m; the flight is 1.5 m up. The
    turns into the corridors lie 0.892 m + a cell beyond the row ends (the
    margin is kept from the airframe's surface, docs/mission.md "Margins"),
    so the trajectory's entry (it settles onto the lane within a few mm)
    is still beside the row: 5 mm allowed."""
    m, scene, r = _scene("flat-rectangle")
    assert r == pytest.approx(0.315 + 0.127)
    cl = [scene.clearance(p, r) for p in planned_path]
    rows = min(c.rows_m for c in cl)
    assert rows == pytest.approx(1.05 - r, abs=5e-3)
    assert min(c.terrain_m for c in cl) == pytest.approx(1.5 - r, abs=1e-3)
    assert all(c.obstacle_index is None for c in cl)


@pytest.mark.parametrize("name", ["obstacle-low", "obstacle-tall"])
def test_scenario_obstacle_is_on_the_planned_path(planned_path, name):
    m, scene, r = _scene(name)
    assert m.map_path.resolve() == (missions_dir() / "flat-rectangle" / "map.yaml").resolve()
    cl = [scene.clearance(p, r) for p in planned_path]
    assert min(c.obstacle_m for c in cl) < -0.1            # flown as planned, the vehicle hits it
    assert min(c.rows_m for c in cl) == pytest.approx(1.05 - r, abs=5e-3)   # as flat-rectangle's


def test_low_obstacle_can_be_climbed_over_inside_the_corridor():
    m, scene, r = _scene("obstacle-low")
    box = scene.obstacles[0]
    assert box.top_z_m == pytest.approx(1.2) and 1.5 - r < box.top_z_m < m.sim.canopy_height_m
    over = scene.clearance((box.x_m, box.y_m, box.top_z_m + r + 0.5), r)
    assert over.obstacle_m == pytest.approx(0.5) and over.rows_m > 0.5


def test_tall_post_blocks_its_corridor():
    m, scene, r = _scene("obstacle-tall")
    post = scene.obstacles[0]
    assert post.top_z_m > m.sim.canopy_height_m + 0.5
    # at the post, every position across the corridor touches the post or a row
    best = max(min(c.obstacle_m, c.rows_m) for c in
               (scene.clearance((post.x_m, y, 1.5), r) for y in np.linspace(2.7, 4.8, 211)))
    assert best < 0.0
    assert best == pytest.approx(-(2 * r - (1.05 - 0.25)) / 2, abs=0.01)   # the gap is 0.80 m, the vehicle 0.884


def test_scenarios_carry_closed_rings_of_custom_rangefinders_and_their_mounts():
    for name in ("obstacle-low", "obstacle-tall"):
        m = load_mission(missions_dir() / name / "mission.yaml")
        rfs = m.sim.rangefinders
        custom = [r for r in rfs if r.orientation == 100]
        assert len(custom) == 40 and any(r.orientation == 25 for r in rfs)
        for pitch, n in ((0.0, 16), (20.0, 16), (45.0, 8)):
            ring = [r for r in custom if r.rotation_flu_deg[1] == pitch]
            assert len(ring) == n
            # closed: the yaws are evenly spaced and each beam is as wide as the spacing
            yaws = sorted(r.rotation_flu_deg[2] for r in ring)
            assert np.allclose(np.diff(yaws), 360.0 / n) and all(r.hfov_deg == 360.0 / n for r in ring)
        assert all(math.hypot(*r.position_flu_m) > 0 for r in rfs)
        # the companion knows where each one sits (the offset is not on the wire)
        mounts = {s.id: s.offset_flu_m for s in m.replan.sensors}
        assert mounts == {r.id: tuple(r.position_flu_m) for r in rfs}


@pytest.mark.slow
def test_demo_without_a_replanner_ends_in_the_crash_the_sitl_reports(tmp_path, capsys):
    """obstacle-low with its crate moved into the first corridor (x = 19 m,
    reached ~3 s into the trajectory) so that a short cut reaches it: same
    sensors, same crate, same flight."""
    src = missions_dir() / "obstacle-low" / "mission.yaml"
    text = src.read_text().replace("../flat-rectangle/", str(missions_dir() / "flat-rectangle") + "/")
    text = text.replace("{type: box, x: 7.0, y: 6.25,", "{type: box, x: 19.0, y: 8.75,")
    text = text.replace("\nreplan:\n", "\nreplan:\n  enabled: false\n")
    assert "x: 19.0, y: 8.75" in text and "enabled: false" in text
    mission = tmp_path / "mission.yaml"
    mission.write_text(text)
    out = tmp_path / "out"
    rc = main(["demo", "--mission", str(mission), "--cut", "8", "--out", str(out), "--no-plots", "--quiet"])
    assert rc == EXIT_FAILED
    rep = json.loads((out / "report.json").read_text())
    assert not rep["completed"] and rep["crashed"] and rep["violation"]["kind"] == "crash"
    assert rep["crash"]["text"].startswith("CRASH: box #1")
    recs = [r.msg for r in read_tlog(out / "flight.tlog")
            if r.msg.get_srcSystem() == 1 and r.msg.get_srcComponent() == 1]
    texts = [(m.severity, m.text) for m in recs if m.get_type() == "STATUSTEXT"]
    crash = [t for s, t in texts if t.startswith("CRASH")]
    assert len(crash) == 1 and (2, crash[0]) in texts                      # once, MAV_SEVERITY_CRITICAL
    # flying west, the crate's east face is at x = 19.4, its top 0.3 m below the
    # flight: the sphere touches the top edge sqrt(r^2 - 0.3^2) = 0.325 m before it
    assert crash[0].startswith("CRASH: box #1 at E19.72 N8.75 U1.50"), crash
    # HEARTBEAT: EMERGENCY from the crash on, never before
    k = next(i for i, m in enumerate(recs) if m.get_type() == "STATUSTEXT" and m.text.startswith("CRASH"))
    status = [(i, m.system_status) for i, m in enumerate(recs) if m.get_type() == "HEARTBEAT"]
    assert all(st != 6 for i, st in status if i < k)
    assert [st for i, st in status if i > k] and all(st == 6 for i, st in status if i > k)
    assert "CRASH: box #1" in capsys.readouterr().err
    # the report's crash time is the frame that carried the text (HIGHRES_IMU closes a frame)
    frame_end = next(m.time_usec for m in recs[k:] if m.get_type() == "HIGHRES_IMU")
    assert rep["crash"]["t_s"] == pytest.approx(frame_end * 1e-6, abs=0.0041)
