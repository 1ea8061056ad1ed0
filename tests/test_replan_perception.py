"""Perception: DISTANCE_SENSOR on the wire -> sensor rotation (codec) -> ENU
evidence (every orientation, yawed and tilted poses, mounting offsets),
the pose history, known-vs-unknown classification and the obstacle memory.

Expected directions are worked by hand: MAV_SENSOR_ORIENTATION k (0..7) is
a yaw of k x 45 deg in FRD (forward turning right), so in FLU the beam is
(cos 45k, -sin 45k, 0); PITCH_90 (24) looks up, PITCH_270 (25) down.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore import frames
from companion.coverage.freespace import erode_free_space
from mavcore import codec
from mavcore.maps.grid import ElevationModel, OccupancyGrid
from mavcore.mission.replan import ReplanConfig, SensorMount
from companion.replan import KnownMap, ObstacleMemory, Pose, PoseHistory, beam_evidence
from companion.replan.knownmap import KNOWN_ADDED, KNOWN_GROUND, KNOWN_ROW, UNKNOWN

S2 = math.sqrt(0.5)
#: body FLU beam of each orientation, by hand
BEAM_FLU = {0: (1, 0, 0), 1: (S2, -S2, 0), 2: (0, -1, 0), 3: (-S2, -S2, 0), 4: (-1, 0, 0),
            5: (-S2, S2, 0), 6: (0, 1, 0), 7: (S2, S2, 0), 24: (0, 0, 1), 25: (0, 0, -1)}


def _wire(msg, mav):
    rx = mavlink.MAVLink(None)
    out = rx.parse_buffer(msg.pack(mav))
    assert out is not None and len(out) == 1
    return out[0]


def _mav():
    return mavlink.MAVLink(None, srcSystem=1, srcComponent=1)


def _reading(orientation, distance_cm, q=(0.0, 0.0, 0.0, 0.0), hfov=0.1, vfov=0.05, max_cm=1000, cov=255):
    mav = _mav()
    m = mav.distance_sensor_encode(1234, 10, max_cm, distance_cm, mavlink.MAV_DISTANCE_SENSOR_LASER, 7,
                                   orientation, cov, hfov, vfov, q, 100)
    return codec.decode_distance_sensor(_wire(m, mav))


# --- codec: the sensor's rotation -----------------------------------------------------------


@pytest.mark.parametrize("orientation", sorted(BEAM_FLU))
def test_decoded_beam_direction_every_orientation(orientation):
    r = _reading(orientation, 250)
    S = np.array(r.R_flu_sensor).reshape(3, 3)
    np.testing.assert_allclose(S[:, 0], BEAM_FLU[orientation], atol=1e-12)
    np.testing.assert_allclose(S @ S.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(S) == pytest.approx(1.0)
    # the FOV axes: horizontal sensors spread in the horizontal plane, vertical ones along body y
    if orientation in (24, 25):
        np.testing.assert_allclose(np.abs(S[:, 1]), (0, 1, 0), atol=1e-12)
    else:
        assert S[2, 1] == 0.0 and S[:, 2] == pytest.approx((0, 0, 1))
    assert (r.distance_m, r.hfov_rad, r.vfov_rad, r.no_return) == (2.5, pytest.approx(0.1), pytest.approx(0.05), False)


def test_custom_orientation_from_the_quaternion():
    # FRD pitch +30 deg (nose up): the beam is forward and 30 deg up in FLU
    q = (math.cos(math.radians(15)), 0.0, math.sin(math.radians(15)), 0.0)
    r = _reading(codec.MAV_SENSOR_ROTATION_CUSTOM, 300, q)
    S = np.array(r.R_flu_sensor).reshape(3, 3)
    np.testing.assert_allclose(S[:, 0], (math.cos(math.radians(30)), 0, math.sin(math.radians(30))), atol=1e-6)
    # FRD yaw +90 deg through CUSTOM is the same sensor as orientation 2 (right)
    q = (S2, 0.0, 0.0, S2)
    r2 = _reading(codec.MAV_SENSOR_ROTATION_CUSTOM, 300, q)
    np.testing.assert_allclose(r2.R_flu_sensor, _reading(2, 300).R_flu_sensor, atol=1e-6)
    # the quaternion is ignored unless CUSTOM
    assert _reading(0, 300, q).R_flu_sensor == _reading(0, 300).R_flu_sensor


def test_custom_with_invalid_quaternion_or_unsupported_orientation_has_no_rotation():
    assert _reading(codec.MAV_SENSOR_ROTATION_CUSTOM, 300, (0.0, 0.0, 0.0, 0.0)).R_flu_sensor is None
    assert _reading(codec.MAV_SENSOR_ROTATION_CUSTOM, 300, (math.nan, 0.0, 0.0, 1.0)).R_flu_sensor is None
    assert _reading(8, 300).R_flu_sensor is None                        # ROLL_180: not a rangefinder's
    assert codec.sensor_rotation_flu(codec.MAV_SENSOR_ROTATION_CUSTOM, None) is None


def test_no_return_covariance_and_too_close():
    r = _reading(0, 1001, cov=16)
    assert math.isnan(r.distance_m) and r.no_return and r.covariance_m2 == pytest.approx(16e-4)
    r = _reading(0, 5)
    assert math.isnan(r.distance_m) and not r.no_return and math.isnan(r.covariance_m2)


def test_R_frd2flu_is_an_involution_and_matches_vectors():
    rng = np.random.default_rng(3)
    R = frames.quat_wxyz2rotmat(rng.normal(size=4))
    np.testing.assert_allclose(frames.R_frd2flu(frames.R_frd2flu(R)), R, atol=1e-12)
    v = rng.normal(size=3)
    # rotating in FRD then converting equals converting then rotating in FLU
    np.testing.assert_allclose(frames.frd2flu(R @ v), frames.R_frd2flu(R) @ frames.frd2flu(v), atol=1e-12)


# --- beam geometry against hand-placed points -------------------------------------------------


def _Rz(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _Rx(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


P0 = (2.0, 3.0, 1.5)
OFFSET = (0.2, -0.1, 0.05)
#: yaw 90 deg (body x north, body y west, z up): the offset is (+0.1 east, +0.2 north, +0.05 up)
ENU_YAW90 = {0: (0, 1, 0), 1: (S2, S2, 0), 2: (1, 0, 0), 3: (S2, -S2, 0), 4: (0, -1, 0),
             5: (-S2, -S2, 0), 6: (-1, 0, 0), 7: (-S2, S2, 0), 24: (0, 0, 1), 25: (0, 0, -1)}
#: roll 90 deg, yaw 0 (body y up, body z south): the offset is (+0.2 east, -0.05 north, -0.1 up)
ENU_ROLL90 = {0: (1, 0, 0), 2: (0, 0, -1), 6: (0, 0, 1), 24: (0, -1, 0), 25: (0, 1, 0), 1: (S2, 0, -S2)}


@pytest.mark.parametrize("orientation", sorted(BEAM_FLU))
def test_hit_point_yawed_pose_with_offset(orientation):
    pose = Pose(0.0, P0, tuple(_Rz(90).ravel()))
    ev = beam_evidence(_reading(orientation, 400), pose, OFFSET)
    origin = (2.1, 3.2, 1.55)
    np.testing.assert_allclose(ev.origin, origin, atol=1e-12)
    np.testing.assert_allclose(ev.axis, ENU_YAW90[orientation], atol=1e-12)
    np.testing.assert_allclose(ev.hit, np.add(origin, 4.0 * np.array(ENU_YAW90[orientation])), atol=1e-12)
    assert ev.free_m == 4.0


@pytest.mark.parametrize("orientation", sorted(ENU_ROLL90))
def test_hit_point_tilted_pose_with_offset(orientation):
    pose = Pose(0.0, P0, tuple(_Rx(90).ravel()))
    ev = beam_evidence(_reading(orientation, 250), pose, OFFSET)
    origin = (2.2, 2.95, 1.4)
    np.testing.assert_allclose(ev.origin, origin, atol=1e-12)
    np.testing.assert_allclose(ev.hit, np.add(origin, 2.5 * np.array(ENU_ROLL90[orientation])), atol=1e-12)


def test_custom_pitched_sensor_on_a_yawed_vehicle():
    q = (math.cos(math.radians(15)), 0.0, math.sin(math.radians(15)), 0.0)    # 30 deg up
    pose = Pose(0.0, P0, tuple(_Rz(90).ravel()))
    ev = beam_evidence(_reading(codec.MAV_SENSOR_ROTATION_CUSTOM, 200, q), pose)
    np.testing.assert_allclose(ev.hit, (2.0, 3.0 + 2 * math.cos(math.radians(30)), 1.5 + 1.0), atol=1e-5)


def test_fan_points_follow_the_sensor_roll():
    # CUSTOM roll +90 deg (FRD) about the beam: the horizontal field of view turns vertical
    q = (S2, S2, 0.0, 0.0)
    hfov = math.radians(20)
    ev = beam_evidence(_reading(codec.MAV_SENSOR_ROTATION_CUSTOM, 300, q, hfov=hfov, vfov=0.0),
                       Pose(0.0, (0.0, 0.0, 1.5), tuple(np.eye(3).ravel())))
    assert len(ev.fan_hits) == 4                     # wider than 10 deg: the edges and half-way
    zs = sorted(h[2] - 1.5 for h in ev.fan_hits)
    s1, s2 = 3 * math.sin(hfov / 2), 3 * math.sin(hfov / 4)
    np.testing.assert_allclose(zs, [-s1, -s2, s2, s1], atol=1e-6)
    np.testing.assert_allclose([h[1] for h in ev.fan_hits], 0.0, atol=1e-6)
    assert ev.half_v_rad == 0.0 and ev.half_h_rad == ev.half_max_rad == pytest.approx(hfov / 2)
    np.testing.assert_allclose(np.abs(ev.h_axis), (0, 0, 1), atol=1e-6)   # the FOV opens vertically


def test_no_return_clears_to_max_and_invalid_reading_gives_nothing():
    pose = Pose(0.0, P0, tuple(np.eye(3).ravel()))
    ev = beam_evidence(_reading(0, 1001), pose)
    assert ev.hit is None and ev.free_m == 10.0
    assert beam_evidence(_reading(0, 5), pose) is None                      # below min: no evidence
    assert beam_evidence(_reading(8, 300), pose) is None                    # unsupported orientation


# --- pose history ---------------------------------------------------------------------------


def test_pose_history_interpolates_and_bounds():
    h = PoseHistory()
    R0, R1 = tuple(np.eye(3).ravel()), tuple(_Rz(10).ravel())
    h.add(1.000, (0.0, 0.0, 1.0), R0)
    h.add(1.004, (0.004, 0.0, 1.0), R1)
    p = h.at(1.001)
    assert p.p == pytest.approx((0.001, 0.0, 1.0)) and p.R == R0         # nearer pose's attitude
    assert h.at(1.003).R == R1
    assert h.at(1.014).p == pytest.approx((0.014, 0.0, 1.0))              # extrapolated 10 ms
    assert h.at(1.2) is None and h.at(0.9) is None
    for k in range(200):                                                   # keeps HISTORY_S only
        h.add(2.0 + 0.004 * k, (0.0, 0.0, 0.0), R0)
    assert h.at(1.004) is None and len(h) <= 0.5 / 0.004 + 2


def test_pose_history_takes_reordered_poses_in_time_order():
    """A lossy link delivers frames out of order: a pose older than the last is
    slotted in (it used to wipe the history, leaving readings with one pose or
    none), and one older than the whole history still restarts it."""
    h = PoseHistory()
    R0 = tuple(np.eye(3).ravel())
    for t, x in ((1.000, 0.0), (1.008, 0.008), (1.004, 0.004), (1.012, 0.012)):
        h.add(t, (x, 0.0, 1.0), R0)
    assert len(h) == 4
    assert h.at(1.006).p == pytest.approx((0.006, 0.0, 1.0))
    assert h.at(1.002).p == pytest.approx((0.002, 0.0, 1.0))
    h.add(0.2, (5.0, 0.0, 1.0), R0)                      # older than HISTORY_S: a restart
    assert len(h) == 1 and h.at(1.006) is None


def test_propagated_pose_matches_the_matrix_exponential():
    """Position carried by its velocity; attitude by R exp([w]x dt) with body rates,
    checked against scipy's rotation-vector exponential; bounded intervals."""
    from scipy.spatial.transform import Rotation

    from companion.replan.perception import MAX_PROPAGATION_S, propagated_pose

    R0 = Rotation.from_euler("ZYX", [170.0, 4.0, -3.0], degrees=True).as_matrix()
    w = (0.05, -0.1, math.radians(12.5))
    p, R = propagated_pose(0.08, (9.0, 8.75, 1.5), (-1.0, 0.0, 0.1), 0.08, R0.ravel(), w)
    assert p == pytest.approx((8.92, 8.75, 1.508))
    want = R0 @ Rotation.from_rotvec(np.array(w) * 0.08).as_matrix()
    assert np.allclose(np.reshape(R, (3, 3)), want, atol=1e-12)
    p, R = propagated_pose(10.0, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), -10.0, R0.ravel(), (0.0, 0.0, 1.0))
    assert p[0] == pytest.approx(MAX_PROPAGATION_S)
    assert np.allclose(np.reshape(R, (3, 3)), R0 @ _Rz(-math.degrees(MAX_PROPAGATION_S)), atol=1e-12)


