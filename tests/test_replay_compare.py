"""Output comparison field by field, and the codec pieces replay adds (both ways)."""

from __future__ import annotations

import math
import struct
from types import SimpleNamespace

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from mavcore import frames
from companion.flight.core import ActuatorOut
from mavcore import codec
from companion.link.tlog_scan import RawRecord
from companion.replay.compare import (
    DRIFT_REL,
    DRIFT_REL_TRAJECTORY,
    OutputComparer,
    computed_payload,
    drift_allowance,
    field_values,
    ulp32,
)

MAV = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)


def record_of(msg) -> RawRecord:
    pkt = bytes(msg.pack(MAV))
    return RawRecord(0, 0, msg.get_msgId(), 1, 191, pkt)


def f32_next(x: float) -> float:
    """The next float32 above ``x``."""
    (i,) = struct.unpack("<i", struct.pack("<f", x))
    return struct.unpack("<f", struct.pack("<i", i + 1))[0]


def test_actuator_payload_is_pymavlinks():
    for cmd, armed in (((0.1, 0.2, 0.3, 0.4), True), (None, False), ((0.0, 0.0, 0.0, 0.0), True)):
        msg = codec.encode_hil_actuator_controls(MAV, 123456, cmd, armed)
        pkt = msg.pack(MAV)
        mid, payload = computed_payload(ActuatorOut(123456, cmd, armed), MAV)
        assert mid == 93 and payload == bytes(pkt[10:10 + pkt[1]])


def test_field_values_match_pymavlinks_decoding():
    msgs = [MAV.hil_actuator_controls_encode(5, [0.5, -0.25] + [0.0] * 14, 129, 1),
            MAV.statustext_encode(4, b"companion: hello", 0x4353, 3),
            MAV.set_position_target_local_ned_encode(7, 1, 1, 1, 0, 1.5, -2.5, 3.0, 0, 0, 0, 0, 0, 0, 0.25, 0)]
    for m in msgs:
        pkt = m.pack(MAV)
        got = dict(field_values(m.get_msgId(), bytes(pkt[10:10 + pkt[1]])))
        ref = mavlink.MAVLink(None).decode(bytearray(pkt))
        for name in ref.get_fieldnames():
            v = getattr(ref, name)
            if isinstance(v, list):
                assert [got[f"{name}[{k}]"] for k in range(len(v))] == v
            else:
                assert got[name] == v


def test_comparer_bit_for_bit_and_tolerance():
    rec = record_of(MAV.set_position_target_local_ned_encode(7, 1, 1, 1, 0, 1.5, -2.5, 3.0, 0, 0, 0, 0, 0, 0, 0, 0))
    same = MAV.set_position_target_local_ned_encode(7, 1, 1, 1, 0, 1.5, -2.5, 3.0, 0, 0, 0, 0, 0, 0, 0, 0)
    c = OutputComparer()
    assert c.compare(same, rec) is None and c.n_bitwise == 1
    # one float32 step in y: caught, named, with both values
    nudged = MAV.set_position_target_local_ned_encode(7, 1, 1, 1, 0, 1.5, f32_next(-2.5), 3.0, 0, 0, 0, 0, 0, 0,
                                                       0, 0)
    d = c.compare(nudged, rec)
    assert d.field == "y" and d.recorded_value == -2.5 and d.computed_value == f32_next(-2.5)
    # -0.0 is not 0.0 bit for bit
    neg = MAV.set_position_target_local_ned_encode(7, 1, 1, 1, 0, 1.5, -2.5, 3.0, 0, 0, 0, 0, 0, 0, -0.0, 0)
    assert c.compare(neg, rec).field == "yaw"
    # within a tolerance: accepted and measured
    t = OutputComparer(tolerance=1e-3)
    off = MAV.set_position_target_local_ned_encode(7, 1, 1, 1, 0, 1.5, -2.5005, 3.0, 0, 0, 0, 0, 0, 0, 0, 0)
    assert t.compare(off, rec) is None and t.n_within == 1
    assert t.max_abs_diff["SET_POSITION_TARGET_LOCAL_NED.y"] == pytest.approx(5e-4, rel=1e-3)
    far = MAV.set_position_target_local_ned_encode(7, 1, 1, 1, 0, 1.5, -2.6, 3.0, 0, 0, 0, 0, 0, 0, 0, 0)
    assert t.compare(far, rec).field == "y"
    # integers are never within a tolerance
    late = MAV.set_position_target_local_ned_encode(8, 1, 1, 1, 0, 1.5, -2.5, 3.0, 0, 0, 0, 0, 0, 0, 0, 0)
    assert t.compare(late, rec).field == "time_boot_ms"


