"""VehicleFilter's rules at their edges (issue 19: a safety test must fail when its rule is broken).

Messages are small stand-ins with the pymavlink accessors ``accept`` uses; the
time of each is set in its own field and unit (``TIMED_FIELDS``), so a wrong
scale or a wrong tolerance shows. Documented defaults: 1 s tolerance, 25
agreeing frames re-anchor the clock.
"""

from __future__ import annotations

import math

import pytest

from companion.link.auth import TIMED_FIELDS, LinkStats, VehicleFilter
from mavcore.link.signing import SignatureVerifier

VEH, SPOOF = ("127.0.0.1", 40001), ("127.0.0.1", 40002)


class Msg:
    def __init__(self, mtype: str, sysid: int = 1, compid: int = 1, **fields) -> None:
        self._t, self._s, self._c = mtype, sysid, compid
        self.__dict__.update(fields)

    def get_type(self):
        return self._t

    def get_srcSystem(self):
        return self._s

    def get_srcComponent(self):
        return self._c

    def get_msgbuf(self):
        return b"\xfd" + bytes(20)


HB = Msg("HEARTBEAT")


def imu(t_s: float) -> Msg:
    return Msg("HIGHRES_IMU", time_usec=round(t_s * 1e6))


def timed(mtype: str, t_s: float) -> Msg:
    """A message of ``mtype`` at vehicle time ``t_s``, in its own field and unit (MAVLink spec)."""
    field, unit = {"HIGHRES_IMU": ("time_usec", 1e6), "RAW_IMU": ("time_usec", 1e6), "ODOMETRY": ("time_usec", 1e6),
                   "LOCAL_POSITION_NED": ("time_boot_ms", 1e3), "ATTITUDE": ("time_boot_ms", 1e3),
                   "ATTITUDE_QUATERNION": ("time_boot_ms", 1e3),
                   "DISTANCE_SENSOR": ("time_boot_ms", 1e3)}[mtype]
    return Msg(mtype, **{field: round(t_s * unit)})


def bound(**kw) -> VehicleFilter:
    f = VehicleFilter(**kw)
    assert f.accept(HB, VEH)
    return f


def test_timed_fields_are_the_mavlink_time_fields():
    assert TIMED_FIELDS == {"HIGHRES_IMU": ("time_usec", 1e-6), "RAW_IMU": ("time_usec", 1e-6),
                            "ODOMETRY": ("time_usec", 1e-6),
                            "LOCAL_POSITION_NED": ("time_boot_ms", 1e-3), "ATTITUDE": ("time_boot_ms", 1e-3),
                            "ATTITUDE_QUATERNION": ("time_boot_ms", 1e-3),
                            "DISTANCE_SENSOR": ("time_boot_ms", 1e-3)}


@pytest.mark.parametrize("mtype", sorted(TIMED_FIELDS))
@pytest.mark.parametrize("offset_s,ok", [(0.9, True), (-0.9, True), (1.1, False), (-1.1, False)])
def test_each_timed_message_within_one_second_of_the_clock(mtype, offset_s, ok):
    """Default tolerance 1 s: 0.9 s away passes, 1.1 s away is a time jump (either side)."""
    f = bound()
    assert f.accept(imu(100.0), VEH)
    assert f.clock_s == pytest.approx(100.0)
    assert f.accept(timed(mtype, 100.0 + offset_s), VEH) is ok
    assert f.stats().time_jump == (0 if ok else 1)


def test_the_tolerance_is_inclusive_and_configurable():
    f = bound(max_time_jump_s=0.25)
    f.accept(imu(10.0), VEH)
    assert f.accept(timed("ATTITUDE", 10.25), VEH)          # exactly the tolerance
    assert not f.accept(timed("ATTITUDE", 10.251), VEH)
    assert f.accept(imu(10.25), VEH)                        # the IMU too
    assert f.clock_s == pytest.approx(10.25)
    assert not f.accept(imu(10.501), VEH)


def test_timed_messages_before_the_first_imu_pass_and_untimed_ones_always():
    f = bound()
    assert f.clock_s is None
    assert f.accept(timed("LOCAL_POSITION_NED", 5000.0), VEH)
    assert f.clock_s is None                                # only HIGHRES_IMU sets the clock
    f.accept(imu(1.0), VEH)
    assert f.accept(Msg("SYS_STATUS"), VEH)
    assert f.accept(HB, VEH)


def test_an_older_imu_frame_within_tolerance_passes_without_moving_the_clock_back():
    f = bound()
    f.accept(imu(10.0), VEH)
    assert f.accept(imu(9.5), VEH)
    assert f.clock_s == pytest.approx(10.0)
    assert f.accept(imu(10.004), VEH) and f.clock_s == pytest.approx(10.004)


@pytest.mark.parametrize("n", [2, 3, 25])
def test_exactly_resync_frames_agreeing_jumped_frames_re_anchor(n):
    f = bound(resync_frames=n)
    f.accept(imu(1.0), VEH)
    got = [f.accept(imu(50.0 + 0.004 * k), VEH) for k in range(n + 2)]
    assert got == [False] * (n - 1) + [True] * 3
    assert f.stats().clock_resyncs == 1 and f.stats().time_jump == n - 1


def test_the_default_re_anchoring_needs_25_frames():
    f = bound()
    f.accept(imu(1.0), VEH)
    got = [f.accept(imu(50.0 + 0.004 * k), VEH) for k in range(26)]
    assert got.index(True) == 24