def test_a_stale_attitude_carried_to_the_reading_keeps_a_row_return_on_the_row():
    """The lossy-link phantom: heading west and turning at 30 deg/s, six ATTITUDE
    messages lost (120 ms), a return from a row's face 7.5 m ahead. Placed with the
    stale attitude it lands 0.45 m off the face in the corridor (unknown: a phantom
    obstacle); carried to the reading's time with the body rate it is the row."""
    from companion.replan.perception import propagated_pose

    km = _known()                                       # a row: x 1..5 m, y 1.8..2.2 m
    pos, hit = (11.0, 1.0, 1.0), (3.5, 1.85, 1.0)
    d = math.hypot(hit[0] - pos[0], hit[1] - pos[1])
    yaw_true = math.degrees(math.atan2(hit[1] - pos[1], hit[0] - pos[0]))
    rate, age = math.radians(-30.0), 0.12
    yaw_stale = yaw_true - math.degrees(rate * age)
    reading = codec.Range(time_boot_ms=0, sensor_id=0, distance_m=d, min_m=0.1, max_m=10.0, orientation=0,
                          R_flu_sensor=tuple(np.eye(3).ravel()))
    stale = Pose(0.0, pos, tuple(_Rz(yaw_stale).ravel()))
    _, R = propagated_pose(0.0, pos, (0.0, 0.0, 0.0), age, stale.R, (0.0, 0.0, rate))
    fresh = Pose(0.0, pos, R)
    assert beam_evidence(reading, fresh).hit == pytest.approx(hit)
    assert km.classify(*beam_evidence(reading, stale).hit) == UNKNOWN
    for pose, explained in ((stale, False), (fresh, True)):
        ev = beam_evidence(reading, pose)
        assert km.explains(ev.origin, ev.axis, ev.distance_m) is explained, pose


