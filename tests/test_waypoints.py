"""Way-point extraction: corners, cruise points, altitudes on a sloped DEM, times."""

from __future__ import annotations

import numpy as np
import pytest

from companion.coverage import CoveragePlan, extract_waypoints
from companion.coverage.waypoints import A_REF_M_S2
from mavcore.errors import MapError
from mavcore.maps.grid import ElevationModel
from mavcore.mission.schema import FlightConfig

# plane z = A x + B y + C, sampled on a 1 m DEM (bilinear reproduces a plane exactly)
A, B, C = 0.08, -0.05, 3.0


def plane_dem():
    x0, y0 = -5.0, -5.0
    xs = x0 + np.arange(40)
    ys = y0 + np.arange(20)
    return ElevationModel(heights_m=A * xs[None, :] + B * ys[:, None] + C, x0_m=x0, y0_m=y0,
                          cellsize_m=1.0, source="plane.asc")


def plan_from_path(path):
    path = np.asarray(path, dtype=float)
    return CoveragePlan(path_xy_m=path, orientation_deg=0.0, line_spacing_m=3.0, main_segments=[],
                        aux_paths=[], free_eroded=np.zeros((1, 1), bool), coverage_fraction=1.0,
                        path_length_m=float(np.sum(np.hypot(*np.diff(path, axis=0).T))))


PATH = [(0.0, 0.0), (20.0, 0.0), (20.0, 3.0), (0.0, 3.0)]


def test_corners_altitudes_and_velocities():
    flight = FlightConfig(height_agl_m=1.5, speed_m_s=1.0, waypoint_interval_s=4.0)
    w = extract_waypoints(plan_from_path(PATH), plane_dem(), flight)
    # altitudes: z = A x + B y + C + height, computed by hand from the plane
    x, y, z = w.p_enu_m.T
    assert np.allclose(z, A * x + B * y + C + 1.5, atol=1e-9)
    # corners are exactly the path vertices, in order, at rest
    assert np.allclose(w.p_enu_m[w.corner, :2], PATH)
    assert np.all(w.v_enu_m_s[w.corner] == 0.0)
    assert np.all(w.a_enu_m_s2 == 0.0)
    assert w.t_s[0] == 0.0 and np.all(np.diff(w.t_s) > 0)
    # intermediate points: |v| = speed, along the run's 3D direction
    mid = ~w.corner
    assert mid.sum() > 0
    assert np.allclose(np.linalg.norm(w.v_enu_m_s[mid], axis=1), 1.0)
    for i in np.flatnonzero(mid):
        run = 0 if w.p_enu_m[i, 1] < 1.5 else 2                  # runs along y = 0 and y = 3
        dxy = np.array(PATH[run + 1]) - np.array(PATH[run])
        d3 = np.append(dxy, A * dxy[0] + B * dxy[1])
        assert np.allclose(w.v_enu_m_s[i], d3 / np.linalg.norm(d3), atol=1e-9)


def test_intermediate_spacing_and_times():
    flight = FlightConfig(height_agl_m=2.0, speed_m_s=1.0, waypoint_interval_s=4.0)
    w = extract_waypoints(plan_from_path(PATH), plane_dem(), flight)
    V, dt = 1.0, 4.0
    # first run: 20 m in x on slope A -> 3D length 20 sqrt(1 + A^2)
    S = 20.0 * np.hypot(1.0, A)
    t_acc = 1.875 * V / A_REF_M_S2                 # quintic ramp, peak accel a_ref
    g_min = max(V * dt / 2, V * t_acc / 2)
    n_mid = int(np.floor((S - 2 * g_min) / (V * dt))) + 1
    g = (S - (n_mid - 1) * V * dt) / 2
    run = w.p_enu_m[1:1 + n_mid]
    assert not w.corner[1:1 + n_mid].any() and w.corner[1 + n_mid]
    # consecutive intermediate points are speed x interval apart (3D) and interval apart in time
    assert np.allclose(np.linalg.norm(np.diff(run, axis=0), axis=1), V * dt, atol=1e-6)
    assert np.allclose(np.diff(w.t_s[1:1 + n_mid]), dt)
    # symmetric end gaps g, with the ramp time added to their pieces
    assert np.linalg.norm(run[0] - w.p_enu_m[0]) == pytest.approx(g, abs=1e-6)
    assert np.linalg.norm(w.p_enu_m[1 + n_mid] - run[-1]) == pytest.approx(g, abs=1e-6)
    assert w.t_s[1] == pytest.approx(g / V + t_acc / 2)
    # the 3 m connection is too short for cruise points: quintic rest-to-rest time
    i = 1 + n_mid
    L = np.linalg.norm(w.p_enu_m[i + 1] - w.p_enu_m[i])
    assert L == pytest.approx(3.0 * np.hypot(1.0, B))
    expected = max(1.875 * L / V, np.sqrt(10 / np.sqrt(3) * L / A_REF_M_S2))
    assert w.t_s[i + 1] - w.t_s[i] == pytest.approx(expected, rel=1e-6)