@pytest.mark.parametrize("step_s,agree", [(0.5, True), (1.0, True), (1.001, False), (0.0, False), (-0.004, False)])
def test_jumped_frames_agree_when_each_is_later_and_within_tolerance_of_the_previous(step_s, agree):
    """Candidate run: cand < t <= cand + tolerance (1 s). Frames that repeat a time, go back,
    or step more than the tolerance start the run again."""
    f = bound(resync_frames=3)
    f.accept(imu(1.0), VEH)
    got = [f.accept(imu(100.0 + step_s * k), VEH) for k in range(3)]
    assert got[-1] is agree


def test_an_accepted_frame_clears_a_candidate_run():
    f = bound(resync_frames=3)
    f.accept(imu(1.0), VEH)
    assert not f.accept(imu(50.0), VEH)
    assert not f.accept(imu(50.004), VEH)
    assert f.accept(imu(1.004), VEH)                        # the real stream: the run starts over
    assert not f.accept(imu(50.008), VEH)
    assert not f.accept(imu(50.012), VEH)
    assert f.accept(imu(50.016), VEH)                       # third of the new run
    assert f.clock_s == pytest.approx(50.016)


def test_the_resync_reset_lets_the_following_frames_through():
    f = bound(resync_frames=2)
    f.accept(imu(1.0), VEH)
    assert [f.accept(imu(t), VEH) for t in (30.0, 30.004, 30.008, 70.0, 70.004)] == \
        [False, True, True, False, True]
    assert f.stats().clock_resyncs == 2


@pytest.mark.parametrize("kw", [{"max_time_jump_s": 0.0}, {"max_time_jump_s": -1.0},
                                {"max_time_jump_s": math.nan}, {"resync_frames": 1}, {"resync_frames": 0}])
def test_bad_settings_are_refused(kw):
    with pytest.raises(ValueError):
        VehicleFilter(**kw)


def test_smallest_settings_are_allowed():
    f = VehicleFilter(max_time_jump_s=1e-6, resync_frames=2)
    assert f.max_time_jump_s == 1e-6 and f.resync_frames == 2


@pytest.mark.parametrize("sysid,compid", [(2, 1), (1, 2), (255, 190)])
def test_either_id_wrong_is_foreign(sysid, compid):
    f = VehicleFilter()
    assert not f.accept(Msg("HEARTBEAT", sysid, compid), VEH)
    assert f.stats().foreign_id == 1 and f.vehicle_addr is None
    assert f.accept(HB, VEH)


def test_other_vehicle_ids():
    f = VehicleFilter(sysid=7, compid=3)
    assert not f.accept(HB, VEH)
    assert f.accept(Msg("HEARTBEAT", 7, 3), VEH)


def test_the_binding_never_moves():
    f = bound()
    assert not f.accept(HB, SPOOF)
    assert f.accept(HB, VEH) and f.vehicle_addr == VEH
    assert f.stats().foreign_address == 1


def test_filter_keeps_the_accepted_messages_in_order():
    f = VehicleFilter()
    assert f.filter([], VEH) == [] and f.filter(None, VEH) == []
    a, b = Msg("SYS_STATUS"), Msg("SYS_STATUS", 9, 9)
    assert f.filter([a, HB, b, a], VEH) == [HB, a]
    s = f.stats()
    assert (s.received, s.accepted, s.before_heartbeat, s.foreign_id) == (4, 2, 1, 1)


def test_stats_name_the_address_of_each_link_kind():
    f = VehicleFilter()
    assert f.stats().vehicle_address is None
    f.accept(HB, "/dev/ttyACM0")                  # a stream link's "address"
    assert f.stats().vehicle_address == "/dev/ttyACM0"
    f = VehicleFilter()
    f.accept(HB, ("::1", 14550, 0, 0))            # an IPv6 address tuple
    assert f.stats().vehicle_address == "('::1', 14550, 0, 0)"


def test_link_stats_dropped_and_dict():
    s = LinkStats(received=10, accepted=7, time_jump=3)
    assert s.dropped == 3
    d = s.to_dict()
    assert d["dropped"] == 3 and d["received"] == 10 and d["vehicle_address"] is None


class _Verdict:
    def __init__(self, verdict):
        self.verdict, self.ok = verdict, verdict == "ok"


class _Verifier(SignatureVerifier):
    def __init__(self, verdicts):                       # noqa: D107 - a scripted verifier
        self._v = list(verdicts)

    def check(self, packet):
        return _Verdict(self._v.pop(0))


def test_signature_verdicts_are_counted_by_kind():
    f = VehicleFilter(verifier=_Verifier(["unsigned", "bad_signature", "malformed", "replay", "stale",
                                          "odd", "ok"]))
    assert [f.accept(HB, VEH) for _ in range(7)] == [False] * 6 + [True]
    s = f.stats()
    assert (s.unsigned, s.bad_signature, s.replayed, s.accepted) == (1, 3, 2, 1)


def test_empty_link_stats_count_nothing():
    """A report written before any message (or with no link) shows zero counts, not made-up ones."""
    d = LinkStats().to_dict()
    assert d.pop("vehicle_address") is None
    assert set(d.values()) == {0} and len(d) == 12


def test_stats_without_a_count_of_bad_packets_say_zero():
    assert VehicleFilter().stats().bad_packets == 0