# --- known vs unknown -------------------------------------------------------------------------


def _known() -> KnownMap:
    occ = np.zeros((40, 60), dtype=bool)
    occ[18:22, 10:50] = True                        # a row: x 1..5 m, y 1.8..2.2 m
    grid = OccupancyGrid(occupied=occ, free=~occ, resolution_m=0.1)
    dem = ElevationModel(np.array([[0.0, 0.6], [0.0, 0.6]]), x0_m=0.0, y0_m=0.0, cellsize_m=6.0)  # slope 0.1
    return KnownMap.build(grid, dem, erode_free_space(grid, 0.5), 2.0, 0.2)


def test_classification_row_ground_post_canopy_top():
    km = _known()
    assert km.classify(3.0, 1.8, 1.5) == KNOWN_ROW            # the row's south face
    assert km.classify(3.0, 1.65, 1.5) == KNOWN_ROW           # within the tolerance of the face
    assert km.classify(3.0, 1.3, 1.5) == UNKNOWN              # a post in the corridor
    assert km.classify(3.0, 2.0, 2.0 + 0.3 + 0.25) == UNKNOWN  # above canopy + tolerance (ground 0.3)
    assert km.classify(3.0, 2.0, 2.0 + 0.3) == KNOWN_ROW
    assert km.classify(3.0, 1.0, 0.3 + 0.1) == KNOWN_GROUND   # the sloped terrain under the hit
    assert km.classify(3.0, 1.0, 0.3 + 0.25) == UNKNOWN
    assert km.classify(-5.0, 1.0, 1.0) == UNKNOWN             # off the map, above the ground
    added = km.with_obstacle(np.array([[3.0, 1.0]]))
    assert added.classify(3.0, 1.05, 3.5) == KNOWN_ADDED      # any height over an added obstacle
    assert km.classify(3.0, 1.05, 3.5) == UNKNOWN             # the original map is unchanged


