"""The unrolled 250 Hz paths equal the readable reference implementations bit for bit.

``GeometricController.update`` (a wrapper of ``update_fast``) against
``update_reference`` (the composition of the module's pure functions), and
``Mixer.mix_fast`` against ``Mixer.mix``, on random inputs that visit the
rare branches: free fall, pointing target at the vehicle, pointing along the
thrust, both attitude laws, filters on and off, and every mixer saturation
step.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from companion.control import ControlConfig, GeometricController, Measurements, Mixer, Reference
from companion.vehicle import GRAVITY_M_S2, VehicleConfig

CONFIGS = {
    "default": ControlConfig(),                                  # the observer
    "paper": ControlConfig(attitude_law="paper", mag_perpendicular=False, accel_vector_gain_rad_s=0.0,
                           mag_vector_gain_rad_s=0.0, pointing_limit=False, ki=0.0, vectors="paper",
                           velocity_aided=False, observer=False),
    "paper-vectors-aided": ControlConfig(vectors="paper", observer=False),
    "accel-as-gravity": ControlConfig(velocity_aided=False, observer=False),
    "no-observer": ControlConfig(observer=False),                # tilt from the differentiated velocity
    "observer-paper-law": ControlConfig(attitude_law="paper"),
    "observer-paper-vectors": ControlConfig(vectors="paper"),
    "observer-gravity-only": ControlConfig(vectors="paper", velocity_aided=False, nav_adaptive_noise=False),
    "lowpass": ControlConfig(accel_filter_tau_s=0.02, kx=16, kv=5.6, ki=10, observer=False),   # int gains
    "no-integral": ControlConfig(ki=0.0),
    # integral on and off its bound and in and out of its zone (position noise 10 mm)
    "integral-clamped": ControlConfig(ki=300.0, integral_limit_fraction=0.002, integral_zone_m=0.015,
                                      observer=False),
}


def _same(a, b) -> bool:
    """Exact equality of nested numbers/tuples, NaN equal to NaN (numpy inputs may
    leave np.float64 where the other path has float: the same double)."""
    if isinstance(a, tuple):
        return isinstance(b, tuple) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    a, b = float(a), float(b)
    return a == b or (math.isnan(a) and math.isnan(b))


def _frames(rng, n=400):
    """Noisy frames along a wandering reference, with some degenerate ones."""
    t = 0.0
    for k in range(n):
        t += 0.004 if k % 97 else 0.0                     # a repeated time stamp now and then
        w1, w2 = 0.6, 0.4                                 # a smooth Lissajous reference
        c1, s1, c2, s2 = math.cos(w1 * t), math.sin(w1 * t), math.cos(w2 * t), math.sin(w2 * t)
        xd = (2.0 * s1, 3.0 * c2, 1.5)
        vd = (2.0 * w1 * c1, -3.0 * w2 * s2, 0.0)
        ad = (-2.0 * w1 ** 2 * s1, -3.0 * w2 ** 2 * c2, 0.0)
        jd = (-2.0 * w1 ** 3 * c1, 3.0 * w2 ** 3 * s2, 0.0)
        sd = (2.0 * w1 ** 4 * s1, 3.0 * w2 ** 4 * c2, 0.0)
        target = None
        if k % 50 == 7:
            target = xd                                   # pointing undefined: at the target
        elif k % 50 == 21:
            target = (xd[0], xd[1], xd[2] + 5.0)          # pointing along the thrust
        elif k % 50 == 33:
            ad = (0.0, 0.0, -GRAVITY_M_S2)                # free fall demanded
            vd = jd = sd = (0.0, 0.0, 0.0)
        pos = tuple(np.asarray(xd) + rng.normal(0.0, 0.01, 3))
        vel = tuple(np.asarray(vd) + rng.normal(0.0, 1e-4, 3))
        if k % 50 == 33:
            pos, vel = xd, vd
        gyro = tuple(rng.normal(0.0, 0.3, 3))
        acc = tuple(np.array([0.0, 0.0, 9.8]) + rng.normal(0.0, 0.2, 3))
        mag = tuple(np.array([0.05, 0.2, -0.43]) + rng.normal(0.0, 0.05, 3))
        yield t, Measurements(gyro, acc, mag, pos, vel, None if k % 3 else t - 0.002), \
            Reference(xd, vd, ad, jd, sd, target)


@pytest.mark.parametrize("name", sorted(CONFIGS))
@pytest.mark.parametrize("target", [(11.5, 5.0, 1.5), (0.2, 2.7, 1.0)])   # far; close: yaw-limited pointing
def test_update_equals_reference_bit_for_bit(name, target):
    veh, cfg = VehicleConfig(), CONFIGS[name]
    fast = GeometricController(veh, cfg, target)
    ref = GeometricController(veh, cfg, target)
    n_sat = 0
    for t, meas, r in _frames(np.random.default_rng(3)):
        a = fast.update(t, meas, r)
        b = ref.update_reference(t, meas, r)
        for f in dataclasses.fields(a):
            assert _same(getattr(a, f.name), getattr(b, f.name)), (t, f.name)
        n_sat += a.saturated
        # the fast path's log row is R_d's columns and f
        assert fast.last_desired == tuple(b.R_d[i][j] for j in range(3) for i in range(3)) + (b.f_n,)
    assert n_sat > 0                                      # the saturated mixer paths were visited
    if fast.observer is not None:                         # the observer ran the same in both
        assert fast.observer.R == ref.observer.R and fast.observer.p == ref.observer.p
        assert fast.observer.n_tilt_updates == ref.observer.n_tilt_updates
        assert fast.attitude_estimate() == ref.attitude_estimate()


def test_update_fast_raises_like_reference_on_a_zero_vector():
    veh, cfg = VehicleConfig(), ControlConfig()
    ctl = GeometricController(veh, cfg, (11.5, 5.0, 1.5))
    meas = Measurements((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.2, -0.4), (0.0, 0.0, 1.0), (0.0, 0.0, 0.0))
    with pytest.raises(ValueError):
        ctl.update(0.0, meas, Reference((0.0, 0.0, 1.0)))
    with pytest.raises(ValueError):
        GeometricController(veh, cfg, (11.5, 5.0, 1.5)).update_reference(0.0, meas, Reference((0.0, 0.0, 1.0)))


def test_mix_fast_equals_mix_bit_for_bit():
    mixer = Mixer(VehicleConfig())
    rng = np.random.default_rng(5)
    fmax = mixer.f_max
    steps = set()
    for _ in range(20000):
        f = float(rng.uniform(-0.5, 4.5) * fmax)
        tx, ty = (float(x) for x in rng.normal(0.0, rng.choice([0.05, 1.0, 5.0]), 2))
        tz = float(rng.normal(0.0, rng.choice([0.01, 0.2])))
        ref = mixer.mix(f, (tx, ty, tz))
        cmd, sat = mixer.mix_fast(f, tx, ty, tz)
        assert cmd == ref.cmd and sat == ref.saturated
        steps.add((ref.saturated, ref.tau_flu_nm[2] == 0.0, ref.f_n == f))
    assert len(steps) >= 3                                # unsaturated, yaw cut, collective shifted