def test_ulp32_is_the_float32_step():
    # hand-worked: float32 has 24 significant bits, so the step in [2^k, 2^(k+1)) is 2^(k-23)
    assert ulp32(0.75) == 2.0 ** -24 == f32_next(0.75) - 0.75
    assert ulp32(1.0) == 2.0 ** -23 == f32_next(1.0) - 1.0
    assert ulp32(-3.0) == 2.0 ** -22
    assert ulp32(0.0) == 2.0 ** -149 and ulp32(1e-45) == 2.0 ** -149      # subnormals
    # the allowance of one drifting value: that step plus DRIFT_REL of the scale (at least 1)
    assert drift_allowance(0.75, 0.75) == 2.0 ** -24 + DRIFT_REL
    assert drift_allowance(0.0, 7.1e-17) == ulp32(7.1e-17) + DRIFT_REL


def test_drift_mode_allows_one_rounding_step_of_continuous_outputs_only():
    rec = record_of(codec.encode_hil_actuator_controls(MAV, 10, (0.75, 0.0, 0.5, 0.5), True))
    c = OutputComparer(drift=True)
    assert c.mode == "drift" and OutputComparer().mode == "bitwise" and OutputComparer(1e-3, True).mode == "absolute"
    # one float32 step up, and 7.1e-17 for an exact 0 (a cancellation's last bit): within drift
    assert c.compare(ActuatorOut(10, (f32_next(0.75), 7.1e-17, 0.5, 0.5), True), rec) is None
    assert c.n_within == 1
    # two steps: more than one rounding can make; caught and named
    d = c.compare(ActuatorOut(10, (f32_next(f32_next(0.75)), 0.0, 0.5, 0.5), True), rec)
    assert d.field == "controls[0]"
    # the mode (an integer field) stays exact
    assert c.compare(ActuatorOut(10, (0.75, 0.0, 0.5, 0.5), False), rec).field == "mode"
    # a command's float parameter is a decision, not a drifting value: exact
    cmd = MAV.command_long_encode(1, 1, 176, 0, 1.0, 6.0, 0, 0, 0, 0, 0)
    d = c.compare(MAV.command_long_encode(1, 1, 176, 0, 1.0, f32_next(6.0), 0, 0, 0, 0, 0), record_of(cmd))
    assert d.field == "param2"
    # a setpoint value drifts like a command
    sp = MAV.set_position_target_local_ned_encode(7, 1, 1, 1, 0, 1.5, -2.5, 3.0, 0, 0, 0, 0, 0, 0, 0, 0)
    assert c.compare(MAV.set_position_target_local_ned_encode(7, 1, 1, 1, 0, 1.5, f32_next(-2.5), 3.0, 0, 0, 0,
                                                               0, 0, 0, 0, 0), record_of(sp)) is None
    # ... with the trajectory's allowance (one setpoint compared, the flip at 2.5)
    mean, bound = c.drift_summary()["SET_POSITION_TARGET_LOCAL_NED.y"]
    assert mean == ulp32(2.5) and bound == pytest.approx(DRIFT_REL_TRAJECTORY * 2.5 + ulp32(2.5), rel=1e-6)


