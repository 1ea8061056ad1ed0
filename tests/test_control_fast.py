"""The 250 Hz paths equal plain, readable compositions of the same equations bit for bit.

``GeometricController.update`` (``command``, the one controller path, plus
the named output) against ``plain_update`` below: eqs. (21)-(31) composed
with tuple helpers as first written (the former ``update_reference``,
kept here as the specification), and ``Mixer.mix_fast`` against
``Mixer.mix``, on random inputs that visit the rare branches: free fall,
pointing target at the vehicle, pointing along the thrust, both attitude
laws, filters on and off, and every mixer saturation step.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from companion.control import GeometricController, Measurements, Mixer, Reference
from mavcore.mission.control import ControlConfig
from companion.control.geometric import ControlOutput, DesiredAttitude, attitude_torque
from companion.control.observer import virtual_pairs
from companion.control.rates import rate_command
from mavcore.so3 import cross, dot, unit3, unit_d2
from companion.control.tilt import limit_thrust
from companion.control.vectors import controller_vectors
from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig

_ZERO = (0.0, 0.0, 0.0)


# --- the specification: the controller step as first written -------------------------------


def plain_body_coordinates(w, b1, b2, r1, r2):
    """R^T w by TRIAD, as first written."""
    mb = unit3(cross(b1, b2))
    mr = unit3(cross(r1, r2))
    nb = cross(b1, mb)
    nr = cross(r1, mr)
    c1, c2, c3 = dot(w, r1), dot(w, mr), dot(w, nr)
    return tuple(c1 * b1[i] + c2 * mb[i] + c3 * nb[i] for i in range(3))


def plain_thrust_axis(b1, b2, r1, r2):
    """R e3 by TRIAD, as first written."""
    mb = unit3(cross(b1, b2))
    mr = unit3(cross(r1, r2))
    nb = cross(b1, mb)
    nr = cross(r1, mr)
    return tuple(r1[i] * b1[2] + mr[i] * mb[2] + nr[i] * nb[2] for i in range(3))


def plain_desired_attitude(F, F_dot, F_ddot, u_s, u_s_dot, u_s_ddot, b2_fallback=(0.0, 1.0, 0.0)) -> DesiredAttitude:
    """desired_attitude written with unit_d2 on tuples (the specification of desired_frame)."""
    if dot(F, F) < 1e-12:   # free fall demanded: no thrust direction, keep level
        F, F_dot, F_ddot = (0.0, 0.0, 1e-6), _ZERO, _ZERO
    b3, b3d, b3dd = unit_d2(F, F_dot, F_ddot)
    if dot(u_s, u_s) > 1e-12:
        s, sd, sdd = unit_d2(u_s, u_s_dot, u_s_ddot)
    else:
        s, sd, sdd = b2_fallback, _ZERO, _ZERO
    # w = s - (s.b3) b3 (eq. 22) and its derivatives.
    c = dot(s, b3)
    cd = dot(sd, b3) + dot(s, b3d)
    cdd = dot(sdd, b3) + 2.0 * dot(sd, b3d) + dot(s, b3dd)
    w = (s[0] - c * b3[0], s[1] - c * b3[1], s[2] - c * b3[2])
    wd = tuple(sd[i] - cd * b3[i] - c * b3d[i] for i in range(3))
    wdd = tuple(sdd[i] - cdd * b3[i] - 2.0 * cd * b3d[i] - c * b3dd[i] for i in range(3))
    if dot(w, w) < 1e-12:   # s along b3d: keep the previous pointing, frozen
        c = dot(b2_fallback, b3)
        w = tuple(b2_fallback[i] - c * b3[i] for i in range(3))
        wd = wdd = _ZERO
        if dot(w, w) < 1e-12:
            w = cross(b3, (1.0, 0.0, 0.0) if abs(b3[0]) < 0.9 else (0.0, 1.0, 0.0))
    b2, b2d, b2dd = unit_d2(w, wd, wdd)
    b1 = cross(b2, b3)
    x1, x2 = cross(b2d, b3), cross(b2, b3d)
    b1d = (x1[0] + x2[0], x1[1] + x2[1], x1[2] + x2[2])
    y1, y2, y3 = cross(b2dd, b3), cross(b2d, b3d), cross(b2, b3dd)
    b1dd = tuple(y1[i] + 2.0 * y2[i] + y3[i] for i in range(3))
    Omega_d = (dot(b3, b2d), dot(b1, b3d), dot(b2, b1d))
    Omega_d_dot = (dot(b3d, b2d) + dot(b3, b2dd),
                   dot(b1d, b3d) + dot(b1, b3dd),
                   dot(b2d, b1d) + dot(b2, b1dd))
    R_d = ((b1[0], b2[0], b3[0]), (b1[1], b2[1], b3[1]), (b1[2], b2[2], b3[2]))
    return DesiredAttitude(R_d, b1, b2, b3, Omega_d, Omega_d_dot)


def plain_yaw_filter(state, t_s, x, cutoff_hz):
    """The yaw-rate low-pass (companion.control.yaw) written out: ``state`` is a dict
    holding the previous time and output; exact discretisation ``y += (1 - exp(-w dt)) (x - y)``."""
    if "t" not in state:
        state["t"], state["y"] = t_s, x
        return x
    dt = t_s - state["t"]
    if not dt > 0.0:
        return state["y"]
    state["t"] = t_s
    state["y"] = state["y"] + (1.0 - math.exp(-(2.0 * math.pi * cutoff_hz) * dt)) * (x - state["y"])
    return state["y"]


def plain_decoupled(inertia_kg_m2, Omega, Omega_d, Omega_d_dot, q1, q2, q3, rho, alpha, alpha_yaw=None,
                    yaw_rate_filtered=None):
    """attitude_torque_decoupled as first written (tuple comprehensions): (tau, z, V); the yaw
    damping ``alpha_yaw`` on ``yaw_rate_filtered - (Q Omega_d)_z`` where given."""
    dx, dy, dz = q3
    kx, ky = -dy, dx                       # k = e3 x d (k_z = 0)
    s_t = math.sqrt(kx * kx + ky * ky)
    tilt = math.atan2(s_t, dz)
    # Q_xy^T q1 = q1 - k x q1 + k x (k x q1) / (1 + d_z): q1 with the tilt undone.
    v = q1
    if dz > -1.0 + 1e-9:
        kv = (ky * v[2], -kx * v[2], kx * v[1] - ky * v[0])                   # k x v
        kkv = (ky * kv[2], -kx * kv[2], kx * kv[1] - ky * kv[0])              # k x (k x v)
        w = 1.0 / (1.0 + dz)
        vx, vy = v[0] - kv[0] + w * kkv[0], v[1] - kv[1] + w * kkv[1]
        psi = math.atan2(vy, vx)
    else:                                  # upside down: tilt first, no yaw error
        psi = 0.0
    r1, r2 = rho
    z = (r1 * kx, r1 * ky, r2 * math.sin(psi))
    Od = tuple(Omega_d[0] * q1[i] + Omega_d[1] * q2[i] + Omega_d[2] * q3[i] for i in range(3))
    Odd = tuple(Omega_d_dot[0] * q1[i] + Omega_d_dot[1] * q2[i] + Omega_d_dot[2] * q3[i] for i in range(3))
    wx, wy, wz = Omega
    e = (wx - Od[0], wy - Od[1], wz - Od[2])
    WxOd = cross(Omega, Od)
    Jx, Jy, Jz = inertia_kg_m2
    Jw = (Jx * wx, Jy * wy, Jz * wz)
    gyro = (wy * Jw[2] - wz * Jw[1], wz * Jw[0] - wx * Jw[2], wx * Jw[1] - wy * Jw[0])
    damp = [alpha * e[0], alpha * e[1], alpha * e[2]]
    if alpha_yaw is not None:
        damp[2] = alpha_yaw * (yaw_rate_filtered - Od[2])
    tau = tuple(gyro[i] + inertia_kg_m2[i] * (Odd[i] - WxOd[i] + z[i] - damp[i]) for i in range(3))
    V = r1 * (1.0 - dz) + r2 * (1.0 - math.cos(psi)) + 0.5 * dot(e, e)
    return tau, z, V


def plain_update(self, t_s: float, meas: Measurements, ref: Reference) -> ControlOutput:
    """The controller step as the plain composition of eqs. (21)-(31) (``GeometricController.update_reference``
    before the per-frame path replaced it): the specification ``command`` is checked against.
    ``self`` is a ``GeometricController`` whose filter state this advances."""
    m, g = self._m, self._g
    kx, kv = self.cfg.kx, self.cfg.kv
    gyro = meas.gyro_flu_rad_s
    Omega = (float(gyro[0]), float(gyro[1]), float(gyro[2]))
    p, v = meas.pos_enu_m, meas.vel_enu_m_s
    t_nav = t_s if meas.nav_time_s is None else meas.nav_time_s
    obs = self.observer
    if obs is not None:
        obs.update(t_s, Omega, meas.accel_flu_m_s2, meas.mag_flu_gauss, p, v, meas.nav_time_s,
                   self._thrust_prev)
        if obs.t is None:
            raise ValueError("the observer has no attitude estimate yet")
        Omega = (Omega[0] - obs.b[0], Omega[1] - obs.b[1], Omega[2] - obs.b[2])
        p, v, t_nav = obs.p, obs.v, t_s
        fi = obs.fix_interval_s
        self.accel.tau_s = fi if fi > self._tau_a else self._tau_a
    a_hat = self.accel.update(t_nav, v, ref.jerk_enu_m_s3)
    if obs is not None:
        pairs = virtual_pairs(obs.R, self._h)
    else:
        pairs = controller_vectors(self._f_acc.update(t_s, unit3(meas.accel_flu_m_s2), Omega),
                                   self._f_mag.update(t_s, unit3(meas.mag_flu_gauss), Omega),
                                   a_hat, self._r2, g, self.cfg.mag_perpendicular, self._vectors, self._aided)
    b1, b2, r1, r2 = pairs.b1, pairs.b2, pairs.r1, pairs.r2
    self._pairs = (b1, b2, r1, r2)
    self._pv = (tuple(p), tuple(v))
    self._t_last = t_s

    xd, vd, ad, jd, sd = ref.pos_enu_m, ref.vel_enu_m_s, ref.acc_enu_m_s2, ref.jerk_enu_m_s3, ref.snap_enu_m_s4
    e_x = (p[0] - xd[0], p[1] - xd[1], p[2] - xd[2])
    e_v = (v[0] - vd[0], v[1] - vd[1], v[2] - vd[2])
    ev_dot = (a_hat[0] - ad[0], a_hat[1] - ad[1], a_hat[2] - ad[2])
    ki = self._ki
    if ki > 0.0:
        # the integral term: F_d gains -ki e_i, F_d_dot -ki e_i_dot, F_d_ddot -ki e_i_ddot
        e_i, active = self._integrate(t_s, e_x)
        ei_dot, ei_ddot = (e_x, e_v) if active else (_ZERO, _ZERO)
        ev_ddot = tuple(-(kx * e_v[i] + kv * ev_dot[i] + ki * ei_dot[i]) / m for i in range(3))
        F = (-kx * e_x[0] - kv * e_v[0] - ki * e_i[0] + m * ad[0],
             -kx * e_x[1] - kv * e_v[1] - ki * e_i[1] + m * ad[1],
             -kx * e_x[2] - kv * e_v[2] - ki * e_i[2] + m * (g + ad[2]))
        F_dot = tuple(-kx * e_v[i] - kv * ev_dot[i] - ki * ei_dot[i] + m * jd[i] for i in range(3))
        F_ddot = tuple(-kx * ev_dot[i] - kv * ev_ddot[i] - ki * ei_ddot[i] + m * sd[i] for i in range(3))
    else:
        ev_ddot = tuple(-(kx * e_v[i] + kv * ev_dot[i]) / m for i in range(3))
        F = (-kx * e_x[0] - kv * e_v[0] + m * ad[0],
             -kx * e_x[1] - kv * e_v[1] + m * ad[1],
             -kx * e_x[2] - kv * e_v[2] + m * (g + ad[2]))
        F_dot = tuple(-kx * e_v[i] - kv * ev_dot[i] + m * jd[i] for i in range(3))
        F_ddot = tuple(-kx * ev_dot[i] - kv * ev_ddot[i] + m * sd[i] for i in range(3))
    Sp = self.target_enu_m if ref.target_enu_m is None else ref.target_enu_m
    u_s = (Sp[0] - xd[0], Sp[1] - xd[1], Sp[2] - xd[2])
    u_s_dot, u_s_ddot = (-vd[0], -vd[1], -vd[2]), (-ad[0], -ad[1], -ad[2])
    if self.pointing is not None and dot(u_s, u_s) > 1e-12:
        # eq. (21) made flyable (companion.control.pointing): a unit vector
        # with consistent derivatives passes desired_attitude's _unit_d2 unchanged.
        u_s, u_s_dot, u_s_ddot = self.pointing.update(t_s, *unit_d2(u_s, u_s_dot, u_s_ddot))
    # the safety limit of F_d (companion.control.tilt): None where inactive
    lim = limit_thrust(F, F_dot, F_ddot, self.cfg.vertical_thrust_min_fraction * m * GRAVITY_M_S2,
                       math.tan(math.radians(self.cfg.tilt_max_deg)))
    if lim is not None:
        F = lim.F
        des = plain_desired_attitude(lim.G, lim.G_dot, lim.G_ddot, u_s, u_s_dot, u_s_ddot, self._b2_prev)
    else:
        des = plain_desired_attitude(F, F_dot, F_ddot, u_s, u_s_dot, u_s_ddot, self._b2_prev)
    self._b2_prev = des.b2d

    if self._decoupled:
        q = [plain_body_coordinates(bd, b1, b2, r1, r2) for bd in (des.b1d, des.b2d, des.b3d)]
        # the yaw loop of companion.control.yaw: its own gains, damping on the low-passed yaw rate
        yaw = self.yaw
        wz_f = plain_yaw_filter(self.__dict__.setdefault("_spec_yaw_filter", {}), t_s, Omega[2], yaw.cutoff_hz)
        tau, z, V = plain_decoupled(self._J, Omega, des.Omega_d, des.Omega_d_dot, q[0], q[1], q[2],
                                    (self.cfg.rho1, yaw.stiffness_1_s2), self.cfg.alpha, yaw.damping_1_s, wz_f)
        Od = des.Omega_d
        Od_body = tuple(Od[0] * q[0][i] + Od[1] * q[1][i] + Od[2] * q[2][i] for i in range(3))   # Q Omega_d
        rates = rate_command(Od_body, z, self.cfg.alpha)
        rates = (rates[0], rates[1], rate_command(Od_body, z, yaw.damping_1_s)[2])   # yaw: z / alpha_y
    else:
        tau, z, V = attitude_torque(self._J, Omega, des.Omega_d, des.Omega_d_dot, (b1, b2), (r1, r2),
                                    des.b1d, des.b2d, des.b3d, self._rho, self.cfg.alpha)
        rates = rate_command(des.Omega_d, z, self.cfg.alpha)
    f = dot(F, plain_thrust_axis(b1, b2, r1, r2))
    mc = self.mixer.mix(f, tau)
    self._thrust_prev = (mc.cmd[0] + mc.cmd[1] + mc.cmd[2] + mc.cmd[3]) * self._fmax
    return ControlOutput(f, tau, mc.cmd, mc.saturated, des.b3d, des.b2d, des.R_d, des.Omega_d,
                         e_x, e_v, z, V, rates)


# --- the checks -----------------------------------------------------------------------------


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
    n_sat = n_lim = 0
    for t, meas, r in _frames(np.random.default_rng(3)):
        a = fast.update(t, meas, r)
        b = plain_update(ref, t, meas, r)
        n_lim += fast.last_limited
        for f in dataclasses.fields(a):
            assert _same(getattr(a, f.name), getattr(b, f.name)), (t, f.name)
        n_sat += a.saturated
        # the fast path's log row is R_d's columns and f
        assert fast.last_desired == tuple(b.R_d[i][j] for j in range(3) for i in range(3)) + (b.f_n,)
    assert n_sat > 0                                      # the saturated mixer paths were visited
    assert 0 < n_lim < 400                                # both sides of the thrust limit were visited
    if fast.observer is not None:                         # the observer ran the same in both
        assert fast.observer.R == ref.observer.R and fast.observer.p == ref.observer.p
        assert fast.observer.n_tilt_updates == ref.observer.n_tilt_updates
        assert fast.attitude_estimate() == ref.attitude_estimate()


def test_command_raises_like_the_specification_on_a_zero_vector():
    veh, cfg = VehicleConfig(), ControlConfig()
    ctl = GeometricController(veh, cfg, (11.5, 5.0, 1.5))
    meas = Measurements((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.2, -0.4), (0.0, 0.0, 1.0), (0.0, 0.0, 0.0))
    with pytest.raises(ValueError):
        ctl.update(0.0, meas, Reference((0.0, 0.0, 1.0)))
    with pytest.raises(ValueError):
        plain_update(GeometricController(veh, cfg, (11.5, 5.0, 1.5)), 0.0, meas, Reference((0.0, 0.0, 1.0)))


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