def test_each_run_keeps_its_own_speed():
    """Per-run speeds (a sortie's transits at the transit speed): spacing speed x
    interval, |v| the run's speed, the ramp time of that speed, runs of several lengths."""
    from companion.coverage.waypoints import waypoints_along

    flight = FlightConfig(height_agl_m=1.0, speed_m_s=1.0, waypoint_interval_s=2.0)
    path = np.array([(0.0, 0.0), (30.0, 0.0), (30.0, 0.2), (30.0, 12.0), (2.0, 12.0)])
    speeds = np.array([3.0, 3.0, 1.0, 2.0])
    w = waypoints_along(path, plane_dem(), flight, speeds_m_s=speeds)
    assert np.allclose(w.p_enu_m[w.corner, :2], path)
    x, y, z = w.p_enu_m.T
    assert np.allclose(z, A * x + B * y + C + 1.0, atol=1e-9)
    ic = np.flatnonzero(w.corner)
    for k, V in enumerate(speeds):
        mid = np.arange(ic[k] + 1, ic[k + 1])
        d3 = np.append(path[k + 1] - path[k], A * (path[k + 1, 0] - path[k, 0]) + B * (path[k + 1, 1] - path[k, 1]))
        S = np.linalg.norm(d3)
        t_acc = 1.875 * V / A_REF_M_S2
        g_min = max(V * 2.0 / 2, V * t_acc / 2)
        n_mid = int(np.floor((S - 2 * g_min) / (V * 2.0))) + 1 if S >= 2 * g_min else 0
        assert len(mid) == n_mid, k
        if n_mid:
            assert np.allclose(w.v_enu_m_s[mid], V * d3 / S, atol=1e-9)
            assert np.allclose(np.linalg.norm(np.diff(w.p_enu_m[mid], axis=0), axis=1), 2.0 * V, atol=1e-6)
            g = (S - (n_mid - 1) * V * 2.0) / 2
            assert w.t_s[mid[0]] - w.t_s[ic[k]] == pytest.approx(g / V + t_acc / 2)
        else:
            expected = max(1.875 * S / V, np.sqrt(10 / np.sqrt(3) * S / A_REF_M_S2))
            assert w.t_s[ic[k + 1]] - w.t_s[ic[k]] == pytest.approx(expected, rel=1e-6)


def test_dem_not_covering_the_path_is_an_error():
    dem = plane_dem()
    with pytest.raises(MapError, match="plane.asc"):
        extract_waypoints(plan_from_path([(0.0, 0.0), (60.0, 0.0)]), dem, FlightConfig())


def test_lqr_trajectory_passes_the_waypoints_within_5_cm():
    lqr = pytest.importorskip("companion.trajectory.lqr")
    w = extract_waypoints(plan_from_path(PATH + [(0.0, 6.0), (25.0, 6.0)]), plane_dem(), FlightConfig())
    traj = lqr.generate_trajectory(w.t_s, w.p_enu_m, w.v_enu_m_s, w.a_enu_m_s2)
    states = traj.sample(w.t_s)
    assert np.max(np.linalg.norm(states.p - w.p_enu_m, axis=1)) <= 0.05