def test_drift_mode_sums_the_flips_per_field():
    """A float64 deviation e below a float32 step flips a fraction e/step of the roundings,
    so the flips' sum estimates e: over n outputs it may reach DRIFT_REL n + one step."""
    step = 2.0 ** -24                      # at 0.75
    rec = record_of(codec.encode_hil_actuator_controls(MAV, 10, (0.75, 0.5, 0.5, 0.5), True))
    flip = ActuatorOut(10, (f32_next(0.75), 0.5, 0.5, 0.5), True)
    same = ActuatorOut(10, (0.75, 0.5, 0.5, 0.5), True)
    n = 4096
    k_max = int((DRIFT_REL * n + step) / step)      # flips the bound allows: 2^12 2^-40 / 2^-24 + 1 = 1.06
    assert DRIFT_REL == 2.0 ** -40 and k_max == 1
    for k, over in ((k_max, False), (k_max + 1, True)):
        c = OutputComparer(drift=True)
        for i in range(n):
            assert c.compare(flip if i < k else same, rec) is None
        ex = c.drift_excess()
        assert bool(ex) is over
        mean, bound = c.drift_summary()["HIL_ACTUATOR_CONTROLS.controls[0]"]
        assert mean == pytest.approx(k * step / n) and bound == pytest.approx(DRIFT_REL + step / n, rel=1e-12)
        if over:
            assert ex[0]["field"] == "HIL_ACTUATOR_CONTROLS.controls[0]" and ex[0]["n_differing"] == k
    # bit for bit: no drift accounting at all
    assert OutputComparer().drift_excess() == []


def test_comparer_nan_and_types():
    rec = record_of(codec.encode_hil_actuator_controls(MAV, 10, None, True))
    c = OutputComparer()
    assert c.compare(ActuatorOut(10, None, True), rec) is None            # NaN ticks are equal
    d = c.compare(ActuatorOut(10, (0.5, 0.5, 0.5, 0.5), True), rec)
    assert d.field == "controls[0]" and math.isnan(d.recorded_value) and d.computed_value == 0.5
    d = c.compare(MAV.heartbeat_encode(18, 8, 0, 0, 4), rec)
    assert d.field is None and (d.recorded_value, d.computed_value) == ("HIL_ACTUATOR_CONTROLS", "HEARTBEAT")
    # a STATUSTEXT's ``id`` field is not its message id
    st = MAV.statustext_encode(7, b"cs:x", 0x4353, 0)
    assert c.compare(st, record_of(st)) is None


def test_global_position_round_trip_with_the_sitls_encoder():
    from mavcore import codec as sitl_codec

    origin = sitl_codec.GeoOrigin(44.8, -0.6, 30.0)
    home = (0.0, 0.0, 0.0)
    for p, v in (((12.3456, -7.891, 2.5), (1.0, -0.5, 0.25)), ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))):
        msg = sitl_codec.global_position_int(MAV, 1234, origin, home, p, v, 0.3)
        g = codec.decode_global_position_int(msg)
        e, n, u = frames.geodetic2enu(g.lat_deg, g.lon_deg, g.alt_m, origin.lat_deg, origin.lon_deg, origin.alt_m)
        assert abs(n - p[1]) <= 0.0056 and abs(e - p[0]) <= 0.0056 and abs(u - p[2]) <= 0.0005
        assert g.relative_alt_m == pytest.approx(p[2], abs=5e-4)
        assert g.vel_enu_m_s == pytest.approx(v, abs=0.005)
        assert g.time_boot_ms == 1234


def test_home_position_round_trip_with_the_sitls_encoder():
    from mavcore import codec as sitl_codec

    origin = sitl_codec.GeoOrigin(44.8, -0.6, 30.0)
    home_enu = (3.0, -4.0, 0.5)
    h = codec.decode_home_position(sitl_codec.home_position(MAV, origin, home_enu, 0))
    assert h.pos_enu_m == pytest.approx(home_enu, abs=1e-6)
    # its geodetic pose is the local point's, to the resolution of HOME_POSITION's
    # fields: half of 1e-7 deg in latitude and longitude, half a millimetre in altitude
    lat, lon, alt = frames.enu2geodetic(*home_enu, origin.lat_deg, origin.lon_deg, origin.alt_m)
    assert (h.lat_deg, h.lon_deg) == pytest.approx((lat, lon), abs=0.5e-7 + 1e-12)
    assert h.alt_m == pytest.approx(alt, abs=0.5e-3 + 1e-12)


def test_figures_take_any_plan_or_none():
    from companion.flight_plot import _plan_points

    wp = np.zeros((3, 3))
    assert _plan_points(None) == (None, None)
    a = _plan_points(SimpleNamespace(waypoints=SimpleNamespace(p_enu_m=wp), target_enu_m=(1, 2, 3)))
    b = _plan_points(SimpleNamespace(waypoints_p_enu_m=wp, target_enu_m=(1, 2, 3)))
    assert a[0] is wp and b[0] is wp and a[1] == b[1] == (1, 2, 3)
