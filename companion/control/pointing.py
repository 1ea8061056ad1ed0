r"""A dynamically feasible pointing reference (eq. 21 limited in yaw rate and acceleration).

Why. Eq. (21) points the body y axis at S_p: ``s = (S_p - x_d)/|S_p - x_d|``.
Its heading ``psi_s = atan2(s_y, s_x)`` turns at ``psi_s_dot = v_perp / d``
(``v_perp`` the speed across the line of sight, ``d`` the horizontal
distance to S_p): at 1 m/s passing 1.25 m from the target it swings by
180 deg in a few seconds, at up to 0.8 rad/s and 0.4 rad/s^2. This vehicle's
yaw authority is tiny (rotor drag torque coefficient 0.8 mm: at hover the
largest yaw torque is ``4 c_tau min(f_h, f_max - f_h)`` = 0.034 N m, i.e.
0.25 rad/s^2 with J_zz = 0.1377 kg m^2), so eq. (21) is not flyable there:
the yaw lags by tens of degrees and (with the paper's coupled attitude error)
the lag drags the thrust direction, hence the position.

What. A rate- and acceleration-saturated second-order reference governor on
the heading. Its state is the deviation ``delta = psi_r - psi_s`` of the
flown heading from eq. (21)'s and its rate; each sample::

    delta_dot_cmd = -sign(delta) min(k_p |delta|, sqrt(2 gamma a_max |delta|))
    u = clamp(psi_s_ddot + k_w (delta_dot_cmd - delta_dot), -a_max, a_max)   # psi_r_ddot
    delta_ddot = u - psi_s_ddot;  delta_dot += delta_ddot dt
    delta_dot = clamp(psi_s_dot + delta_dot, -w_max, w_max) - psi_s_dot;  delta += delta_dot dt

The braking-curve command (``gamma < 1`` leaves a margin) brings ``delta``
back to zero without overshoot at an acceleration within ``a_max``. Where
eq. (21) is feasible and the governor has caught up (``delta = delta_dot =
0``, ``|psi_s_ddot| <= a_max``, ``|psi_s_dot| <= w_max``), ``u`` equals
``psi_s_ddot`` exactly and ``delta`` stays exactly zero: the reference IS
eq. (21) there. Only where eq. (21) demands more than the vehicle has does
the flown heading deviate, by as little as the limits allow, and it rejoins
eq. (21) afterwards. The elevation of s (its z component) is kept as eq.
(21)'s: ``s_r = (c cos psi_r, c sin psi_r, s_z)`` with ``c = sqrt(1 -
s_z^2)``; its first two derivatives are analytic from ``psi_r``'s and
``s_z``'s, so Omega_d and Omega_d_dot (eq. 31) follow the governed heading.

It is causal (computed on the vehicle clock inside the controller), so it
needs nothing from the runner. ``a_max`` is a fraction of the vehicle's yaw
acceleration at hover (``ControlConfig.pointing_yaw_accel_fraction``): the
rest is left to reject disturbances and noise (the yaw loop's gains,
``companion.control.yaw``, give the gyro noise 10 % of it at 1 sigma).
Pure: no clock, no I/O.
"""

from __future__ import annotations

import math

Vec3 = tuple[float, float, float]


def heading_derivatives(s, sd, sdd):
    """Heading ``psi = atan2(s_y, s_x)`` of a pointing vector and its two derivatives.

    Parameters
    ----------
    s, sd, sdd : sequence (3,)
        Unit pointing vector (ENU) and its first two time derivatives.

    Returns
    -------
    (psi, psi_dot, psi_ddot) : floats (rad, rad/s, rad/s^2), or None when s
    is (nearly) vertical and has no heading.
    """
    rho = s[0] * s[0] + s[1] * s[1]
    if rho < 1e-8:
        return None
    n = s[0] * sd[1] - s[1] * sd[0]
    nd = s[0] * sdd[1] - s[1] * sdd[0]
    rhod = 2.0 * (s[0] * sd[0] + s[1] * sd[1])
    return math.atan2(s[1], s[0]), n / rho, (nd * rho - n * rhod) / (rho * rho)


