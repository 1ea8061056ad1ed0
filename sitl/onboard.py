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

Collision prevention (``velocity_limit``, ``sitl.collision_prevention``, PX4's
CP_DIST/CP_DELAY/CP_GO_NO_DATA from OBSTACLE_DISTANCE) scales the horizontal
velocity setpoint after the speed limits and drops the horizontal
acceleration feed-forward while it limits.

The setpoint follows MAVLink's type_mask semantics: a ``None`` group (or a
NaN component) is not controlled. Position absent: the velocity loop runs on
the velocity setpoint alone; velocity and position absent: acceleration
only; yaw absent: the yaw rate setpoint is integrated (or yaw is held).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig, allocation_matrix


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
        self.gains = gains            # property: also caches the gains as plain floats
        self.g = float(gravity_m_s2)
        self.m = float(vehicle.mass_kg)
        self.J = tuple(float(j) for j in vehicle.inertia_kg_m2)
        self.fmax = float(vehicle.max_thrust_per_rotor_n)
        #: Collision prevention (``sitl.collision_prevention.CollisionPrevention.limit``)
        #: applied to the horizontal velocity setpoint; None: none.
        self.velocity_limit = None
        Ainv = np.linalg.pinv(allocation_matrix(vehicle))
        self._Ainv = tuple(tuple(float(x) for x in row) for row in Ainv)   # rows: rotors
        self.reset()

    @property
    def gains(self) -> OnboardGains:
        """The gains in use; assigning new gains takes effect at the next update."""
        return self._gains

    @gains.setter
    def gains(self, gains: OnboardGains) -> None:
        self._gains = gains
        # One flat tuple of floats, unpacked into locals by update_floats
        # (attribute and tuple-index lookups cost as much as the arithmetic).
        G = gains
        self._g_flat = tuple(float(x) for x in (
            *G.pos_kp, *G.vel_kp, *G.vel_ki, *G.vel_kd, G.vel_int_limit_m_s2,
            G.max_speed_xy_m_s, G.max_speed_up_m_s, G.max_speed_down_m_s,
            math.tan(G.max_tilt_rad), G.min_thrust_frac,
            *G.att_kp, *G.max_rate_rad_s, *G.rate_kp, *G.rate_ki, G.rate_int_limit_rad_s2))

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
        (kpx, kpy, kpz, kvx, kvy, kvz, kix, kiy, kiz, kdx, kdy, kdz, vlim,
         vxy_max, vup_max, vdn_max, tan_tilt, min_frac,
         kax, kay, kaz, mrx, mry, mrz, krx, kry, krz, kwx, kwy, kwz, il) = self._g_flat
        g, m = self.g, self.m
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
        px, py, pz = p
        vx, vy, vz = v

        # ---------------- position -> velocity -> acceleration (per axis)
        # NaN (or a None group) = not controlled; x == x is False only for NaN.
        psx, psy, psz = _f3(sp.pos_enu_m)
        vfx, vfy, vfz = _f3(sp.vel_enu_m_s)
        afx, afy, afz = _f3(sp.acc_enu_m_s2)
        hpx, hpy, hpz = psx == psx, psy == psy, psz == psz
        hvx, hvy, hvz = vfx == vfx, vfy == vfy, vfz == vfz
        vsx = (vfx if hvx else 0.0) + (kpx * (psx - px) if hpx else 0.0)
        vsy = (vfy if hvy else 0.0) + (kpy * (psy - py) if hpy else 0.0)
        vsz = (vfz if hvz else 0.0) + (kpz * (psz - pz) if hpz else 0.0)
        cx_on, cy_on, cz_on = hpx or hvx, hpy or hvy, hpz or hvz
        accx = afx if afx == afx else 0.0
        accy = afy if afy == afy else 0.0
        accz = afz if afz == afz else 0.0
        # Speed limits (horizontal norm, then vertical), as PX4.
        sxy = math.hypot(vsx, vsy)
        if sxy > vxy_max:
            k = vxy_max / sxy
            vsx *= k
            vsy *= k
        vsz = -vdn_max if vsz < -vdn_max else vsz
        vsz = vup_max if vsz > vup_max else vsz
        cp = self.velocity_limit
        if cp is not None:
            vsx, vsy, limited = cp(vsx, vsy, math.atan2(r10, r00), dt)
            if limited:       # no feed-forward into what it stops for
                accx = accy = 0.0
        evx = vsx - vx if cx_on else 0.0
        evy = vsy - vy if cy_on else 0.0
        evz = vsz - vz if cz_on else 0.0
        prev = self._ev_prev
        if prev is not None and dt > 0:
            dvx = (evx - prev[0]) / dt
            dvy = (evy - prev[1]) / dt
            dvz = (evz - prev[2]) / dt
        else:
            dvx = dvy = dvz = 0.0
        self._ev_prev = [evx, evy, evz]
        vi = self._vint
        if cx_on:
            accx += kvx * evx + vi[0] + kdx * dvx
        else:
            vi[0] = 0.0
        if cy_on:
            accy += kvy * evy + vi[1] + kdy * dvy
        else:
            vi[1] = 0.0
        if cz_on:
            accz += kvz * evz + vi[2] + kdz * dvz
        else:
            vi[2] = 0.0

        # ---------------- thrust vector with tilt and thrust limits
        Fx, Fy, Fz = m * accx, m * accy, m * (accz + g)
        Fmin = min_frac * 4.0 * self.fmax
        Fmax = 4.0 * self.fmax
        Fz = Fmin if Fz < Fmin else Fz
        Fz = Fmax if Fz > Fmax else Fz
        txy = math.hypot(Fx, Fy)
        tmax = Fz * tan_tilt
        if txy > tmax:
            k = tmax / txy
            Fx *= k
            Fy *= k
        # The integrator runs through saturation (bounded by its limit): in a
        # P-position / PI-velocity cascade its charge over a transient is
        # ~Kp int(e_p) - dp ~ 0, and freezing it while clipped breaks that
        # balance (measured: slower settling, steady undershoot).
        if not landed:
            if cx_on:
                x = vi[0] + kix * evx * dt
                vi[0] = -vlim if x < -vlim else (vlim if x > vlim else x)
            if cy_on:
                x = vi[1] + kiy * evy * dt
                vi[1] = -vlim if x < -vlim else (vlim if x > vlim else x)
            if cz_on:
                x = vi[2] + kiz * evz * dt
                vi[2] = -vlim if x < -vlim else (vlim if x > vlim else x)
        Fn = math.sqrt(Fx * Fx + Fy * Fy + Fz * Fz)
        b3x, b3y, b3z = Fx / Fn, Fy / Fn, Fz / Fn
        thrust = Fx * r02 + Fy * r12 + Fz * r22   # projected on the current body z (PX4)
        thrust = Fmin if thrust < Fmin else thrust
        thrust = Fmax if thrust > Fmax else thrust

        # ---------------- yaw setpoint
        yr = sp.yaw_rate_rad_s
        yr = 0.0 if yr is None or yr != yr else float(yr)
        ysp = sp.yaw_enu_rad
        if ysp is not None and ysp == ysp:
            yaw_sp = float(ysp)
            self._yaw_hold = yaw_sp
        else:
            if self._yaw_hold is None or landed:
                self._yaw_hold = math.atan2(r10, r00)
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
        # Yaw feed-forward: world-z rate expressed in the body frame (R^T e3).
        wsx = kax * ex + yr * r20
        wsy = kay * ey + yr * r21
        wsz = kaz * ez + yr * r22
        wsx = -mrx if wsx < -mrx else (mrx if wsx > mrx else wsx)
        wsy = -mry if wsy < -mry else (mry if wsy > mry else wsy)
        wsz = -mrz if wsz < -mrz else (mrz if wsz > mrz else wsz)

        # ---------------- body rate PI + gyroscopic feed-forward
        wx, wy, wz = w
        Jx, Jy, Jz = self.J
        erx, ery, erz = wsx - wx, wsy - wy, wsz - wz
        wi = self._wint
        if not landed:
            x = wi[0] + kwx * erx * dt
            wi[0] = -il if x < -il else (il if x > il else x)
            x = wi[1] + kwy * ery * dt
            wi[1] = -il if x < -il else (il if x > il else x)
            x = wi[2] + kwz * erz * dt
            wi[2] = -il if x < -il else (il if x > il else x)
        else:
            wi[0] = wi[1] = wi[2] = 0.0
        tx = Jx * (krx * erx + wi[0]) + (wy * Jz * wz - wz * Jy * wy)
        ty = Jy * (kry * ery + wi[1]) + (wz * Jx * wx - wx * Jz * wz)
        tz = Jz * (krz * erz + wi[2]) + (wx * Jy * wy - wy * Jx * wx)
        self.last_thrust_n = thrust
        self.last_torque_n_m = (tx, ty, tz)
        return self.mix(thrust, tx, ty, tz)

    def mix(self, thrust_n: float, tx: float, ty: float, tz: float):
        """Rotor commands (4-tuple, normalised) for [f (N), tau (N m, FLU)]
        with the saturation order roll/pitch > thrust > yaw (module docstring)."""
        fmax = self.fmax
        (a00, a01, a02, a03), (a10, a11, a12, a13), (a20, a21, a22, a23), (a30, a31, a32, a33) = self._Ainv
        # 1) roll/pitch must fit in the thrust range on its own
        q0 = a01 * tx + a02 * ty
        q1 = a11 * tx + a12 * ty
        q2 = a21 * tx + a22 * ty
        q3 = a31 * tx + a32 * ty
        span = max(q0, q1, q2, q3) - min(q0, q1, q2, q3)
        if span > fmax:
            k = fmax / span
            q0, q1, q2, q3 = q0 * k, q1 * k, q2 * k, q3 * k
        u0 = a00 * thrust_n + q0
        u1 = a10 * thrust_n + q1
        u2 = a20 * thrust_n + q2
        u3 = a30 * thrust_n + q3
        # 2) shift the collective (least change) so that all fit
        lo, hi = min(u0, u1, u2, u3), max(u0, u1, u2, u3)
        if lo < 0.0:
            shift = -lo
        elif hi > fmax:
            shift = fmax - hi
        else:
            shift = 0.0
        u0 += shift
        u1 += shift
        u2 += shift
        u3 += shift
        # 3) the yaw gets what is left
        y0, y1, y2, y3 = a03 * tz, a13 * tz, a23 * tz, a33 * tz
        k = 1.0
        for u, y in ((u0, y0), (u1, y1), (u2, y2), (u3, y3)):
            if y > 0.0:
                if u + y > fmax:
                    x = (fmax - u) / y
                    k = x if x < k else k
            elif y < 0.0 and u + y < 0.0:
                x = -u / y
                k = x if x < k else k
        k = 0.0 if k < 0.0 else k
        o0 = (u0 + k * y0) / fmax
        o1 = (u1 + k * y1) / fmax
        o2 = (u2 + k * y2) / fmax
        o3 = (u3 + k * y3) / fmax
        return (0.0 if o0 < 0.0 else (1.0 if o0 > 1.0 else o0),
                0.0 if o1 < 0.0 else (1.0 if o1 > 1.0 else o1),
                0.0 if o2 < 0.0 else (1.0 if o2 > 1.0 else o2),
                0.0 if o3 < 0.0 else (1.0 if o3 > 1.0 else o3))


_NAN3 = (math.nan, math.nan, math.nan)


def _f3(x):
    """A setpoint group as three plain floats (NaN for None): numpy scalars
    would make every operation of the cascade ~10x slower."""
    if x is None:
        return _NAN3
    a, b, c = x
    return float(a), float(b), float(c)
