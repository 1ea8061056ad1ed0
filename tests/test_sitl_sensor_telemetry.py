"""What the SITL's sensor telemetry carries on the wire (real UDP, lockstep):
the configured IMU noise in HIGHRES_IMU, the delivered GNSS sample in
LOCAL_POSITION_NED stamped with its measurement time, and the estimate (or,
in "true state" mode, the truth) in ATTITUDE."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink
from scipy.stats import chi2

from sitl.api import SitlThread

ROOT = Path(__file__).resolve().parents[1]
NAN = float("nan")
G = 9.81
M_E = np.array([0.0, 0.21, -0.42])          # the bundled missions' Earth field (ENU, gauss)
PROFILE = "icm42688p-bmm150-zedf9p"


def variant(tmp_path: Path, **sim) -> Path:
    """flat-rectangle with extra ``sim`` keys, written to tmp_path (maps by absolute path)."""
    src = ROOT / "missions" / "flat-rectangle"
    d = yaml.safe_load((src / "mission.yaml").read_text())
    d["map"], d["dem"] = str(src / d["map"]), str(src / d["dem"])
    d["sim"].update(sim)
    p = tmp_path / "mission.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def lockstep_frames(mission: Path, n_frames: int, lpos_every_frame: bool = False):
    """Answer n frames in lockstep (no motor override: the vehicle stays on the
    ground, disarmed); per frame the HIGHRES_IMU and the LOCAL_POSITION_NED /
    ATTITUDE sent in it (None if none)."""
    with SitlThread(mission, lockstep=True, speed=0.0) as s:
        conn = mavutil.mavlink_connection(s.url, source_system=1, source_component=191)
        conn.mav = mavlink.MAVLink(conn, srcSystem=1, srcComponent=191)
        conn.mav.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        if lpos_every_frame:
            conn.mav.command_long_send(1, 1, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                       mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 4000, 0, 0, 0, 0, 0)
        frames, seen = [], {}
        last_t = None
        while len(frames) < n_frames:
            m = conn.recv_match(blocking=True, timeout=5.0)
            assert m is not None, "the SITL stopped sending"
            t = m.get_type()
            if t in ("LOCAL_POSITION_NED", "ATTITUDE"):
                seen[t] = m
            elif t == "HIGHRES_IMU":
                if m.time_usec != last_t:           # the first frame is re-sent until answered
                    frames.append((m, seen.get("LOCAL_POSITION_NED"), seen.get("ATTITUDE")))
                    last_t = m.time_usec
                seen = {}
                conn.mav.hil_actuator_controls_send(m.time_usec, [NAN] * 16, 0, 1)
        conn.close()
    return frames


def var_ok(x: np.ndarray, sigma2: float, p: float = 1e-6) -> bool:
    """Sample variance of n normal samples within the two-sided chi-square bounds."""
    n = len(x)
    v = np.var(x, ddof=1) / sigma2 * (n - 1)
    return chi2.ppf(p / 2, n - 1) < v < chi2.ppf(1 - p / 2, n - 1)


@pytest.fixture(scope="module")
def profile_frames(tmp_path_factory):
    # the profile, with one key overridden under sim.noise (it must reach the wire)
    path = variant(tmp_path_factory.mktemp("profile"), sensor_profile=PROFILE,
                   noise={"gyro_variance": 1.0e-4, "gyro_bias_walk_rad_s_rts": 0.0,
                          "accel_bias_walk_m_s2_rts": 0.0})
    return lockstep_frames(path, 800, lpos_every_frame=True)


def test_highres_imu_carries_the_configured_noise(profile_frames):
    """At rest on the ground the truth is exactly known (gyro 0, specific force
    +g up, the Earth field at heading 0), so each HIGHRES_IMU field minus its
    true value is the noise: its sample variance must match the configured
    per-sample variance (chi-square, p = 1e-6), and differ from zero."""
    imu = [f[0] for f in profile_frames[50:]]
    gyro = np.array([(m.xgyro, m.ygyro, m.zgyro) for m in imu])
    acc = np.array([(m.xacc, m.yacc, m.zacc) for m in imu])
    mag = np.array([(m.xmag, m.ymag, m.zmag) for m in imu])
    rate = 250.0
    gyro_var = 1.0e-4 + (2.8e-3 * math.pi / 180.0) ** 2 * rate      # override + ICM-42688-P density
    acc_var = (70e-6 * 9.80665) ** 2 * rate
    mag_var = 0.006 ** 2                                            # BMM150, gauss
    for x, v in ((gyro, gyro_var), (acc, acc_var), (mag, mag_var)):
        for i in range(3):
            assert var_ok(x[:, i], v), (i, np.var(x[:, i]), v)
    # the noise is on the wire: no component equals the truth (FRD: gyro 0, accel (0, 0, -g))
    assert np.count_nonzero(gyro == 0.0) == 0
    assert np.mean(acc[:, 2]) == pytest.approx(-G, abs=0.15)          # + a turn-on bias of a few mg
    # magnetometer: Earth field + hard iron of the profile (motors off), FLU -> FRD
    hard = np.array([0.008, -0.006, 0.012])
    expect_flu = M_E + hard
    assert np.mean(mag, axis=0) == pytest.approx(expect_flu * [1, -1, -1], abs=5 * 0.006 / math.sqrt(len(mag)))


def test_local_position_ned_is_the_delivered_gnss_sample_stamped_with_its_measurement_time(profile_frames):
    """10 Hz, 80 ms latency (the profile): in the frame at time t the message
    carries the sample measured at floor((t - 80 ms) / 100 ms) * 100 ms (the
    primed sample of time 0 before the first delivery), repeated with the same
    time_boot_ms until the next delivery."""
    t_ms = np.array([f[0].time_usec // 1000 for f in profile_frames])
    stamp = np.array([f[1].time_boot_ms for f in profile_frames])
    expect = np.where(t_ms >= 180, (t_ms - 80) // 100 * 100, 0)
    assert np.array_equal(stamp, expect)
    # one new sample per 100 ms, values held in between, noisy between samples
    pos = {}
    for f in profile_frames:
        pos.setdefault(f[1].time_boot_ms, set()).add((f[1].x, f[1].y, f[1].z))
    assert all(len(v) == 1 for v in pos.values())                     # held: identical repeats
    xs = np.array([next(iter(v)) for v in pos.values()])
    assert len(xs) == len(np.unique(expect)) and np.unique(xs[:, 0]).size == len(xs)   # noise drawn per sample


def test_attitude_is_the_estimate_and_the_truth_in_true_state_mode(profile_frames, tmp_path):
    att = [f[2] for f in profile_frames if f[2] is not None]
    assert att and all(abs(a.roll) < 0.05 and abs(a.pitch) < 0.05 for a in att)   # level within the estimate's error
    assert any(a.roll != 0.0 for a in att)                                           # ... but not the exact truth
    truth = lockstep_frames(variant(tmp_path, sensor_profile=PROFILE, onboard_state="truth"), 60)
    att = [f[2] for f in truth if f[2] is not None]
    # landed level, facing east (ENU yaw 0 = NED yaw pi/2), exactly
    assert att and all((a.roll, a.pitch, a.yaw) == (0.0, 0.0, np.float32(math.pi / 2)) for a in att)
