"""Thrust and torque -> normalised motor commands (PX4 quad-X order).

The wrench ``[f, tau_x, tau_y, tau_z]`` (N, N m, body FLU) maps to rotor
thrusts through the inverse of ``mavcore.vehicle.allocation_matrix``;
``cmd_i = f_i / max_thrust_per_rotor_n`` (``mavcore/vehicle.py``).

Saturation policy (thrust direction first). A quadrotor's thrust direction
is its attitude, and the attitude is steered by the roll/pitch torques, so:

1. the demand is achievable (every rotor in [0, f_max]): use it;
2. otherwise scale the yaw torque down (largest factor in [0, 1]) keeping
   collective and roll/pitch torques;
3. if even zero yaw torque does not fit, shift the collective thrust to the
   nearest value at which the roll/pitch torques fit (less thrust when the
   rotors hit the top, more when they hit zero), then give back as much yaw
   torque as fits at that collective;
4. if the roll/pitch torques alone span more than [0, f_max], scale them
   down together (their ratio, the axis of the correction, is kept) around
   the mid collective, with zero yaw torque;
5. clip to [0, 1] (guards rounding only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mavcore.vehicle import VehicleConfig, allocation_matrix


@dataclass(frozen=True, slots=True)
class MotorCommand:
    """Mixer output.

    Attributes
    ----------
    cmd : tuple (4,)
        Normalised motor commands in [0, 1], PX4 quad-X order.
    f_n : float
        Collective thrust actually commanded (N).
    tau_flu_nm : tuple (3,)
        Torque actually commanded (N m, body FLU).
    saturated : bool
        True when the demand was modified (steps 2-4 of the policy).
    """

    cmd: tuple[float, float, float, float]
    f_n: float
    tau_flu_nm: tuple[float, float, float]
    saturated: bool


class Mixer:
    """Wrench -> motor commands for one vehicle (precomputes the inverse allocation).

    Parameters
    ----------
    vehicle : VehicleConfig
    """

    __slots__ = ("f_max", "_inv", "_A", "_coef")

    def __init__(self, vehicle: VehicleConfig) -> None:
        A = allocation_matrix(vehicle)
        self._A = A
        inv = np.linalg.inv(A)
        # Columns of A^-1 as float tuples: thrust_i = sum_j inv[i][j] w_j.
        self._inv = tuple(tuple(float(x) for x in row) for row in inv)
        self.f_max = float(vehicle.max_thrust_per_rotor_n)
        # The same numbers unrolled for mix_fast: (c_i, p_i, q_i, s_i) are
        # the weights of f, tau_x, tau_y, tau_z in rotor i's thrust.
        self._coef = tuple(row[j] for j in range(4) for row in self._inv)

    def wrench(self, thrusts_n) -> tuple[float, float, float, float]:
        """Rotor thrusts (4,) N -> [f, tau_x, tau_y, tau_z] (N, N m, FLU)."""
        w = self._A @ np.asarray(thrusts_n, dtype=float)
        return (float(w[0]), float(w[1]), float(w[2]), float(w[3]))

    def yaw_torque_limit(self, f_n: float) -> float:
        """Largest yaw torque |tau_z| (N m) at collective ``f_n`` (N) with zero roll/pitch torque.

        The yaw authority of the vehicle: every rotor stays in [0, f_max].
        For this module's quad-X, ``4 c_tau min(f/4, f_max - f/4)``.
        """
        lim = float("inf")
        for row in self._inv:
            base, y = row[0] * float(f_n), abs(row[3])
            if y > 0.0:
                lim = min(lim, min(base, self.f_max - base) / y)
        return max(lim, 0.0)

    def mix(self, f_n: float, tau_flu_nm) -> MotorCommand:
        """Apply the saturation policy of the module docstring.

        Parameters
        ----------
        f_n : float
            Desired collective thrust (N).
        tau_flu_nm : sequence (3,)
            Desired torque (N m, body FLU).
        """
        inv = self._inv
        fmax = self.f_max
        tx, ty, tz = float(tau_flu_nm[0]), float(tau_flu_nm[1]), float(tau_flu_nm[2])
        f = float(f_n)
        c = [row[0] for row in inv]                    # per unit collective
        d = [row[1] * tx + row[2] * ty for row in inv]  # roll/pitch part
        y = [row[3] * tz for row in inv]                # yaw part
        t = [c[i] * f + d[i] + y[i] for i in range(4)]
        if min(t) >= 0.0 and max(t) <= fmax:
            return MotorCommand(tuple(x / fmax for x in t), f, (tx, ty, tz), False)

        # Collective + roll/pitch with no yaw; c_i is the same for all rotors
        # of a symmetric quad-X, so the collective shifts all rotors equally.
        base = [c[i] * f + d[i] for i in range(4)]
        spread_fits = max(d) - min(d) <= fmax
        if not (min(base) >= 0.0 and max(base) <= fmax):
            if spread_fits:
                # Nearest collective at which the roll/pitch torques fit.
                lo = max(-d[i] / c[i] for i in range(4))
                hi = min((fmax - d[i]) / c[i] for i in range(4))
                f = min(max(f, lo), hi)
                base = [c[i] * f + d[i] for i in range(4)]
            else:
                mu = fmax / (max(d) - min(d))
                tx, ty = tx * mu, ty * mu
                d = [x * mu for x in d]
                f = (0.5 * fmax - 0.5 * (max(d) + min(d))) / c[0]
                base = [c[i] * f + d[i] for i in range(4)]
                tz = 0.0
                y = [0.0] * 4
        lam = _max_scale(base, y, fmax)
        tz *= lam
        t = [min(max(base[i] + lam * y[i], 0.0), fmax) for i in range(4)]
        return MotorCommand(tuple(x / fmax for x in t), f, (tx, ty, tz), True)


    def mix_fast(self, f, tx, ty, tz):
        """:meth:`mix` on plain floats, for the 250 Hz loop: ``(cmd (4,), saturated)``.

        The same policy and the same floating-point operations in the same
        order as :meth:`mix` (so bit-identical results), unrolled for the
        quad's four rotors; ``min``/``max`` are spelled as the comparisons
        the builtins make (``x < current`` / ``x > current``, first wins).
        The rare step 4 (roll/pitch alone do not fit) is delegated to
        :meth:`mix`.

        Parameters
        ----------
        f : float
            Desired collective thrust (N).
        tx, ty, tz : float
            Desired torque (N m, body FLU).
        """
        c0, c1, c2, c3, p0, p1, p2, p3, q0, q1, q2, q3, s0, s1, s2, s3 = self._coef
        fmax = self.f_max
        d0, d1, d2, d3 = p0 * tx + q0 * ty, p1 * tx + q1 * ty, p2 * tx + q2 * ty, p3 * tx + q3 * ty
        y0, y1, y2, y3 = s0 * tz, s1 * tz, s2 * tz, s3 * tz
        b0, b1, b2, b3 = c0 * f + d0, c1 * f + d1, c2 * f + d2, c3 * f + d3
        t0, t1, t2, t3 = b0 + y0, b1 + y1, b2 + y2, b3 + y3
        lo = t0
        if t1 < lo:
            lo = t1
        if t2 < lo:
            lo = t2
        if t3 < lo:
            lo = t3
        hi = t0
        if t1 > hi:
            hi = t1
        if t2 > hi:
            hi = t2
        if t3 > hi:
            hi = t3
        if lo >= 0.0 and hi <= fmax:
            return (t0 / fmax, t1 / fmax, t2 / fmax, t3 / fmax), False

        lo = b0
        if b1 < lo:
            lo = b1
        if b2 < lo:
            lo = b2
        if b3 < lo:
            lo = b3
        hi = b0
        if b1 > hi:
            hi = b1
        if b2 > hi:
            hi = b2
        if b3 > hi:
            hi = b3
        if not (lo >= 0.0 and hi <= fmax):
            dmin = dmax = d0
            for x in (d1, d2, d3):
                if x < dmin:
                    dmin = x
                if x > dmax:
                    dmax = x
            if not dmax - dmin <= fmax:
                mc = self.mix(f, (tx, ty, tz))
                return mc.cmd, mc.saturated
            # Nearest collective at which the roll/pitch torques fit.
            lo = -d0 / c0
            for x in (-d1 / c1, -d2 / c2, -d3 / c3):
                if x > lo:
                    lo = x
            hi = (fmax - d0) / c0
            for x in ((fmax - d1) / c1, (fmax - d2) / c2, (fmax - d3) / c3):
                if x < hi:
                    hi = x
            if lo > f:
                f = lo
            if hi < f:
                f = hi
            b0, b1, b2, b3 = c0 * f + d0, c1 * f + d1, c2 * f + d2, c3 * f + d3
        lam = 1.0
        for b, yi in ((b0, y0), (b1, y1), (b2, y2), (b3, y3)):
            if yi > 0.0:
                x = (fmax - b) / yi
                if x < lam:
                    lam = x
            elif yi < 0.0:
                x = -b / yi
                if x < lam:
                    lam = x
        if 0.0 > lam:
            lam = 0.0
        out = []
        for b, yi in ((b0, y0), (b1, y1), (b2, y2), (b3, y3)):
            x = b + lam * yi
            if 0.0 > x:
                x = 0.0
            if fmax < x:
                x = fmax
            out.append(x / fmax)
        return tuple(out), True


def _max_scale(base, y, fmax: float) -> float:
    """Largest lam in [0, 1] with 0 <= base_i + lam y_i <= fmax for all i."""
    lam = 1.0
    for b, yi in zip(base, y):
        if yi > 0.0:
            lam = min(lam, (fmax - b) / yi)
        elif yi < 0.0:
            lam = min(lam, -b / yi)
    return max(lam, 0.0)
