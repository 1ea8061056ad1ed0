"""Geometric controller benchmarks: time per update, and closed-loop tracking with noise.

Usage::

    python benchmarks/bench_control.py              # timing + tracking table
    python benchmarks/bench_control.py --timing     # timing only

Timing: median wall time of ``GeometricController.update`` (one 250 Hz
sensor frame) over many calls along a moving reference.

Tracking: the controller against an in-process plant (eq. 20 + the rotor
allocation of ``mavcore/vehicle.py`` + first-order motors), 250 Hz sample
and hold, plant integrated by RK4 at 1 ms. Measurements: gyro, specific
force and magnetic field directions with white noise of the paper's
variance (5e-4 per component on the unit vectors and on Omega), exact
position and velocity (mocap-like, as the SITL's default). Reference:
a 1 m/s circle of radius 1.25 m (the turn between rows 2.5 m apart) and a
Lissajous sweep (20 m rows at up to 1 m/s). Reported: max and RMS position
error after 5 s settling, and the motor command range.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import statistics
import sys
import time

import numpy as np

from companion.control import GeometricController, Measurements, Reference
from mavcore.mission.control import ControlConfig
from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig, allocation_matrix


def circle(radius_m: float = 1.25, speed_m_s: float = 1.0, height_m: float = 1.5):
    w = speed_m_s / radius_m

    def ref(t):
        c, s = math.cos(w * t), math.sin(w * t)
        r = radius_m
        return Reference((r * c, r * s, height_m), (-r * w * s, r * w * c, 0.0),
                         (-r * w**2 * c, -r * w**2 * s, 0.0), (r * w**3 * s, -r * w**3 * c, 0.0),
                         (r * w**4 * c, r * w**4 * s, 0.0))
    return ref, (0.0, 0.0, 0.0)   # pointing at the centre, on the ground


def lissajous(half_length_m: float = 10.0, half_width_m: float = 2.5, height_m: float = 1.5):
    w = 1.0 / half_length_m          # peak speed 1 m/s along x

    def ref(t):
        A, B, w2 = half_length_m, half_width_m, 2.0 * w
        sx, cx, sy, cy = math.sin(w * t), math.cos(w * t), math.sin(w2 * t), math.cos(w2 * t)
        return Reference((A * sx, B * sy, height_m), (A * w * cx, B * w2 * cy, 0.0),
                         (-A * w**2 * sx, -B * w2**2 * sy, 0.0), (-A * w**3 * cx, -B * w2**3 * cy, 0.0),
                         (A * w**4 * sx, B * w2**4 * sy, 0.0))
    return ref, (0.0, 2.0 * half_width_m + 3.0, 0.0)   # beside the field


def _hat(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def simulate(cfg: ControlConfig, reference, duration_s: float, *, noise_var: float = 5e-4,
             gyro_var: float | None = None, seed: int = 0,
             vehicle: VehicleConfig | None = None, settle_s: float = 5.0, frame_hz: float = 250.0,
             substeps: int = 4, mag_enu=(0.0, 0.21, -0.42), yaw0_deg: float = 0.0):
    """Closed loop; returns a dict of figures. Starts on the reference, level, at rest."""
    veh = vehicle or VehicleConfig()
    ref_fn, target = reference
    ctl = GeometricController(veh, cfg, target)
    rng = np.random.default_rng(seed)
    sig = math.sqrt(noise_var)
    sig_g = sig if gyro_var is None else math.sqrt(gyro_var)
    m, J, g = veh.mass_kg, veh.J, GRAVITY_M_S2
    Jinv = np.linalg.inv(J)
    A = allocation_matrix(veh)
    tau_m = veh.motor_time_constant_s
    fmax = veh.max_thrust_per_rotor_n
    B = np.asarray(mag_enu, float)
    r0 = ref_fn(0.0)
    p = np.array(r0.pos_enu_m, float)
    v = np.array(r0.vel_enu_m_s, float)
    # Start on the desired attitude and angular velocity of t = 0.
    a0 = np.array(r0.acc_enu_m_s2) + [0.0, 0.0, g]
    out0 = GeometricController(veh, cfg, target).update(
        0.0, Measurements((0, 0, 0), (0, 0, np.linalg.norm(a0)), tuple(B), tuple(p), tuple(v)), r0)
    R = np.array(out0.R_d)
    W = np.array(out0.Omega_d)
    if yaw0_deg:   # start off in yaw, not rotating
        c, s_ = math.cos(math.radians(yaw0_deg)), math.sin(math.radians(yaw0_deg))
        R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]]) @ R
        W = np.zeros(3)
    thr = np.full(4, out0.f_n / 4)

    def deriv(p, v, R, W, thr):
        w = A @ thr
        a = w[0] / m * R[:, 2] - g * np.array([0, 0, 1.0])
        Wd = Jinv @ (w[1:] - np.cross(W, J @ W))
        return v, a, R @ _hat(W), Wd

    dt = 1.0 / frame_hz
    h = dt / substeps
    n = int(round(duration_s * frame_hz))
    errs, cmds, att, tilt, sat = [], [], [], [], []
    a_now = deriv(p, v, R, W, thr)[1]
    for k in range(n):
        t = k * dt
        sf_body = R.T @ (a_now + np.array([0, 0, g]))
        sfn = np.linalg.norm(sf_body)
        acc_meas = sfn * (sf_body / sfn + sig * rng.standard_normal(3))
        bm = R.T @ B
        mag_meas = np.linalg.norm(B) * (bm / np.linalg.norm(B) + sig * rng.standard_normal(3))
        gyro = W + sig_g * rng.standard_normal(3)
        ref = ref_fn(t)
        meas = Measurements(tuple(gyro), tuple(acc_meas), tuple(mag_meas), tuple(p), tuple(v))
        out = ctl.update(t, meas, ref)
        if t >= settle_s:
            errs.append(np.linalg.norm(p - np.array(ref.pos_enu_m)))
            Rd = np.array(out.R_d)
            att.append(math.acos(min(1.0, max(-1.0, 0.5 * (np.trace(Rd.T @ R) - 1.0)))))
            tilt.append(math.acos(min(1.0, float(Rd[:, 2] @ R[:, 2]))))
            sat.append(out.saturated)
        cmd = np.array(out.motor_cmd) * fmax
        cmds.append(out.motor_cmd)
        for _ in range(substeps):
            # RK4 on (p, v, R, W, thr); motors first order toward the command.
            def f(state):
                p_, v_, R_, W_, th_ = state
                dp, dv, dR, dW = deriv(p_, v_, R_, W_, th_)
                dth = (cmd - th_) / tau_m if tau_m > 0 else np.zeros(4)
                return dp, dv, dR, dW, dth
            s0 = (p, v, R, W, thr)
            k1 = f(s0)
            k2 = f(tuple(x + 0.5 * h * d for x, d in zip(s0, k1)))
            k3 = f(tuple(x + 0.5 * h * d for x, d in zip(s0, k2)))
            k4 = f(tuple(x + h * d for x, d in zip(s0, k3)))
            p, v, R, W, thr = (x + h / 6 * (d1 + 2 * d2 + 2 * d3 + d4)
                               for x, d1, d2, d3, d4 in zip(s0, k1, k2, k3, k4))
            if tau_m == 0:
                thr = cmd.copy()
            a_now = k4[1]
        u, _, vt = np.linalg.svd(R)
        R = u @ vt
        a_now = deriv(p, v, R, W, thr)[1]
    errs = np.array(errs)
    cmds = np.array(cmds)
    return {"max_mm": 1e3 * float(errs.max()), "rms_mm": 1e3 * math.sqrt(np.mean(errs**2)),
            "cmd_min": float(cmds.min()), "cmd_max": float(cmds.max()),
            "att_max_deg": math.degrees(max(att)), "tilt_max_deg": math.degrees(max(tilt)),
            "saturated_frac": float(np.mean(sat)), "errors_m": errs}


def bench_timing(n: int = 20000) -> float:
    veh = VehicleConfig()
    ref_fn, target = lissajous()
    ctl = GeometricController(veh, ControlConfig(), target)
    rng = np.random.default_rng(1)
    meas = [Measurements(tuple(0.01 * rng.standard_normal(3)), (0.1, -0.05, 9.8), (0.01, 0.2, -0.43),
                         tuple(ref_fn(0.004 * k).pos_enu_m), tuple(ref_fn(0.004 * k).vel_enu_m_s))
            for k in range(200)]
    refs = [ref_fn(0.004 * k) for k in range(200)]
    times = []
    for k in range(n):
        i = k % 200
        t0 = time.perf_counter()
        ctl.update(0.004 * k, meas[i], refs[i])
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e6


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--timing", action="store_true", help="timing only")
    ap.add_argument("--duration", type=float, default=25.0, help="simulated seconds per case")
    args = ap.parse_args(argv)
    print(f"GeometricController.update: median {bench_timing():.1f} us per call")
    if args.timing:
        return 0
    d = ControlConfig()
    raw = dataclasses.replace(d, accel_vector_gain_rad_s=0.0, mag_vector_gain_rad_s=0.0)
    paper = dataclasses.replace(raw, mag_perpendicular=False, attitude_law="paper")
    lee = dataclasses.replace(d, kx=16.0, kv=5.6, ki=0.0)   # Lee et al.'s PD (ki=60 is unstable with it)
    noint = dataclasses.replace(d, ki=0.0)
    cases = (("default", d), ("unfiltered vectors", raw), ("paper law, unfiltered, raw", paper),
             ("default, kx=16 kv=5.6 ki=0", lee), ("default, ki=0", noint))
    print(f"closed loop, {args.duration:.0f} s, noise variance 5e-4, error after 5 s:")
    for name, cfg in cases:
        for tname, tr in (("circle r=1.25 m, 1 m/s", circle()), ("lissajous 20 m, 1 m/s", lissajous())):
            r = simulate(cfg, tr, args.duration)
            print(f"{name:27s} {tname:24s} max {r['max_mm']:6.2f} mm  rms {r['rms_mm']:6.2f} mm  "
                  f"cmd [{r['cmd_min']:.2f}, {r['cmd_max']:.2f}]  yaw-saturated {100 * r['saturated_frac']:.0f}%  "
                  f"max attitude error {r['att_max_deg']:.2f} deg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