class PointingGovernor:
    """Yaw-rate/yaw-acceleration limited version of eq. (21) (module docstring).

    Parameters
    ----------
    yaw_rate_max_rad_s : float
        w_max (rad/s), > 0.
    yaw_accel_max_rad_s2 : float
        a_max (rad/s^2), > 0.
    kp : float
        Linear gain of the braking curve near zero (1/s).
    kw : float
        Rate-tracking gain (1/s); ``kw dt`` must stay well below 1.
    gamma : float
        Fraction of a_max the braking curve assumes (margin), in (0, 1].
    """

    __slots__ = ("w_max", "a_max", "kp", "kw", "gamma", "_t", "_d", "_dd")

    def __init__(self, yaw_rate_max_rad_s: float, yaw_accel_max_rad_s2: float, kp: float = 1.5,
                 kw: float = 4.0, gamma: float = 0.5) -> None:
        if not (yaw_rate_max_rad_s > 0 and yaw_accel_max_rad_s2 > 0 and kp > 0 and kw > 0 and 0 < gamma <= 1):
            raise ValueError("PointingGovernor: limits and gains must be > 0, gamma in (0, 1]")
        self.w_max = float(yaw_rate_max_rad_s)
        self.a_max = float(yaw_accel_max_rad_s2)
        self.kp, self.kw, self.gamma = float(kp), float(kw), float(gamma)
        self._t: float | None = None
        self._d = 0.0      # delta = psi_r - psi_s (rad)
        self._dd = 0.0     # its rate (rad/s)

    @property
    def deviation_rad(self) -> float:
        """Current deviation psi_r - psi_s of the flown heading from eq. (21) (rad)."""
        return self._d

    def reset(self) -> None:
        self._t = None
        self._d = self._dd = 0.0

    def update(self, t_s: float, s, sd, sdd):
        """One sample of eq. (21)'s pointing -> the governed pointing.

        Parameters
        ----------
        t_s : float
            Vehicle time (s).
        s, sd, sdd : sequence (3,)
            Eq. (21)'s unit pointing vector (ENU) and its first two derivatives.

        Returns
        -------
        (s_r, s_r_dot, s_r_ddot) : three float tuples (3,), ENU: the governed
        unit pointing vector and its derivatives (``s`` itself, unchanged,
        while it has no heading).
        """
        # heading_derivatives(s, sd, sdd), inlined (250 Hz path); the
        # min/max below are spelled as the comparisons the builtins make.
        s0, s1 = s[0], s[1]
        rho = s0 * s0 + s1 * s1
        if rho < 1e-8:
            return tuple(s), tuple(sd), tuple(sdd)
        n = s0 * sd[1] - s1 * sd[0]
        w_s = n / rho
        a_s = ((s0 * sdd[1] - s1 * sdd[0]) * rho - n * (2.0 * (s0 * sd[0] + s1 * sd[1]))) / (rho * rho)
        psi = math.atan2(s1, s0)
        a_max, w_max = self.a_max, self.w_max
        t_prev = self._t
        d, dd = self._d, self._dd
        if t_prev is None:
            d = 0.0
            x = w_s
            if -w_max > x:
                x = -w_max
            if w_max < x:
                x = w_max
            dd = x - w_s
            u = a_s
            if -a_max > u:
                u = -a_max
            if a_max < u:
                u = a_max
        else:
            dt = t_s - t_prev
            ad = abs(d)
            if ad == 0.0:
                cmd = 0.0
            else:
                x = self.kp * ad
                y = math.sqrt(2.0 * self.gamma * a_max * ad)
                if y < x:
                    x = y
                cmd = -math.copysign(x, d)
            u = a_s + self.kw * (cmd - dd)
            if -a_max > u:
                u = -a_max
            if a_max < u:
                u = a_max
            if dt > 0.0:
                dd += (u - a_s) * dt
                x = w_s + dd
                if -w_max > x:
                    x = -w_max
                if w_max < x:
                    x = w_max
                dd = x - w_s
                d += dd * dt
                d = (d + math.pi) % (2.0 * math.pi) - math.pi
        self._t, self._d, self._dd = t_s, d, dd
        if d == 0.0 and dd == 0.0 and u == a_s:
            return tuple(s), tuple(sd), tuple(sdd)       # eq. (21) exactly
        pr, wr = psi + d, w_s + dd
        # s_r = c (cos pr, sin pr, 0) + s_z e3, c = sqrt(1 - s_z^2)
        sz, szd, szdd = s[2], sd[2], sdd[2]
        c = math.sqrt(max(1.0 - sz * sz, 1e-12))
        cd = -sz * szd / c
        cdd = -(szd * szd + sz * szdd) / c + sz * szd * cd / (c * c)
        cp, sp = math.cos(pr), math.sin(pr)
        sr = (c * cp, c * sp, sz)
        srd = (cd * cp - c * wr * sp, cd * sp + c * wr * cp, szd)
        srdd = (cdd * cp - 2.0 * cd * wr * sp - c * (u * sp + wr * wr * cp),
                cdd * sp + 2.0 * cd * wr * cp + c * (u * cp - wr * wr * sp), szdd)
        return sr, srd, srdd
