"""Energy model, sorties and the SITL's battery, against hand-derived numbers and
physical laws; the battery and a NO_SPACE rejection seen over real UDP sockets."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore.energy import EnergyConfig, cruise_power_w, flight_energy, hover_power_w, rotor_power_w
from mavcore.mission import load_mission
from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig
from sitl.battery import Battery
from ports import private_link

ROOT = Path(__file__).resolve().parents[1]
FLAT = ROOT / "missions" / "flat-rectangle" / "mission.yaml"
VEH = VehicleConfig()
CFG = EnergyConfig()


def test_hover_power_by_hand():
    """4.34 kg: each rotor lifts 4.34 x 9.81 / 4 = 10.644 N; disk pi 0.19^2 = 0.11341 m^2;
    ideal power T^1.5 / sqrt(2 rho A) = 34.726 / 0.52711 = 65.88 W; / (0.6 x 0.8) = 137.25 W;
    four rotors 549.0 W, plus 15 W avionics: 564.0 W."""
    t = 4.34 * 9.81 / 4
    a = math.pi * 0.19 ** 2
    ideal = t ** 1.5 / math.sqrt(2 * 1.225 * a)
    assert ideal == pytest.approx(65.88, abs=0.01)
    assert hover_power_w(VEH, CFG) == pytest.approx(4 * ideal / 0.48 + 15.0, rel=1e-12)
    assert hover_power_w(VEH, CFG) == pytest.approx(564.0, abs=0.1)
    # momentum theory: rotor power grows as (weight)^(3/2)
    heavy = dataclasses.replace(VEH, mass_kg=2 * VEH.mass_kg)
    ratio = (hover_power_w(heavy, CFG) - 15.0) / (hover_power_w(VEH, CFG) - 15.0)
    assert ratio == pytest.approx(2 ** 1.5, rel=1e-12)


@pytest.mark.parametrize("speed", [0.0, 1.0, 3.0, 8.0])
def test_cruise_power_satisfies_glauert(speed):
    """Rotor power scales with the induced velocity v_i, which solves v_i^4 + V^2 v_i^2 = v_h^4
    in level flight; at V = 0 it is the hover power. Drag adds 1/2 rho CdA V^3 / eta."""
    p = float(cruise_power_w(speed, VEH, CFG))
    drag = 0.5 * 1.225 * CFG.drag_area_m2 * speed ** 3 / CFG.drive_efficiency
    p_rot_hover = hover_power_w(VEH, CFG) - 15.0
    v_h = math.sqrt(VEH.mass_kg * GRAVITY_M_S2 / 4 / (2 * 1.225 * CFG.disk_area_m2))
    v_i = (p - 15.0 - drag) / p_rot_hover * v_h
    assert v_i ** 4 + speed ** 2 * v_i ** 2 == pytest.approx(v_h ** 4, rel=1e-9)
    if speed == 0.0:
        assert p == pytest.approx(hover_power_w(VEH, CFG), rel=1e-12)


def test_flight_energy_of_a_level_leg_and_a_climb():
    """100 m in 100 s at 1 m/s: P_cruise(1) x 100 s; then 2 m up in 4 s adds m g 2 / eta;
    plus the take-off and landing of 1.5 m at 0.5 m/s (6 s at hover power + m g 1.5 / eta)."""
    t = np.array([0.0, 100.0, 104.0])
    p = np.array([[0, 0, 1.5], [100, 0, 1.5], [100, 0, 3.5]])
    e = flight_energy(t, p, 1.5, VEH, CFG)
    w = VEH.mass_kg * GRAVITY_M_S2
    expect_j = (float(cruise_power_w(1.0, VEH, CFG)) * 100 + float(cruise_power_w(0.0, VEH, CFG)) * 4
                + w * 2.0 / 0.8 + hover_power_w(VEH, CFG) * 6.0 + w * 1.5 / 0.8)
    assert e.energy_wh == pytest.approx(expect_j / 3600, rel=1e-12)
    assert e.duration_s == pytest.approx(110.0)


def independent_flight_energy_wh(t_s, p_enu_m, height_agl_m, vehicle, cfg, dt_s=0.01):
    """Energy (Wh) of flying the way-points plus the take-off and landing, computed apart from
    ``mavcore.energy``, and the bound (Wh) of its quadrature error.

    Momentum theory per rotor at T = m g / 4 on a disk A = pi r^2: hover induced velocity
    v_h = sqrt(T / (2 rho A)); in level flight at V, v_i is the root in [0, v_h] of
    v_i^4 + V^2 v_i^2 - v_h^4 (found by bisection, not the closed form); rotor power
    4 T v_i / (FM eta); parasite drag 1/2 rho CdA V^3 / eta; climbing at w > 0 adds m g w / eta.
    The trajectory (piecewise linear in time between way-points) is sampled on a uniform
    grid of ``dt_s``; each cell's velocity is its mean velocity, and the power is integrated
    by the midpoint rule. Cells inside a leg are exact; a cell that straddles a way-point
    mixes two legs, so the error is at most (P_max - P_min) dt per straddling cell.
    Take-off and landing: h / w_climb each at hover power, plus m g h / eta for the climb.
    """
    from scipy.optimize import brentq

    t = np.asarray(t_s, float)
    p = np.asarray(p_enu_m, float)
    assert np.all(np.diff(t) > 0), "the way-point times must increase (a zero-length leg has no power)"
    g = GRAVITY_M_S2
    thrust = vehicle.mass_kg * g / 4.0
    area = math.pi * cfg.rotor_radius_m ** 2
    rho, fm, eta = cfg.air_density_kg_m3, cfg.figure_of_merit, cfg.drive_efficiency
    v_h = math.sqrt(thrust / (2.0 * rho * area))

    def power_w(v_xy, w):
        v_i = brentq(lambda x: x ** 4 + v_xy ** 2 * x ** 2 - v_h ** 4, 0.0, v_h, xtol=1e-14, rtol=1e-15) \
            if v_xy > 0 else v_h
        return (4.0 * thrust * v_i / (fm * eta) + 0.5 * rho * cfg.drag_area_m2 * v_xy ** 3 / eta
                + cfg.avionics_power_w + vehicle.mass_kg * g * max(w, 0.0) / eta)

    n = int(math.ceil((t[-1] - t[0]) / dt_s))
    edges = np.linspace(t[0], t[-1], n + 1)
    h = edges[1] - edges[0]
    pos = np.stack([np.interp(edges, t, p[:, k]) for k in range(3)], axis=1)
    vel = np.diff(pos, axis=0) / h
    keys = np.round(np.column_stack([np.hypot(vel[:, 0], vel[:, 1]), vel[:, 2]]), 12)
    uniq, inverse = np.unique(keys, axis=0, return_inverse=True)
    powers = np.array([power_w(float(v), float(w)) for v, w in uniq])[inverse.ravel()]
    legs_j = float(np.sum(powers) * h)
    straddling = int(np.count_nonzero(np.diff(np.searchsorted(t, edges, side="right")) > 0))
    bound_j = straddling * h * (powers.max() - powers.min()) + 1e-9 * legs_j
    p_hover = 4.0 * thrust * v_h / (fm * eta) + cfg.avionics_power_w
    vertical_j = p_hover * 2.0 * height_agl_m / cfg.climb_speed_m_s + vehicle.mass_kg * g * height_agl_m / eta
    return (legs_j + vertical_j) / 3600.0, bound_j / 3600.0


def test_independent_energy_of_a_hover_and_a_level_leg_by_hand():
    """Check the independent helper itself: 100 s hovering in place costs 100 s x 564.0 W
    (test_hover_power_by_hand) plus the 1.5 m take-off and landing: 6 s at 564.0 W and
    4.34 x 9.81 x 1.5 / 0.8 = 79.83 J."""
    t = np.array([0.0, 100.0])
    p = np.array([[0, 0, 1.5], [0, 0, 1.5]])
    e_wh, bound = independent_flight_energy_wh(t, p, 1.5, VEH, CFG)
    assert e_wh * 3600 == pytest.approx(564.0 * 106 + 79.83, abs=0.1 * 106 + 0.01)
    assert bound < 1e-6
    assert flight_energy(t, p, 1.5, VEH, CFG).energy_wh == pytest.approx(e_wh, rel=1e-9)


def test_battery_drains_by_the_power_drawn():
    """Hovering thrusts for 2 minutes at 250 Hz: each step's terminal power V I equals the
    rotor model's power (the quadratic's root), the charge drawn is the sum of I dt, and
    the state of charge falls by it over the capacity."""
    b = Battery(CFG)
    assert b.cells == 6 and b.voltage_v == pytest.approx(6 * 4.2)
    f = [VEH.mass_kg * GRAVITY_M_S2 / 4] * 4
    p = b.power_w(f)
    assert p == pytest.approx(hover_power_w(VEH, CFG), rel=1e-12)
    dt = 1 / 250
    charge = 0.0
    for i in range(250 * 120):
        b.drain(f, dt)
        if i % 1000 == 0:
            assert b.voltage_v * b.current_a == pytest.approx(p, rel=1e-9)
        charge += b.current_a * dt / 3600
    assert b.consumed_ah == pytest.approx(charge, rel=1e-12)
    assert b.remaining == pytest.approx(1 - charge / 10.0, rel=1e-12)
    # ~564 W for 2 min is 18.8 Wh at the terminals; the cells also heat R: a little more
    assert 18.8 <= b.consumed_wh <= 18.8 * 1.02
    assert 0.91 < b.remaining < 0.93


def test_sorties_of_a_small_battery_cover_every_corridor_once():
    """A 20 Wh battery (15 Wh usable) splits the flat rectangle into several sorties: each starts and ends
    at the launch point, fits the battery and the item limit, and together they fly every
    main segment exactly once, in order, split at corridor ends."""
    from companion.planner import plan_mission

    m = load_mission(FLAT)
    small = dataclasses.replace(m, energy=dataclasses.replace(m.energy, battery_capacity_ah=0.9,
                                                              max_mission_items=40))
    plan = plan_mission(small)
    sp = plan.sorties
    assert len(sp.sorties) >= 2
    segs = [s.segments for s in sp.sorties]
    assert segs[0][0] == 0 and segs[-1][1] == len(plan.coverage.main_segments) - 1
    assert all(b[0] == a[1] + 1 for a, b in zip(segs[:-1], segs[1:]))
    for s in sp.sorties:
        assert s.energy.energy_wh <= small.energy.usable_wh
        assert s.n_items <= 40
        assert np.allclose(s.path_xy_m[0], sp.launch_xy_m) and np.allclose(s.path_xy_m[-1], sp.launch_xy_m)
        # independent energy: momentum theory from the vehicle's parameters, integrated over
        # the way-point trajectory in time (not leg by leg), within its quadrature bound
        e_wh, bound_wh = independent_flight_energy_wh(s.waypoints.t_s, s.waypoints.p_enu_m,
                                                      m.flight.height_agl_m, m.vehicle, m.energy)
        assert abs(s.energy.energy_wh - e_wh) <= bound_wh
        assert bound_wh < 2e-3 * e_wh
        # each main segment of the sortie is flown along: both its ends are path vertices
        for i in range(s.segments[0], s.segments[1] + 1):
            a, b = np.asarray(plan.coverage.main_segments[i])
            assert np.min(np.hypot(*(s.path_xy_m - a).T)) < 1e-6
            assert np.min(np.hypot(*(s.path_xy_m - b).T)) < 1e-6


def test_a_corridor_too_long_for_the_battery_is_a_one_line_error(tmp_path, capsys):
    from companion.cli import main

    text = FLAT.read_text()
    d = tmp_path / "m"
    d.mkdir()
    for f in ("map.yaml", "map.pgm", "dem.asc"):
        (d / f).write_bytes((FLAT.parent / f).read_bytes())
    (d / "mission.yaml").write_text(text + "energy: {battery_capacity_ah: 0.1}\n")
    rc = main(["plan", str(d / "mission.yaml"), "-o", str(tmp_path / "p.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "energy" in err[0] and "Wh" in err[0]
    assert not (tmp_path / "p.json").exists()


@pytest.mark.slow
def test_sitl_reports_the_battery_and_refuses_a_mission_it_cannot_hold():
    """Over UDP: SYS_STATUS and BATTERY_STATUS start full (6 cells at 4.2 V, the avionics'
    current only); hovering draws about P_hover / V; the charge falls. An upload of more
    items than energy.max_mission_items is refused with MAV_MISSION_NO_SPACE, named so."""
    from test_sitl_mavlink import Client, offboard_flight

    from companion.link import Connection
    from mavcore import codec
    from mavcore.services.mission import MissionRejected, MissionUploadClient
    from service_driver import drive
    from sitl.api import SitlThread

    with SitlThread(FLAT, speed=4.0) as sitl:
        gcs = Client(sitl.url)
        try:
            gcs.hello()
            st = gcs.recv("SYS_STATUS", 3.0)
            idle_a = 15.0 / (6 * 4.2)
            assert st.voltage_battery == pytest.approx(6 * 4200 - idle_a * 0.02 * 1000, abs=2)
            assert st.current_battery == pytest.approx(idle_a * 100, abs=1) and st.battery_remaining == 100
            bs = gcs.recv("BATTERY_STATUS", 3.0)
            cell_mv = (6 * 4.2 - idle_a * 0.02) / 6 * 1000
            assert list(bs.voltages[:6]) == [pytest.approx(cell_mv, abs=1)] * 6 and set(bs.voltages[6:]) == {65535}
            p0, sp = offboard_flight(gcs, 2.0)
            gcs.pump(3.0, sp)                                   # 12 s of vehicle time
            st = gcs.recv("SYS_STATUS", 3.0)
            amps = st.current_battery / 100
            volts = st.voltage_battery / 1000
            assert amps * volts == pytest.approx(hover_power_w(VEH, CFG), rel=0.1)
            bs = gcs.recv("BATTERY_STATUS", 3.0)
            assert bs.current_consumed > 0 and bs.energy_consumed > 0 and bs.battery_remaining <= 100
            assert sum(bs.voltages[:6]) / 1000 == pytest.approx(volts, abs=0.01)
        finally:
            gcs.close()
        conn = Connection(sitl.url.replace("udpin", "udpout")).open()
        try:
            conn.wait_heartbeat(timeout_s=5.0)
            items = [codec.encode_mission_item_int(conn.mav, i, (0.0, 0.0, 2.0), 44.8, -0.6, 30.0)
                     for i in range(2001)]
            with pytest.raises(MissionRejected) as exc:
                drive(conn, MissionUploadClient(conn.mav, conn.target_system, conn.target_component, items,
                                                capacity=load_mission(FLAT).energy.max_mission_items))
            assert exc.value.result == mavlink.MAV_MISSION_NO_SPACE
            assert "no space: 2001 items, vehicle holds 2000" in str(exc.value)
        finally:
            conn.close()


@pytest.mark.slow
def test_fly_one_sortie_from_the_launch_point(tmp_path, capsys):
    """``companion fly --plan plan.json --sortie 1`` against the SITL started at the launch
    point: it flies that sortie (its first uploaded way-point is the launch point at flight
    height; with --cut, a short prefix of it) and lands; a sortie the plan does not have
    is a one-line error."""
    import json

    from companion.cli import main
    from mavcore.frames import geodetic2enu
    from companion.link.tlog import read_tlog
    from sitl.api import SitlProcess

    m = load_mission(FLAT)
    assert main(["plan", str(FLAT), "-o", str(tmp_path / "plan.json")]) == 0
    doc = json.loads((tmp_path / "plan.json").read_text())
    launch = doc["launch_enu_m"]
    first = doc["sorties"][0]["waypoints"][0]["p"]
    assert first[:2] == pytest.approx(launch, abs=1e-9)
    capsys.readouterr()
    rc = main(private_link(["fly", str(FLAT), "--plan", str(tmp_path / "plan.json"), "--sortie", "2", "--quiet"]))
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--sortie" in err[0] and "it has 1" in err[0]
    report, tlog = tmp_path / "report.json", tmp_path / "f.tlog"
    with SitlProcess(FLAT, lockstep=True, speed=1.0, start=(launch[0], launch[1], 0.0)) as sitl:
        rc = main(["fly", str(FLAT), "--plan", str(tmp_path / "plan.json"), "--sortie", "1", "--connect",
                   sitl.url, "--control", "vehicle", "--tlog", str(tlog), "--report", str(report),
                   "--cut", "6", "--quiet"])
    rep = json.loads(report.read_text())
    assert rc == 0 and rep["completed"], rep.get("error")
    items = [r.msg for r in read_tlog(tlog) if r.msg.get_type() == "MISSION_ITEM_INT"]
    h = m.home
    p0 = geodetic2enu(items[0].x * 1e-7, items[0].y * 1e-7, items[0].z, h.lat, h.lon, h.alt_m)
    assert p0 == pytest.approx(first, abs=0.01)