def test_explains_a_return_only_where_the_ray_enters_a_known_surface():
    km = _known()                                   # the row: x 1..5 m, y 1.8..2.2 m, canopy 2 m
    o = (3.0, 0.8, 1.5)
    north = (0.0, 1.0, 0.0)
    assert km.explains(o, north, 1.0)              # head-on into the south face
    assert not km.explains(o, north, 0.6)          # short of it: something else
    assert not km.explains(o, north, 1.9)          # beyond the row: the face would have answered first
    # grazing along the face at 3 deg: enters it at the measured range
    a = math.radians(3.0)
    g = (math.cos(a), math.sin(a), 0.0)
    o2 = (1.5, 1.8 - 0.05, 1.5)
    d = 0.05 / math.sin(a)
    assert km.explains(o2, g, d)
    # the row's corner, touched
    c = (1.0, 1.8)
    o3 = (0.5, 1.3, 1.5)
    u = np.array([c[0] - 0.5, c[1] - 1.3, 0.0])
    assert km.explains(o3, tuple(u / np.linalg.norm(u)), float(np.linalg.norm(u)))
    # above the canopy (ground 0.3 m there): not the row; on the ground: yes
    assert not km.explains((3.0, 0.8, 3.0), north, 1.0)
    down = (0.0, 0.0, -1.0)
    assert km.explains((3.0, 1.0, 1.5), down, 1.5 - 0.3)


