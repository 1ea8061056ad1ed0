"""``--control rates``: the body-rate setpoint on the wire, the SITL's inner rate
loop and thrust normalisation, the flight stack's choice of setpoint, and a
short in-process flight (``companion.control.rates``, ``sitl.rate_control``)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.cli import main
from companion.control.rates import normalised_thrust, rate_command, vehicle_hover_thrust
from mavcore import codec
from mavcore.link.command_rules import attitude_target_problem, outgoing_problem
from companion.link.tlog_scan import TlogScanner
from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig
from mavcore import codec as sitl_codec
from sitl.flightstack import FlightMode, FlightStack, NavState, Parameters
from mavcore.codec import PositionTarget
from mavcore.codec import RateSetpoint
from sitl.rate_control import (RateLoop, RateLoopGains, hover_thrust, thrust_curve,
                               thrust_curve_inverse)

S = 1_000_000


def _wire(msg):
    """``msg`` packed by one MAVLink end and parsed by another (float32 on the wire)."""
    tx = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    rx = mavlink.MAVLink(None)
    return rx.parse_buffer(bytes(msg.pack(tx)))[0]


# --- the setpoint on the wire --------------------------------------------------------


def test_rates_packing_flu_to_frd_and_back_by_hand():
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    # FLU (p, q, r) = (0.25, 0.5, -0.75): roll right, pitch nose *down* (FLU +y), yaw clockwise
    msg = _wire(codec.encode_set_attitude_rates(mav, 1234, (0.25, 0.5, -0.75), 0.375))
    assert msg.get_type() == "SET_ATTITUDE_TARGET"
    assert msg.type_mask == mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE == 128
    # FRD: x unchanged, y and z negated (pitch up positive about right, yaw positive clockwise)
    assert (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate) == (0.25, -0.5, 0.75)
    assert msg.thrust == 0.375 and msg.time_boot_ms == 1234
    sp, why = sitl_codec.decode_attitude_rates(msg)
    assert why is None
    assert sp == RateSetpoint((0.25, 0.5, -0.75), 0.375)      # exact: the values are float32 numbers


def test_sitl_decodes_a_hand_written_frd_setpoint():
    mav = mavlink.MAVLink(None)
    msg = _wire(mav.set_attitude_target_encode(0, 1, 1, 128, (1, 0, 0, 0), -0.125, 0.0625, -2.0, 0.5))
    sp, why = sitl_codec.decode_attitude_rates(msg)
    assert why is None and sp.rates_flu_rad_s == (-0.125, -0.0625, 2.0) and sp.thrust == 0.5


@pytest.mark.parametrize("mask, rates, thrust, words", [
    (0, (0.0, 0.0, 0.0), 0.5, "attitude setpoints are not supported"),
    (128 | 4, (0.0, 0.0, 0.0), 0.5, "ignores a body rate or the thrust"),
    (128 | 64, (0.0, 0.0, 0.0), 0.5, "ignores a body rate or the thrust"),
    (128, (math.nan, 0.0, 0.0), 0.5, "body_roll_rate nan"),
    (128, (0.0, 0.0, 101.0), 0.5, "body_yaw_rate 101"),
    (128, (0.0, 0.0, 0.0), 1.01, "thrust 1.01 outside [0, 1]"),
    (128, (0.0, 0.0, 0.0), -0.01, "thrust -0.01 outside [0, 1]"),
    (128, (0.0, 0.0, 0.0), math.inf, "thrust inf"),
])
def test_unusable_rate_setpoints_are_refused_at_both_ends(mask, rates, thrust, words):
    assert words in attitude_target_problem(mask, rates, thrust)
    mav = mavlink.MAVLink(None)
    msg = mav.set_attitude_target_encode(0, 1, 1, mask, (1, 0, 0, 0), *rates, thrust)
    assert words in outgoing_problem(msg)                  # the companion will not send it
    assert sitl_codec.decode_attitude_rates(msg) == (None, attitude_target_problem(mask, rates, thrust))
    assert attitude_target_problem(128, (100.0, -100.0, 0.0), 1.0) is None    # the limits themselves pass


# --- the companion's command and thrust ----------------------------------------------


def test_rate_command_is_the_torque_laws_slow_manifold():
    # Omega_c = Omega_d + z / alpha: (0.1 + 12/12, -0.2 + 0, 0 - 6/12)
    assert rate_command((0.1, -0.2, 0.0), (12.0, 0.0, -6.0), 12.0) == pytest.approx((1.1, -0.2, -0.5))


def test_normalised_thrust_by_hand():
    v = VehicleConfig()          # 4.34 kg, 25 N per rotor
    hover = 4.34 * 9.81 / 100.0
    assert vehicle_hover_thrust(v) == pytest.approx(0.425754) == pytest.approx(hover)
    assert hover_thrust(v) == vehicle_hover_thrust(v)          # the SITL's MPC_THR_HOVER
    assert normalised_thrust(4.34 * GRAVITY_M_S2, 4.34, hover) == pytest.approx(hover)   # f = m g: hover
    assert normalised_thrust(0.5 * 4.34 * GRAVITY_M_S2, 4.34, 0.6) == pytest.approx(0.3)
    assert normalised_thrust(3.0 * 4.34 * GRAVITY_M_S2, 4.34, 0.6) == 1.0                # clipped
    assert normalised_thrust(-5.0, 4.34, 0.6) == 0.0
    assert normalised_thrust(math.nan, 4.34, 0.6) == 0.0


# --- the SITL's thrust curve and rate loop -------------------------------------------


@pytest.mark.parametrize("k, u, t", [
    (0.0, 0.3, 0.3),            # linear motors
    (0.5, 0.5, 0.375),          # 0.5 * 0.5 + 0.5 * 0.25
    (1.0, 0.5, 0.25),           # quadratic: u = sqrt(t)
    (0.3, 1.0, 1.0),            # full signal, full thrust, whatever k
    (0.65, 0.2, 0.096),         # ArduPilot's default expo: 0.35 * 0.2 + 0.65 * 0.04
])
def test_thrust_curve_and_its_inverse_against_hand_values(k, u, t):
    assert thrust_curve(u, k) == pytest.approx(t, abs=1e-12)
    assert thrust_curve_inverse(t, k) == pytest.approx(u, abs=1e-12)


def test_thrust_curve_round_trip_and_clipping():
    for k in (0.0, 1e-9, 0.25, 0.65, 1.0):
        for u in np.linspace(0.0, 1.0, 21):
            assert thrust_curve_inverse(thrust_curve(u, k), k) == pytest.approx(u, abs=1e-12)
    assert thrust_curve_inverse(1.5, 0.5) == 1.0 and thrust_curve_inverse(-0.5, 0.5) == 0.0


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_rate_loop_step_is_first_order_with_time_constant_one_over_kp(axis):
    """Without integral and with the torque applied at once, J W_dot = J kp (W_sp - W):
    W(t) = W_sp (1 - exp(-kp t)), 63.2 % at t = 1/kp, 95.0 % at 3/kp."""
    kp = RateLoopGains().kp
    J = VehicleConfig().inertia_kg_m2
    loop = RateLoop(J, RateLoopGains(kp=kp, ki=(0.0, 0.0, 0.0), yaw_torque_cutoff_hz=0.0))
    w_sp = [0.0, 0.0, 0.0]
    w_sp[axis] = 0.8
    w = [0.0, 0.0, 0.0]
    dt = 1e-5
    tau_s = 1.0 / kp[axis]
    t, seen = 0.0, {}
    while t < 3.0 * tau_s - 1e-12:
        tau = loop.update(w, w_sp, dt)
        w[axis] += dt * tau[axis] / J[axis]        # one axis turning: no gyroscopic term
        t += dt
        for n in (1, 3):
            if n not in seen and t >= n * tau_s - 1e-12:
                seen[n] = w[axis] / w_sp[axis]
    assert seen[1] == pytest.approx(1.0 - math.exp(-1.0), abs=2e-3)
    assert seen[3] == pytest.approx(1.0 - math.exp(-3.0), abs=2e-3)


def test_yaw_torque_low_pass_makes_the_yaw_step_second_order_and_quiets_the_gyro_noise():
    """PX4's MC_YAW_TQ_CUTOFF (2 Hz): with the yaw torque low-passed at w_c = 2 pi f_c the yaw
    rate obeys W'' + w_c W' + w_c kp W = w_c kp W_sp, by hand w_n = sqrt(w_c kp) = 10.03 rad/s,
    zeta = w_c / (2 w_n) = 0.627, overshoot exp(-pi zeta / sqrt(1 - zeta^2)) = 8.0 %; and white
    gyro noise of per-sample std sigma leaves kp sigma sqrt(k / (2 - k)) in the yaw acceleration
    (k = 1 - exp(-w_c dt), the variance of a first-order recursion on white noise)."""
    g = RateLoopGains(ki=(0.0, 0.0, 0.0))
    kp, fc = g.kp[2], g.yaw_torque_cutoff_hz
    assert fc == 2.0
    J = VehicleConfig().inertia_kg_m2
    loop = RateLoop(J, g)
    wc = 2.0 * math.pi * fc
    wn = math.sqrt(wc * kp)
    zeta = wc / (2.0 * wn)
    wd = wn * math.sqrt(1.0 - zeta * zeta)
    w, dt, t, peak = [0.0, 0.0, 0.0], 1e-5, 0.0, 0.0
    while t < 1.0:
        tau = loop.update(w, (0.0, 0.0, 1.0), dt)
        w[2] += dt * tau[2] / J[2]
        t += dt
        peak = max(peak, w[2])
        if abs(t - 0.2) < dt / 2:
            exact = 1.0 - math.exp(-zeta * wn * t) * (math.cos(wd * t) + zeta / math.sqrt(1 - zeta ** 2)
                                                       * math.sin(wd * t))
            assert w[2] == pytest.approx(exact, abs=2e-3)
    assert peak - 1.0 == pytest.approx(math.exp(-math.pi * zeta / math.sqrt(1.0 - zeta ** 2)), abs=2e-3)
    # noise: the paper's gyro variance 5e-4 per 250 Hz sample
    sigma, dt = math.sqrt(5e-4), 0.004
    loop.reset()
    rng = np.random.default_rng(17)
    acc = np.array([loop.update((0.0, 0.0, x), (0.0, 0.0, 0.0), dt)[2] / J[2]
                    for x in sigma * rng.standard_normal(100_000)])[1000:]
    k = 1.0 - math.exp(-wc * dt)
    assert acc.std() == pytest.approx(kp * sigma * math.sqrt(k / (2.0 - k)), rel=0.03)
    assert acc.std() < 0.15 * VehicleConfig().torque_coeff_m * 4.34 * 9.81 / J[2]   # of the yaw authority


def test_rate_loop_torque_includes_the_gyroscopic_term_and_the_integral():
    J = (0.1, 0.2, 0.3)
    loop = RateLoop(J, RateLoopGains(kp=(0.0, 0.0, 0.0), ki=(10.0, 10.0, 10.0), int_limit_rad_s2=1.0,
                                     yaw_torque_cutoff_hz=0.0))
    w = (1.0, 2.0, 0.0)
    # at the setpoint the torque is W x J W = (wy Jz wz - wz Jy wy, wz Jx wx - wx Jz wz, wx Jy wy - wy Jx wx)
    assert loop.update(w, w, 0.01) == pytest.approx((0.0, 0.0, 1.0 * 0.2 * 2.0 - 2.0 * 0.1 * 1.0))
    loop.reset()
    # error 1 rad/s on x for 0.05 s: integral 10 * 1 * 0.05 = 0.5 rad/s^2, then bounded at 1
    tau = loop.update((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.05)
    assert tau[0] == pytest.approx(0.1 * 0.5)
    tau = loop.update((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 1.0)
    assert tau[0] == pytest.approx(0.1 * 1.0)
    assert loop.update((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 1.0, landed=True)[0] == 0.0   # held at 0 on the ground


# --- the flight stack: which setpoint flies ---------------------------------------------


def _air():
    return NavState(np.array([0.0, 0.0, 2.0]), np.zeros(3), 0.0, 0.0, False)


def test_offboard_flies_the_newer_kind_of_setpoint_until_it_is_stale():
    stack = FlightStack(Parameters(), home_enu_m=(0.0, 0.0, 0.0))
    st = _air()
    nan3 = np.full(3, np.nan)
    stack.offboard_setpoint(0, PositionTarget(np.array([0.0, 0.0, 2.0]), nan3, nan3, None, None, 0xDF8))
    assert stack.set_mode(0, st, FlightMode.OFFBOARD).accepted
    stack.arm(0, st, force=True)
    assert stack.update(0, st).rates is None                    # position setpoints only
    rsp = RateSetpoint((0.1, 0.0, 0.0), 0.43)
    stack.rate_setpoint(10_000, rsp)
    assert stack.update(10_000, st).rates is rsp                # the newer kind wins
    stack.offboard_setpoint(20_000, PositionTarget(np.array([0.0, 0.0, 2.0]), nan3, nan3, None, None, 0xDF8))
    assert stack.update(20_000, st).rates is None               # a position setpoint took over again
    stack.rate_setpoint(30_000, rsp)
    loss = stack.params["COM_OF_LOSS_T"]
    assert stack.update(30_000 + int(loss * S), st).rates is rsp
    out = stack.update(30_000 + int(loss * S) + 1, st)          # stale: the offboard failsafe holds
    assert out.rates is None and stack.mode is FlightMode.LOITER and stack.failsafe == "offboard"


def test_rate_setpoints_outside_offboard_are_not_flown():
    stack = FlightStack(Parameters(), home_enu_m=(0.0, 0.0, 0.0))
    st = _air()
    stack.arm(0, st, force=True)
    stack.rate_setpoint(0, RateSetpoint((0.0, 0.0, 0.0), 0.5))
    assert stack.mode is FlightMode.LOITER and stack.update(0, st).rates is None


# --- a short flight ------------------------------------------------------------------------


def test_short_inprocess_flight_in_rates_mode(tmp_path):
    """take-off, hold and 4 s of the flat-rectangle trajectory through the rate loop:
    every frame's answer is a tick without motors, the rates precede it, the thrust of
    the hold is the hover thrust m g / (4 f_max) of the vehicle, and the tracking error
    stays within a few millimetres (the companion's own figure is about 0.3 mm)."""
    out = tmp_path / "rates"
    rc = main(["demo", "--mission", "flat-rectangle", "--control", "rates", "--cut", "4", "--seed", "3",
               "--transport", "inproc", "--out", str(out), "--no-plots", "--quiet"])
    rep = json.loads((out / "report.json").read_text())
    assert rc == 0 and rep["completed"] and rep["control"] == "rates" and rep["control_in_use"] == "rates"
    assert rep["tracking"]["max_error_m"] < 0.005
    sc = TlogScanner()
    recs = sc.feed((out / "flight.tlog").read_bytes()) + sc.close()
    parser = mavlink.MAVLink(None)
    n_rates = n_motor = 0
    thrust, last_tick = [], None
    for r in recs:
        if r.msgid not in (mavlink.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET, mavlink.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS):
            continue
        m = parser.decode(bytearray(r.packet))
        if r.msgid == mavlink.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET:
            n_rates += 1
            assert m.type_mask == 128 and 0.0 <= m.thrust <= 1.0
            assert last_tick is None or m.time_boot_ms >= last_tick // 1000   # this frame's, before its tick
            thrust.append(m.thrust)
        else:
            n_motor += not math.isnan(m.controls[0])
            last_tick = m.time_usec
    assert n_rates > 1500 and n_motor == 0
    hover = 4.34 * GRAVITY_M_S2 / (4 * 25.0)
    assert float(np.median(thrust)) == pytest.approx(hover, abs=0.01)
