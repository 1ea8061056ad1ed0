"""Flight-ready exports (QGC .plan, QGC WPL 110): the item sequence, AMSL altitudes that
do not depend on where the vehicle arms, yaw and ROI toward S_p, the inclusion fence;
checked against QGC's loader keys, pymavlink's mavwp and MAVSDK's importers."""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest

from companion.cli import main
from mavcore.frames import enu2geodetic, geodetic2enu
from mavcore.maps import load_dem, load_ogm
from mavcore.mission import load_mission

ROOT = Path(__file__).resolve().parents[1]
MISSION = ROOT / "missions" / "tilted-hexagon" / "mission.yaml"


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    out = tmp_path_factory.mktemp("exports")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["plan", str(MISSION), "-o", str(out / "plan.json"), "--qgc", str(out / "p.plan"),
                     "--waypoints", str(out / "p.waypoints")]) == 0
    mission = load_mission(MISSION)
    doc = json.loads((out / "plan.json").read_text())
    assert len(doc["sorties"]) == 1          # so the files are named as given
    sortie = doc["sorties"][0]
    return {"out": out, "mission": mission, "doc": doc, "qgc": json.loads((out / "p.plan").read_text()),
            "sortie": sortie, "wp": np.array([w["p"] for w in sortie["waypoints"]]),
            "target": np.array(doc["target_enu_m"])}


def enu(lat, lon, alt, home):
    return np.array(geodetic2enu(lat, lon, alt, home.lat, home.lon, home.alt_m))


def test_item_sequence_positions_speed_roi_and_yaw(exported):
    """Take-off at the launch point, the transit speed, the ROI at S_p, the sortie's
    way-points with the coverage speed from the first corridor and the transit speed
    again from the last corridor's end, then RTL."""
    items = exported["qgc"]["mission"]["items"]
    home, wp, target = exported["mission"].home, exported["wp"], exported["target"]
    flight = exported["mission"].flight
    changes = dict(exported["sortie"]["speed_changes"])
    assert changes[0] == flight.transit_speed_m_s
    expected = [22, 178, 195]
    for i in range(len(wp)):
        if i in changes and i != 0:
            expected.append(178)
        expected.append(16)
    cmds = [it["command"] for it in items]
    assert cmds == expected + [20]
    takeoff, speed, roi = items[0], items[1], items[2]
    launch = np.array(exported["doc"]["launch_enu_m"])
    assert np.allclose(enu(*takeoff["params"][4:7], home)[:2], launch, atol=1e-3)
    assert enu(*takeoff["params"][4:7], home)[2] == pytest.approx(wp[0][2], abs=1e-3)
    assert np.allclose(wp[0][:2], launch, atol=1e-6) and np.allclose(wp[-1][:2], launch, atol=1e-6)
    assert speed["params"][:3] == [1, flight.transit_speed_m_s, -1]     # ground speed, m/s, throttle kept
    speeds = [it["params"][1] for it in items if it["command"] == 178]
    assert speeds == [flight.transit_speed_m_s, flight.speed_m_s, flight.transit_speed_m_s]
    assert np.allclose(enu(*roi["params"][4:7], home), target, atol=1e-3)
    for it, p in zip([it for it in items if it["command"] == 16], wp):
        assert np.allclose(enu(*it["params"][4:7], home), p, atol=1e-3)
        d = target[:2] - p[:2]
        yaw = math.degrees(math.atan2(d[0], d[1])) % 360.0        # from north, clockwise
        assert it["params"][3] == pytest.approx(yaw, abs=1e-6)
    assert all(it["frame"] == 0 for i, it in enumerate(items) if it["command"] in (16, 22, 195))


def test_planned_height_above_terrain_wherever_the_vehicle_arms(exported):
    """The vehicle's home is where it arms. Altitudes in frame 0 are AMSL; in frame 3
    they would be added to the arming point's altitude. For arming points across the
    field (their ground heights differ by metres on the sloped hexagon), every
    way-point must stay within 5 cm of DEM + height_agl_m above the terrain below it."""
    mission, items = exported["mission"], exported["qgc"]["mission"]["items"]
    dem = load_dem(mission.dem_path)
    grid = load_ogm(mission.map_path)
    home = mission.home
    r, c = np.nonzero(grid.free)
    pick = np.linspace(0, len(r) - 1, 7).astype(int)
    x_arm, y_arm = grid.cell_to_world(r[pick], c[pick])
    arm_alt_amsl = home.alt_m + dem.height_at(x_arm, y_arm)
    assert np.ptp(arm_alt_amsl) > 0.5
    wps = [it for it in items if it["command"] == 16]
    for arm_alt in arm_alt_amsl:
        for it in wps:
            lat, lon, alt = it["params"][4:7]
            amsl = alt if it["frame"] == 0 else arm_alt + alt
            x, y, _ = geodetic2enu(lat, lon, 0.0, home.lat, home.lon, home.alt_m)
            agl = amsl - (home.alt_m + float(dem.height_at(x, y)))
            assert agl == pytest.approx(mission.flight.height_agl_m, abs=0.05)