def test_grazing_return_a_few_centimetres_off_the_face_is_the_row():
    """A beam along the corridor 8 deg off the row's face (y = 1.8 m): the range comes
    rounded to the centimetre, with noise, from an estimated pose, so its point lands a
    few centimetres before or inside the face, where the 0.1 m along-ray window sees
    only a centimetre of depth. Within a cell of the face it is the row; 0.3 m short of
    the face (a post standing in front of the row) it is not. (Seen in the SITL: every
    beam looking along a corridor made phantom obstacles before this rule.)"""
    km = _known()
    a = math.radians(8.0)
    g = (math.cos(a), math.sin(a), 0.0)
    o = (1.0, 1.3, 1.5)
    d_face = 0.5 / math.sin(a)                      # where the ray meets y = 1.8
    for short_m in (0.04, 0.02, -0.03):             # before the face, and 3 cm inside it
        assert km.explains(o, g, d_face - short_m / math.sin(a)), short_m
    assert not km.explains(o, g, d_face - 0.3 / math.sin(a))
    # a ray that already ran through the row a metre before its return: not the row's surface
    o_in = (1.0, 1.9, 1.5)
    assert not km.explains(o_in, (1.0, 0.0, 0.0), 1.5)


def test_wide_beam_in_a_corridor_sees_the_post_not_the_row():
    """A 40 deg beam in front of a post: its edge reaches the row only beyond
    the post's range, so the row does not explain the return."""
    from companion.replan import GlobalPlan, Replanner
    from companion.trajectory import generate_trajectory
    from mavcore.mission.trajectory import TrajectoryConfig
    from mavcore.mission.schema import FlightConfig
    km = _known()
    t = np.array([0.0, 10.0])
    p = np.array([[0.5, 1.0, 1.8], [5.5, 1.0, 1.8]])
    plan = GlobalPlan.from_waypoints(generate_trajectory(t, p), t, p, np.zeros((2, 3)), np.zeros((2, 3)),
                                     np.array([True, True]), None, None, FlightConfig(), TrajectoryConfig(), 1.0)
    rp = Replanner(ReplanConfig(), km, plan)
    rp.on_pose(1.234, (1.5, 1.0, 1.5), tuple(np.eye(3).ravel()))       # looking east along y = 1
    # post 1.5 m ahead on the axis; the beam's left edge (20 deg) meets the row face (y = 1.8) at 2.34 m
    rp.on_range(1.234, _reading(0, 150, hfov=math.radians(40), vfov=0.0))
    assert len(rp.memory) >= 1 and rp.memory.distance(np.array([(3.0, 1.0, 1.5)]))[0] < 1e-9    # its voxel
    # the same beam whose return is the row face along its left edge: explained, nothing kept
    rp2 = Replanner(ReplanConfig(), km, plan)
    rp2.on_pose(1.234, (1.5, 1.0, 1.5), tuple(np.eye(3).ravel()))
    rp2.on_range(1.234, _reading(0, round(100 * 0.8 / math.sin(math.radians(20))), hfov=math.radians(40), vfov=0.0))
    assert len(rp2.memory) == 0


