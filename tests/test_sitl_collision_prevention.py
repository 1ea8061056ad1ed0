"""The SITL's collision prevention (sitl/collision_prevention.py): PX4's CP_DIST /
CP_DELAY / CP_GO_NO_DATA on the velocity setpoint, fed by the companion's
OBSTACLE_DISTANCE (companion/link/obstacle_distance.py)."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from mavcore.codec import ObstacleSectors
from sitl.collision_prevention import CollisionPrevention, CollisionPreventionConfig, allowed_speed_m_s

ROOT = Path(__file__).resolve().parents[1]
CFG = CollisionPreventionConfig(dist_m=1.0, delay_s=0.4, go_no_data=False, accel_m_s2=3.0)


def _sectors(distances_m):
    """72 sectors of 5 deg, sector i centred i * 5 deg clockwise of forward (FLU azimuth -5 i deg)."""
    az = -np.radians(np.arange(72) * 5.0)
    return ObstacleSectors((az + math.pi) % (2 * math.pi) - math.pi, math.radians(2.5),
                           np.asarray(distances_m, dtype=float))


def test_allowed_speed_stops_cp_dist_short_by_hand():
    # 2.5 m away, keep 1 m: v 0.4 + v^2 / 6 = 1.5 -> v = 3 (-0.4 + sqrt(0.16 + 1))
    v = float(allowed_speed_m_s(2.5, CFG))
    assert v == pytest.approx(3.0 * (-0.4 + math.sqrt(1.16)), abs=1e-12)
    assert v * 0.4 + v * v / 6.0 == pytest.approx(1.5, abs=1e-12)
    assert float(allowed_speed_m_s(0.8, CFG)) == 0.0 and math.isinf(float(allowed_speed_m_s(math.inf, CFG)))


def test_component_toward_each_sector_is_limited_by_hand():
    d = np.full(72, math.inf)
    d[0] = 2.5                                    # an obstacle straight ahead
    cp = CollisionPrevention(CFG)
    cp.on_sectors(_sectors(d))
    v0 = float(allowed_speed_m_s(2.5, CFG))       # 2.031 m/s
    # heading east (yaw 0): east is toward the obstacle
    vx, vy, lim = cp.limit(3.0, 0.0, 0.0, 0.004)
    assert lim and (vx, vy) == pytest.approx((v0, 0.0), abs=1e-12)
    # 60 deg off the obstacle: |v| cos 60 <= v0, direction kept
    c, s = math.cos(math.radians(60)), math.sin(math.radians(60))
    vx, vy, lim = cp.limit(5.0 * c, 5.0 * s, 0.0, 0.004)
    assert lim and math.hypot(vx, vy) == pytest.approx(v0 / c, abs=1e-12) and vy / vx == pytest.approx(s / c)
    # sideways, backwards and slow enough: untouched
    assert cp.limit(0.0, 3.0, 0.0, 0.004) == (0.0, 3.0, False)
    assert cp.limit(-3.0, 0.0, 0.0, 0.004) == (-3.0, 0.0, False)
    assert cp.limit(1.0, 0.0, 0.0, 0.004) == (1.0, 0.0, False)
    # heading north (yaw 90 deg): the obstacle ahead of the body is north of the vehicle
    vx, vy, lim = cp.limit(0.0, 3.0, math.pi / 2, 0.004)
    assert lim and (vx, vy) == pytest.approx((0.0, v0), abs=1e-12)
    assert cp.limit(3.0, 0.0, math.pi / 2, 0.004) == (3.0, 0.0, False)


def test_no_data_blocks_unless_cp_go_no_data_and_off_when_cp_dist_negative():
    d = np.full(72, math.inf)
    d[18] = math.nan                              # 90 deg right of forward: no sensor there
    cp = CollisionPrevention(CFG)
    assert cp.limit(1.0, 0.0, 0.0, 0.004) == (0.0, 0.0, True)          # nothing received yet
    cp.on_sectors(_sectors(d), 0)
    assert cp.limit(1.0, 0.0, 0.0, 0.004) == (1.0, 0.0, False)
    assert cp.limit(0.0, -1.0, 0.0, 0.004) == (0.0, 0.0, True)         # toward the unknown sector (right)
    cp.set_time(500_000)                                                # 0.5 s later: still fresh
    assert cp.limit(1.0, 0.0, 0.0, 0.004) == (1.0, 0.0, False)
    cp.set_time(500_001)                                                # older than 0.5 s: no data
    assert cp.limit(1.0, 0.0, 0.0, 0.004) == (0.0, 0.0, True)
    cp.configure(CollisionPreventionConfig(1.0, 0.4, True, 3.0))
    assert cp.limit(0.0, -1.0, 0.0, 0.004) == (0.0, -1.0, False)
    cp.configure(CollisionPreventionConfig(-1.0, 0.4, False, 3.0))
    assert cp.limit(0.0, -1.0, 0.0, 0.004) == (0.0, -1.0, False)


# --- the SITL stops short of a wall in --control vehicle, companion avoidance off -------------

WALL_X, WALL_HALF = 16.0, 0.15                    # a box across the first corridor (flown westward)


def _wall_mission(tmp_path):
    src = ROOT / "missions" / "flat-rectangle"
    for f in src.iterdir():
        if f.is_file():
            shutil.copy(f, tmp_path / f.name)
    doc = yaml.safe_load((src / "mission.yaml").read_text())
    doc["sim"]["obstacles"] = [{"type": "box", "x": WALL_X, "y": 8.75, "size_x": 2 * WALL_HALF, "size_y": 1.2,
                                "height": 3.0}]
    doc["replan"] = {"enabled": False}
    (tmp_path / "mission.yaml").write_text(yaml.safe_dump(doc))
    return tmp_path / "mission.yaml"


def _fly_toward_wall(tmp_path, cp_dist_m):
    from companion.commands.demo import launch_pose
    from companion.commands.fly import execute
    from companion.flight_plan import FlightPlan
    from mavcore.mission import load_mission
    from companion.planner import plan_mission
    from sitl.api import SitlInProcess

    path = _wall_mission(tmp_path)
    mission = load_mission(path)
    plan = plan_mission(mission)
    sitl = SitlInProcess(path, seed=1, start=launch_pose(plan.trajectory, plan.target_enu_m)).start()
    server = sitl.server
    assert server.vehicle.params.set("CP_DIST", cp_dist_m).ok
    server._apply_params()                          # as a PARAM_SET would
    xs = []
    step = server.vehicle.sim.step_frame

    def watched(cmd):                               # the true position, every frame
        frame = step(cmd)
        xs.append(float(server.vehicle.sim.plant.p[0]))
        return frame

    server.vehicle.sim.step_frame = watched
    try:
        result = execute(mission, FlightPlan.from_plan(plan), sitl.url, "vehicle", None, cut_s=12.0)
    finally:
        sitl.stop()
    return result, min(xs), server


@pytest.mark.slow
def test_sitl_stops_cp_dist_short_of_a_wall_the_companion_does_not_avoid(tmp_path):
    # CP_DIST 0.7 m: below the 0.95 m from the corridor's centre line to the row faces
    # (a larger one blocks the corridor itself, as on PX4), above the 0.442 m airframe radius
    cp_dist = 0.7
    result, x_min, server = _fly_toward_wall(tmp_path, cp_dist)
    face = WALL_X + WALL_HALF
    assert server.vehicle.collision_prevention.n_messages > 50          # the companion published at ~10 Hz
    assert server.vehicle.sim.crash is None and not result.report.crashed
    # the plan runs 4 m past the wall; the vehicle stopped CP_DIST short of its face, within
    # the sensors' 0.1 m offset from the centre, the 1 cm rounding and the braking lag
    assert cp_dist - 0.15 <= x_min - face <= cp_dist + 0.3
