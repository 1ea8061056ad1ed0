"""The vehicle's own autopilot: a cascaded multicopter controller in the
manner of PX4's ``mc_pos_control`` / ``mc_att_control`` / ``mc_rate_control``.

Cascade (world ENU, body FLU, e3 up)::

    v_sp   = v_ff + Kp_pos (p_sp - p)                 (clamped speed)
    a_sp   = a_ff + Kp_vel e_v + Ki_vel int(e_v) + Kd_vel d(e_v)/dt
    F_sp   = m (a_sp + g e3)                           (tilt-limited, thrust-limited)
    b3_d   = F_sp / |F_sp|,  R_d from b3_d and the yaw setpoint
    f      = F_sp . R e3                               (collective thrust, N)
    W_sp   = Kp_att * vee(R^T R_d - R_d^T R)/2 + yaw-rate feed-forward
    tau    = J (Kp_rate e_W + Ki_rate int(e_W)) + W x J W     (gyroscopic feed-forward)
    thrust = mix(f, tau)                               (inverse of allocation_matrix)

The mixer (inverse of the allocation matrix) saturates in the order roll/pitch
> collective thrust > yaw: the roll/pitch torque is scaled down only if its
rotor spread alone exceeds the thrust range (direction kept), the collective
is shifted by the least amount that brings every rotor into [0, f_max], and
the yaw torque gets what is left (scaled, sign kept) -- the priorities of
PX4's multirotor mixer, where yaw authority is the first thing given up.

Default gains (``OnboardGains``), tuned on the paper's 4.34 kg vehicle at
250 Hz with a 5 ms motor lag: rate loop 25 rad/s bandwidth (Kp_rate as an
angular-acceleration gain, so it is independent of J), attitude 8 /s (yaw
3 /s), velocity 4 /s with a small integral, position 1.5 /s. Each loop is
at least three times slower than the one inside it.

The setpoint follows MAVLink's type_mask semantics: a ``None`` group (or a
NaN component) is not controlled. Position absent: the velocity loop runs on
the velocity setpoint alone; velocity and position absent: acceleration
only; yaw absent: the yaw rate setpoint is integrated (or yaw is held).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.vehicle import GRAVITY_M_S2, VehicleConfig, allocation_matrix


@dataclass(frozen=True)
class Setpoint:
    """A trajectory setpoint (world ENU).

    Attributes
    ----------
    pos_enu_m, vel_enu_m_s, acc_enu_m_s2 : (3,) or None
        None (or a NaN component): not controlled / no feed-forward.
    yaw_enu_rad : float or None
        Heading of body x from east, CCW (rad).
    yaw_rate_rad_s : float or None
        Yaw rate about world z (rad/s), feed-forward.
    """

    pos_enu_m: tuple | np.ndarray | None = None
    vel_enu_m_s: tuple | np.ndarray | None = None
    acc_enu_m_s2: tuple | np.ndarray | None = None
    yaw_enu_rad: float | None = None
    yaw_rate_rad_s: float | None = None


@dataclass(frozen=True)
class OnboardGains:
    """Gains and limits of the cascade (per axis x, y, z where a tuple)."""

    pos_kp: tuple[float, float, float] = (1.5, 1.5, 1.5)              # 1/s
    vel_kp: tuple[float, float, float] = (6.0, 6.0, 6.0)              # 1/s
    vel_ki: tuple[float, float, float] = (3.0, 3.0, 3.0)              # 1/s^2
    vel_kd: tuple[float, float, float] = (0.0, 0.0, 0.0)              # -
    vel_int_limit_m_s2: float = 3.0
    max_speed_xy_m_s: float = 5.0
    max_speed_up_m_s: float = 3.0
    max_speed_down_m_s: float = 1.5
    max_tilt_rad: float = math.radians(35.0)
    min_thrust_frac: float = 0.05                                    # of 4 f_max
    att_kp: tuple[float, float, float] = (12.0, 12.0, 0.5)           # 1/s
    max_rate_rad_s: tuple[float, float, float] = (3.5, 3.5, 0.4)
    rate_kp: tuple[float, float, float] = (40.0, 40.0, 4.0)          # 1/s (x J)
    rate_ki: tuple[float, float, float] = (30.0, 30.0, 0.3)          # 1/s^2 (x J)
    rate_int_limit_rad_s2: float = 5.0


class CascadedController:
    """PX4-style cascaded position/attitude/rate controller (pure, stateful).

    Parameters
    ----------
    vehicle : VehicleConfig
    gains : OnboardGains
    gravity_m_s2 : float
    """

    def __init__(self, vehicle: VehicleConfig = VehicleConfig(), gains: OnboardGains = OnboardGains(),
                 gravity_m_s2: float = GRAVITY_M_S2) -> None:
        self.vehicle = vehicle
        self.gains = gains
        self.g = float(gravity_m_s2)
        self.m = float(vehicle.mass_kg)
        self.J = tuple(float(j) for j in vehicle.inertia_kg_m2)
        self.fmax = float(vehicle.max_thrust_per_rotor_n)
        Ainv = np.linalg.pinv(allocation_matrix(vehicle))
        self._Ainv = tuple(tuple(float(x) for x in row) for row in Ainv)   # rows: rotors
        self.reset()

    def reset(self) -> None:
        """Clear integrators, filters and the held yaw."""
        self._vint = [0.0, 0.0, 0.0]
        self._wint = [0.0, 0.0, 0.0]
        self._ev_prev = None
        self._yaw_hold = None
        self.last_thrust_n = 0.0
        self.last_torque_n_m = (0.0, 0.0, 0.0)

    # ------------------------------------------------------------------
    def update(self, state, sp: Setpoint, dt_s: float) -> np.ndarray:
        """One control step.

        Parameters
        ----------
        state : TrueState-like
            ``pos_enu_m`` (3,), ``vel_enu_m_s`` (3,), ``R`` (3, 3) body FLU ->
            world ENU, ``omega_flu_rad_s`` (3,); optional ``landed`` (bool:
            integrators frozen on the ground).
        sp : Setpoint
        dt_s : float
            Time since the previous update (s).

        Returns
        -------
        (4,) ndarray
            Normalised motor commands in [0, 1] (PX4 quad-X order).
        """
        p = state.pos_enu_m
        v = state.vel_enu_m_s
        Rm = state.R
        w = state.omega_flu_rad_s
        landed = bool(getattr(state, "landed", False))
        return np.array(self.update_floats(
            (float(p[0]), float(p[1]), float(p[2])), (float(v[0]), float(v[1]), float(v[2])),
            tuple(float(x) for x in np.asarray(Rm, dtype=float).reshape(9)),
            (float(w[0]), float(w[1]), float(w[2])), sp, dt_s, landed))

    def update_floats(self, p, v, R, w, sp: Setpoint, dt, landed=False):
        """``update`` on plain floats: p, v, w 3-tuples, R a row-major 9-tuple.

        Returns a 4-tuple of normalised motor commands.
        """
        G = self.gains
        g, m = self.g, self.m
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = R

        # ---------------- position -> velocity -> acceleration (per axis)
        psp, vsp, asp = sp.pos_enu_m, sp.vel_enu_m_s, sp.acc_enu_m_s2
        acc = [0.0, 0.0, 0.0]
        vel_sp = [0.0, 0.0, 0.0]
        vel_ctl = [False, False, False]
        for i in range(3):
            pi = psp[i] if psp is not None else math.nan
            vi = vsp[i] if vsp is not None else math.nan
            ai = asp[i] if asp is not None else math.nan
            has_p = pi == pi
            has_v = vi == vi
            vs = (vi if has_v else 0.0) + (G.pos_kp[i] * (pi - p[i]) if has_p else 0.0)
            vel_ctl[i] = has_p or has_v
            vel_sp[i] = vs
            acc[i] = ai if ai == ai else 0.0
        # Speed limits (horizontal norm, then vertical), as PX4.
        sxy = math.hypot(vel_sp[0], vel_sp[1])
        if sxy > G.max_speed_xy_m_s:
            k = G.max_speed_xy_m_s / sxy
            vel_sp[0] *= k
            vel_sp[1] *= k
        vel_sp[2] = min(max(vel_sp[2], -G.max_speed_down_m_s), G.max_speed_up_m_s)
        ev = [vel_sp[i] - v[i] if vel_ctl[i] else 0.0 for i in range(3)]
        dev = [0.0, 0.0, 0.0]
        if self._ev_prev is not None and dt > 0:
            dev = [(ev[i] - self._ev_prev[i]) / dt for i in range(3)]
        self._ev_prev = ev
        for i in range(3):
            if vel_ctl[i]:
                acc[i] += G.vel_kp[i] * ev[i] + self._vint[i] + G.vel_kd[i] * dev[i]
            else:
                self._vint[i] = 0.0

        # ---------------- thrust vector with tilt and thrust limits
        Fx, Fy, Fz = m * acc[0], m * acc[1], m * (acc[2] + g)
        Fmin = G.min_thrust_frac * 4.0 * self.fmax
        Fmax = 4.0 * self.fmax
        Fz = min(max(Fz, Fmin), Fmax)
        txy = math.hypot(Fx, Fy)
        tmax = Fz * math.tan(G.max_tilt_rad)
        if txy > tmax:
            k = tmax / txy
            Fx *= k
            Fy *= k
        # The integrator runs through saturation (bounded by its limit): in a
        # P-position / PI-velocity cascade its charge over a transient is
        # ~Kp int(e_p) - dp ~ 0, and freezing it while clipped breaks that
        # balance (measured: slower settling, steady undershoot).
        if not landed:
            lim = G.vel_int_limit_m_s2
            for i in range(3):
                if vel_ctl[i]:
                    self._vint[i] = min(max(self._vint[i] + G.vel_ki[i] * ev[i] * dt, -lim), lim)
        Fn = math.sqrt(Fx * Fx + Fy * Fy + Fz * Fz)
        b3x, b3y, b3z = Fx / Fn, Fy / Fn, Fz / Fn
        thrust = Fx * r02 + Fy * r12 + Fz * r22   # projected on the current body z (PX4)
        thrust = min(max(thrust, Fmin), Fmax)

        # ---------------- yaw setpoint
        yaw_now = math.atan2(r10, r00)
        yr = sp.yaw_rate_rad_s if (sp.yaw_rate_rad_s is not None and sp.yaw_rate_rad_s == sp.yaw_rate_rad_s) else 0.0
        if sp.yaw_enu_rad is not None and sp.yaw_enu_rad == sp.yaw_enu_rad:
            yaw_sp = float(sp.yaw_enu_rad)
            self._yaw_hold = yaw_sp
        else:
            if self._yaw_hold is None or landed:
                self._yaw_hold = yaw_now
            self._yaw_hold += yr * dt
            yaw_sp = self._yaw_hold
        # R_d = [b1d b2d b3d]: b2d = b3d x b1c / |.|, b1d = b2d x b3d
        cx, cy = math.cos(yaw_sp), math.sin(yaw_sp)
        b2x, b2y, b2z = -b3z * cy, b3z * cx, b3x * cy - b3y * cx
        n2 = math.sqrt(b2x * b2x + b2y * b2y + b2z * b2z)
        b2x, b2y, b2z = b2x / n2, b2y / n2, b2z / n2
        b1x = b2y * b3z - b2z * b3y
        b1y = b2z * b3x - b2x * b3z
        b1z = b2x * b3y - b2y * b3x

        # ---------------- attitude, tilt first (PX4): roll/pitch from the
        # shortest rotation of b3 onto b3_d, yaw from the full error
        # e_R = vee(R^T R_d - R_d^T R) / 2, so a large yaw error never tilts
        # the thrust. e_tilt = R^T (b3 x b3_d) has no body-z component.
        cx_ = r12 * b3z - r22 * b3y
        cy_ = r22 * b3x - r02 * b3z
        cz_ = r02 * b3y - r12 * b3x
        ex = r00 * cx_ + r10 * cy_ + r20 * cz_
        ey = r01 * cx_ + r11 * cy_ + r21 * cz_
        if r02 * b3x + r12 * b3y + r22 * b3z < 0.0:
            # more than 90 deg off: sin() would shrink the error; use the full magnitude
            n = math.hypot(ex, ey)
            if n > 1e-9:
                ex, ey = ex / n, ey / n
        # E = R^T R_d: E_ij = col_i(R) . col_j(R_d); only E10 - E01 is needed (yaw)
        E01 = r00 * b2x + r10 * b2y + r20 * b2z
        E10 = r01 * b1x + r11 * b1y + r21 * b1z
        ez = 0.5 * (E10 - E01)
        kp = G.att_kp
        # Yaw feed-forward: world-z rate expressed in the body frame (R^T e3).
        wsx = kp[0] * ex + yr * r20
        wsy = kp[1] * ey + yr * r21
        wsz = kp[2] * ez + yr * r22
        mr = G.max_rate_rad_s
        wsx = min(max(wsx, -mr[0]), mr[0])
        wsy = min(max(wsy, -mr[1]), mr[1])
        wsz = min(max(wsz, -mr[2]), mr[2])

        # ---------------- body rate PI + gyroscopic feed-forward
        wx, wy, wz = w
        Jx, Jy, Jz = self.J
        erx, ery, erz = wsx - wx, wsy - wy, wsz - wz
        wi = self._wint
        ki = G.rate_ki
        il = G.rate_int_limit_rad_s2
        if not landed:
            wi[0] = min(max(wi[0] + ki[0] * erx * dt, -il), il)
            wi[1] = min(max(wi[1] + ki[1] * ery * dt, -il), il)
            wi[2] = min(max(wi[2] + ki[2] * erz * dt, -il), il)
        else:
            wi[0] = wi[1] = wi[2] = 0.0
        rk = G.rate_kp
        tx = Jx * (rk[0] * erx + wi[0]) + (wy * Jz * wz - wz * Jy * wy)
        ty = Jy * (rk[1] * ery + wi[1]) + (wz * Jx * wx - wx * Jz * wz)
        tz = Jz * (rk[2] * erz + wi[2]) + (wx * Jy * wy - wy * Jx * wx)
        self.last_thrust_n = thrust
        self.last_torque_n_m = (tx, ty, tz)
        return self.mix(thrust, tx, ty, tz)

    def mix(self, thrust_n: float, tx: float, ty: float, tz: float):
        """Rotor commands (4-tuple, normalised) for [f (N), tau (N m, FLU)]
        with the saturation order roll/pitch > thrust > yaw (module docstring)."""
        fmax = self.fmax
        A = self._Ainv
        base = [A[i][0] * thrust_n for i in range(4)]
        rp = [A[i][1] * tx + A[i][2] * ty for i in range(4)]
        yw = [A[i][3] * tz for i in range(4)]
        # 1) roll/pitch must fit in the thrust range on its own
        span = max(rp) - min(rp)
        if span > fmax:
            k = fmax / span
            rp = [x * k for x in rp]
        u = [base[i] + rp[i] for i in range(4)]
        # 2) shift the collective (least change) so that all fit
        lo, hi = min(u), max(u)
        if lo < 0.0:
            shift = -lo
        elif hi > fmax:
            shift = fmax - hi
        else:
            shift = 0.0
        u = [x + shift for x in u]
        # 3) the yaw gets what is left
        k = 1.0
        for i in range(4):
            y = yw[i]
            if y > 0.0 and u[i] + y > fmax:
                k = min(k, (fmax - u[i]) / y)
            elif y < 0.0 and u[i] + y < 0.0:
                k = min(k, -u[i] / y)
        k = max(k, 0.0)
        return tuple(min(max((u[i] + k * yw[i]) / fmax, 0.0), 1.0) for i in range(4))