def test_with_obstacle_erodes_the_free_space_locally():
    km = _known()
    before = km.free.eroded.copy()
    added = km.with_obstacle(np.array([[3.0, 1.0]]))
    lost = before & ~added.free.eroded
    rows, cols = np.nonzero(lost)
    # every cell lost is within the erosion threshold (+ half a cell diagonal) of the obstacle cell
    xy = np.column_stack(km.grid.cell_to_world(rows, cols))
    d = np.hypot(xy[:, 0] - 3.05, xy[:, 1] - 1.05)
    assert len(d) and d.max() <= km.free.threshold_m + 1e-9
    assert not (added.free.eroded & ~before).any()


def test_replanner_keeps_unknown_hits_only():
    from companion.replan import GlobalPlan, Replanner
    from companion.trajectory import generate_trajectory
    from mavcore.mission.trajectory import TrajectoryConfig
    from mavcore.mission.schema import FlightConfig
    km = _known()
    t = np.array([0.0, 10.0])
    p = np.array([[0.5, 1.0, 1.8], [5.5, 1.0, 1.8]])
    traj = generate_trajectory(t, p, target_enu_m=np.array([3.0, 5.0, 1.8]))
    plan = GlobalPlan.from_waypoints(traj, t, p, np.zeros((2, 3)), np.zeros((2, 3)), np.array([True, True]),
                                     np.zeros((0, 2, 2)), np.array([3.0, 5.0, 1.8]), FlightConfig(),
                                     TrajectoryConfig(), 1.0, (5.5, 1.0))
    rp = Replanner(ReplanConfig(sensors=(SensorMount(7, (0.0, 0.0, 0.0)),)), km, plan)
    rp.on_pose(1.234, (3.0, 1.0, 1.8), tuple(np.eye(3).ravel()))
    rp.on_range(1.234, _reading(6, 80))          # left (north): the row face at y = 1.8
    rp.on_range(1.234, _reading(25, 150))        # down: the ground (0.3 m there)
    assert len(rp.memory) == 0
    rp.on_range(1.234, _reading(2, 60))          # right (south): something at y = 0.4
    assert len(rp.memory) == 1 and rp.memory.distance(np.array([(3.0, 0.4, 1.8)]))[0] < 1e-9     # its voxel
    assert rp.stats.unknown_hits == 1 and rp.stats.readings == 3


# --- memory ---------------------------------------------------------------------------------------


def _memory(**kw):
    args = dict(voxel_m=0.1, lifetime_s=5.0, radius_m=15.0, clear_margin_m=0.15)
    args.update(kw)
    return ObstacleMemory(**args)


def test_memory_decays_unless_seen_again():
    m = _memory()
    m.add(0.0, (5.0, 0.0, 1.5))
    m.add(0.0, (6.0, 0.0, 1.5))
    m.add(4.0, (6.02, 0.01, 1.51))               # same voxel: refreshed, not added, not moved
    assert len(m) == 2
    m.expire(5.5, (0.0, 0.0, 1.5))
    assert len(m) == 1 and m.points()[0] == pytest.approx((6.0, 0.0, 1.5))
    m.expire(9.5, (0.0, 0.0, 1.5))
    assert len(m) == 0