def _inside(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    inside = np.zeros(len(pts), dtype=bool)
    for (x1, y1), (x2, y2) in zip(poly, np.roll(poly, -1, axis=0)):
        crosses = (y1 > pts[:, 1]) != (y2 > pts[:, 1])
        xc = x1 + (pts[:, 1] - y1) * (x2 - x1) / np.where(y2 != y1, y2 - y1, 1.0)
        inside ^= crosses & (pts[:, 0] < xc)
    return inside


def _dist_to_edges(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    t = np.clip(((pts[:, None] - a[None]) * ab[None]).sum(-1) / (ab * ab).sum(-1)[None], 0, 1)
    q = a[None] + t[..., None] * ab[None]
    return np.hypot(*(pts[:, None] - q).transpose(2, 0, 1)).min(axis=1)


def test_inclusion_fence_contains_the_path_with_margin(exported):
    qgc, mission, doc = exported["qgc"], exported["mission"], exported["doc"]
    polys = qgc["geoFence"]["polygons"]
    assert len(polys) == 1 and polys[0]["inclusion"] is True and polys[0]["version"] == 1
    home = mission.home
    fence = np.array([enu(lat, lon, 0.0, home)[:2] for lat, lon in polys[0]["polygon"]])
    assert len(fence) >= 3
    path = np.array(exported["sortie"]["path"])
    dense = np.vstack([np.linspace(p, q, 50) for p, q in zip(path[:-1], path[1:])])
    assert _inside(fence, dense).all()
    # the path keeps the safety margin from the field; the fence is simplified by half of it
    grid = load_ogm(mission.map_path)
    assert _dist_to_edges(fence, dense).min() >= 0.5 * mission.coverage.safety_margin_m - grid.resolution_m
    # and every free cell of the field is inside the fence
    r, c = np.nonzero(grid.free)
    x, y = grid.cell_to_world(r, c)
    assert _inside(fence, np.column_stack([x, y])).all()


def test_qgc_plan_matches_the_loader_schema(exported):
    """The keys and JSON types QGroundControl's loader checks (PlanMasterController /
    MissionController::_loadJsonMissionFileV2 / SimpleMissionItem::load; a number-typed
    key may be null, meaning NaN; GeoFenceController / QGCMapPolygon for the fence)."""
    qgc = exported["qgc"]
    num = (int, float)
    assert qgc["fileType"] == "Plan" and qgc["version"] == 1 and isinstance(qgc["groundStation"], str)
    assert qgc["rallyPoints"] == {"points": [], "version": 2}
    assert qgc["geoFence"]["version"] == 2 and qgc["geoFence"]["circles"] == []
    for poly in qgc["geoFence"]["polygons"]:
        assert all(len(v) == 2 and all(isinstance(x, float) for x in v) for v in poly["polygon"])
    mis = qgc["mission"]
    assert mis["version"] == 2 and mis["globalPlanAltitudeMode"] == 2       # QGC AltitudeModeAbsolute
    for k in ("firmwareType", "vehicleType", "cruiseSpeed", "hoverSpeed", "globalPlanAltitudeMode"):
        assert isinstance(mis[k], num) and not isinstance(mis[k], bool)
    home = exported["mission"].home
    assert mis["plannedHomePosition"] == [home.lat, home.lon, home.alt_m]
    for i, it in enumerate(mis["items"]):
        assert it["type"] == "SimpleItem" and it["autoContinue"] is True and it["doJumpId"] == i + 1
        assert len(it["params"]) == 7 and all(v is None or isinstance(v, num) for v in it["params"])
        assert isinstance(it["command"], int) and it["frame"] in (0, 2)
        assert it["AltitudeMode"] == 2 and isinstance(it["Altitude"], num) and it["AMSLAltAboveTerrain"] is None


def test_wpl_loads_in_pymavlink_and_matches_the_plan(exported):
    from pymavlink import mavwp

    loader = mavwp.MAVWPLoader()
    items = exported["qgc"]["mission"]["items"]
    assert loader.load(str(exported["out"] / "p.waypoints")) == len(items) + 1
    home = exported["mission"].home
    h = loader.wp(0)
    assert (h.seq, h.current, h.frame, h.command) == (0, 1, 0, 16)
    assert (h.x, h.y, h.z) == pytest.approx((home.lat, home.lon, home.alt_m))
    for i, it in enumerate(items, start=1):
        w = loader.wp(i)
        assert (w.seq, w.frame, w.command, w.autocontinue) == (i, it["frame"], it["command"], 1)
        for got, want in zip((w.param1, w.param2, w.param3, w.param4), it["params"][:4]):
            assert (math.isnan(got) and want is None) or got == pytest.approx(want, abs=1e-5)
        assert (w.x, w.y) == pytest.approx(tuple(it["params"][4:6]), abs=1e-9)
        assert w.z == pytest.approx(it["params"][6], abs=1e-4)


@pytest.mark.slow
def test_mavsdk_imports_both_files_and_uploads_to_the_sitl(exported):
    """MAVSDK-Python's MissionRaw importers read the .plan (mission and fence) and the
    WPL file into the same items; the mission uploads to the bundled SITL."""
    mavsdk = pytest.importorskip("mavsdk")
    if not hasattr(mavsdk, "Mavsdk"):
        pytest.skip("needs the native mavsdk >= 4")
    from mavsdk import ComponentType, Configuration, Mavsdk
    from mavsdk.plugins.mission_raw import MissionRaw

    from sitl.api import SitlThread

    qgc_items = exported["qgc"]["mission"]["items"]
    with SitlThread(MISSION, speed=1.0) as sitl:
        port = sitl.listen.rsplit(":", 1)[1]
        drone = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        try:
            drone.add_any_connection(f"udpout://127.0.0.1:{port}")
            system = drone.first_autopilot(10.0)
            assert system is not None
            raw = MissionRaw(system)
            data = raw.import_qgroundcontrol_mission(str(exported["out"] / "p.plan"))
            got = data.mission_items
            assert [m.command for m in got] == [it["command"] for it in qgc_items]
            for m, it in zip(got, qgc_items):
                lat, lon, alt = it["params"][4:7]
                if it["frame"] == 0:
                    assert m.frame == 0 and m.x == round(lat * 1e7) and m.y == round(lon * 1e7)
                    assert m.z == pytest.approx(alt, abs=1e-3)
            fence = exported["qgc"]["geoFence"]["polygons"][0]["polygon"]
            assert [m.command for m in data.geofence_items] == [5001] * len(fence)
            assert all(m.param1 == len(fence) for m in data.geofence_items)
            wpl = raw.import_mission_planner_mission(str(exported["out"] / "p.waypoints"))
            assert [m.command for m in wpl.mission_items][-len(got):] == [m.command for m in got]
            raw.upload_mission(got)
            stored = sitl.server.missions.items
            assert len(stored) == len(got)
            assert [s.command for s in stored] == [m.command for m in got]
        finally:
            drone.destroy()


def test_mission_int_encoding_of_the_items_round_trips(exported):
    """codec.encode_mission_item: the MISSION_ITEM_INT carries the same command, frame,
    params and position (1e7 degrees, AMSL metres) as the .plan item, through a real
    pymavlink pack/parse."""
    from pymavlink.dialects.v20 import common as mavlink

    from mavcore import codec
    from companion.mission_items import build_flight_items

    mission, doc = exported["mission"], exported["doc"]
    h = mission.home
    items = build_flight_items(exported["wp"], exported["target"], (h.lat, h.lon, h.alt_m), mission.flight.speed_m_s,
                               fence_enu_m=np.array([[0, 0], [10, 0], [10, 10]]))
    mav = mavlink.MAVLink(None, 1, 191)
    parser = mavlink.MAVLink(None, 255, 0)
    for seq, it in enumerate(items.mission):
        m = parser.parse_char(codec.encode_mission_item(mav, seq, it).pack(mav))
        assert (m.seq, m.command, m.frame, m.mission_type) == (seq, it.command, it.frame, 0)
        assert m.x == round(it.lat_deg * 1e7) and m.y == round(it.lon_deg * 1e7)
        assert m.z == pytest.approx(it.alt_m, abs=1e-3)
        for got, want in zip((m.param1, m.param2, m.param3, m.param4), it.params):
            assert (math.isnan(got) and math.isnan(want)) or got == pytest.approx(want, rel=1e-6)
    for seq, it in enumerate(items.fence):
        m = parser.parse_char(codec.encode_mission_item(mav, seq, it, mission_type=mavlink.MAV_MISSION_TYPE_FENCE).pack(mav))
        assert (m.command, m.param1, m.mission_type) == (5001, 3.0, mavlink.MAV_MISSION_TYPE_FENCE)
    assert len(exported["wp"]) + 4 == len(items.mission)