def _beam(origin, axis, h_axis, free_m, half_h=math.radians(2.5), half_v=math.radians(2.5)):
    from companion.replan import BeamEvidence
    v_axis = tuple(np.cross(axis, h_axis))
    return BeamEvidence(origin, axis, h_axis, v_axis, half_h, half_v, free_m, None, math.nan)


def test_memory_cleared_by_a_beam_through_the_point_not_beside_it():
    m = _memory()
    m.add(0.0, (3.0, 0.0, 1.5))
    # a beam beside the point (the side sensor after passing it) does not clear it
    m.clear_beam(_beam((4.0, 0.0, 1.5), (0.0, 1.0, 0.0), (-1.0, 0.0, 0.0), 10.0))
    assert len(m) == 1
    # a beam whose return is at the point keeps it (within the margin)
    m.clear_beam(_beam((0.0, 0.0, 1.5), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), 3.05))
    assert len(m) == 1
    # a beam that now reaches farther through the point clears it
    m.clear_beam(_beam((0.0, 0.0, 1.5), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), 8.0))
    assert len(m) == 0


def test_memory_clearing_follows_the_inner_field_of_view():
    """A fan 40 deg wide (20 deg half-angle), flat, looking east: it clears within
    half its half-angle (10 deg) only; a point 18 deg off the axis, at the edge
    where a sensor may miss a small object, stays (hand-worked angles)."""
    fan = _beam((0.0, 0.0, 1.5), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), 8.0, math.radians(20), 0.0)
    m = _memory()
    m.add(0.0, (3.0, 0.45, 1.5))         # 8.5 deg off the axis: cleared
    m.add(0.0, (3.0, 1.0, 1.5))          # 18 deg off: in the fan's edge, kept
    m.add(0.0, (3.0, 1.2, 1.5))          # 22 deg off: outside
    m.add(0.0, (3.0, 0.0, 1.8))          # above the flat fan
    assert m.clear_beam(fan) == 1 and len(m) == 3
    # a short-lived candidate (a wide beam's possible return position) at 18 deg
    # is cleared by the whole field of view
    m.add(0.0, (3.0, -1.0, 1.5), 1.0)
    assert m.clear_beam(fan) == 1 and len(m) == 3


def test_memory_bounded_and_local():
    m = _memory(capacity=16)
    for k in range(100):
        m.add(float(k), (0.3 * k, 0.0, 1.0))
    assert len(m) == 16
    assert m.points()[:, 0].min() == pytest.approx(0.3 * 84)        # the oldest went first
    m.expire(100.0, (0.3 * 99, 0.0, 1.0))
    assert len(m) == 5                                              # seen within the 5 s lifetime
    m2 = _memory(radius_m=1.0)
    m2.add(0.0, (0.0, 0.0, 0.0))
    m2.add(0.0, (5.0, 0.0, 0.0))
    m2.expire(0.0, (0.0, 0.0, 0.0))
    assert len(m2) == 1


def test_replanner_map_remembers_an_obstacle_unseen_for_60_s_and_a_beam_clears_it():
    """No time-out (issue 15): 60 s of flight with no reading leaves the obstacle in the
    map; one beam through it (a longer return along the same line) clears it."""
    from companion.replan import GlobalPlan, Replanner
    from companion.trajectory import generate_trajectory
    from mavcore.mission.trajectory import TrajectoryConfig
    from mavcore.mission.schema import FlightConfig
    km = _known()
    t = np.array([0.0, 10.0])
    p = np.array([[0.5, 1.0, 1.8], [5.5, 1.0, 1.8]])
    plan = GlobalPlan.from_waypoints(generate_trajectory(t, p), t, p, np.zeros((2, 3)), np.zeros((2, 3)),
                                     np.array([True, True]), None, None, FlightConfig(), TrajectoryConfig(), 1.0)
    rp = Replanner(ReplanConfig(), km, plan)
    eye = tuple(np.eye(3).ravel())
    rp.on_pose(1.234, (3.0, 1.0, 1.8), eye)
    rp.on_range(1.234, _reading(2, 60))                 # right (south): something at y = 0.4
    where = np.array([(3.0, 0.4, 1.8)])
    assert rp.memory.distance(where)[0] < 1e-9
    for k in range(1, 1201):                             # 60 s, the vehicle holding there
        rp.on_pose(1.234 + 0.05 * k, (3.0, 1.0, 1.8), eye)
        rp.step(1.234 + 0.05 * k, (3.0, 1.0, 1.8), (0.0, 0.0, 0.0))
    assert len(rp.memory) == 1 and rp.memory.distance(where)[0] < 1e-9
    rp.on_range(1.234 + 60.0, _reading(2, 150))         # the same beam now returns at 1.5 m: through it
    assert rp.memory.log_odds((3.0, 0.4, 1.8)) == 0.0 and rp.memory.distance(where)[0] > 0.5


def test_a_remembered_point_behind_a_row_is_no_threat():
    """The map remembers for good, so an obstacle seen from the next corridor stays in it;
    the line to it crosses the row (x 1..5 m, y 1.8..2.2 m), so it starts no avoidance here."""
    from companion.replan import GlobalPlan, Replanner
    from companion.trajectory import generate_trajectory
    from mavcore.mission.trajectory import TrajectoryConfig
    from mavcore.mission.schema import FlightConfig
    km = _known()
    t = np.array([0.0, 10.0])
    p = np.array([[0.5, 1.0, 1.8], [5.5, 1.0, 1.8]])
    plan = GlobalPlan.from_waypoints(generate_trajectory(t, p), t, p, np.zeros((2, 3)), np.zeros((2, 3)),
                                     np.array([True, True]), None, None, FlightConfig(), TrajectoryConfig(), 1.0)
    rp = Replanner(ReplanConfig(), km, plan)
    pts = np.array([[3.0, 3.0, 1.5], [3.0, 0.2, 1.5], [6.0, 3.0, 1.5], [3.0, 3.0, 2.9]])
    # across the row / beside the vehicle in its corridor / across the row's east end / above the canopy
    np.testing.assert_array_equal(rp._behind_row((3.0, 1.0, 1.5), pts), [True, False, True, False])
    rp.memory.add((3.0, 3.0, 1.5))
    assert rp._threat((3.0, 1.0, 1.5), (0.0, 0.0, 0.0), np.array([1.0, 0.0])) is None
    rp.memory.add((3.5, 0.5, 1.5))
    assert rp._threat((3.0, 1.0, 1.5), (0.0, 0.0, 0.0), np.array([1.0, 0.0])) == pytest.approx(
        math.dist((3.0, 1.0, 1.5), rp.memory.points()[1]))


def test_the_threat_looks_the_leg_up_only_when_hovering():
    """``_threat``'s leg direction may come as a callable: it is called only at rest (the
    direction of travel decides otherwise), and gives the same answer as the vector."""
    from companion.replan import GlobalPlan, Replanner
    from companion.trajectory import generate_trajectory
    from mavcore.mission.trajectory import TrajectoryConfig
    from mavcore.mission.schema import FlightConfig
    t = np.array([0.0, 10.0])
    p = np.array([[0.5, 1.0, 1.8], [5.5, 1.0, 1.8]])
    plan = GlobalPlan.from_waypoints(generate_trajectory(t, p), t, p, np.zeros((2, 3)), np.zeros((2, 3)),
                                     np.array([True, True]), None, None, FlightConfig(), TrajectoryConfig(), 1.0)
    rp = Replanner(ReplanConfig(), _known(), plan)
    rp.memory.add((3.5, 0.5, 1.5))
    calls = []

    def leg_u():
        calls.append(1)
        return np.array([1.0, 0.0])

    moving = rp._threat((3.0, 1.0, 1.5), (0.5, 0.0, 0.0), leg_u)
    assert calls == [] and moving == rp._threat((3.0, 1.0, 1.5), (0.5, 0.0, 0.0), np.array([1.0, 0.0]))
    # hovering: the leg decides what is behind, so it is looked up (once)
    assert rp._threat((3.0, 1.0, 1.5), (0.0, 0.0, 0.0), leg_u) == pytest.approx(math.dist((3.0, 1.0, 1.5),
                                                                                          (3.5, 0.5, 1.5)))
    assert calls == [1]
