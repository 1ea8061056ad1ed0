"""Quadrotor rigid-body plant on SE(3): the paper's eq. (20), z up, ENU/FLU.

Equations (world ENU, body FLU, e3 = (0, 0, 1))::

    p' = v
    m v' = f R e3 - m g e3 - k_d (v - w)           (k_d = 0: eq. (20) exactly)
    R' = R [Omega]x
    J Omega' = -Omega x J Omega + tau

with ``[f, tau] = A @ f_rotor`` (``mavcore.vehicle.allocation_matrix``),
per-rotor thrusts limited to ``[0, max_thrust_per_rotor_n]`` and a
first-order motor lag ``T f_i' = f_cmd_i - f_i``.

Integrator (one physics step of length h, commands held constant):

- motors: exact solution of the lag, ``a = exp(-h/T)``; the force and torque
  used over the step are the exact mean of the thrust over the step;
- Omega: classical RK4 on Euler's equation (torque constant over the step);
- R: ``R <- R Exp(theta)`` (Rodrigues) with the fourth-order Magnus/Hermite
  rotation vector ``theta = h/2 (W0 + W1) + h^2/12 (W0' - W1' + W0 x W1)``,
  so R stays on SO(3) to rounding; a Newton polar step every 64 steps removes
  the rounding drift;
- p, v: RK4 (Simpson) quadrature of the acceleration with the thrust axis at
  the start, middle and end of the step: exact for constant acceleration
  (free fall, hover).

Ground contact: the body origin may not go below the terrain. Touching down
sets ``landed``: the vehicle rests level (yaw kept) with zero velocity and
rate, motors keep spinning; it lifts off as soon as the vertical thrust
exceeds the weight (no sinking, no sliding). Every touchdown increments
``touchdowns`` and records the velocity just before it (``impact_vel_enu_m_s``).

Crash (``crash``, decided by ``sitl.collision``): the rotors stop at once and
stay stopped whatever the commands, velocity and body rate drop to zero (a
fully inelastic hit), and the body falls from where it hit straight down to
the support height given (the terrain, or the top of what is under it),
where it rests (``landed``) until ``set_state`` resets it.

The hot path is plain Python float arithmetic on purpose: numpy calls on
3-vectors cost about 1 us each, the whole step here costs about as much as
ten of them (see ``benchmarks/bench_sitl.py``). ``Plant.advance`` runs the
several steps of a sensor frame with the state in local variables
(bit-for-bit the same as repeated ``step`` calls). With numba installed (the
``fast`` extra) the airborne steps run in ``sitl.plant_kernel`` instead, bit
for bit the same (``VINEYARD_GNC_NUMBA=0``: this loop only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from mavcore.so3 import polar_step
from mavcore.vehicle import GRAVITY_M_S2, VehicleConfig, allocation_matrix

from . import plant_kernel as _plant_kernel

_REORTHO_EVERY = _plant_kernel.REORTHO_EVERY


@dataclass(frozen=True)
class PlantParams:
    """Physical parameters of the plant.

    Attributes
    ----------
    vehicle : VehicleConfig
        Mass, inertia, rotor geometry, thrust limit, motor time constant.
    gravity_m_s2 : float
        g (m/s^2); 0 turns gravity off (tests of the rotational dynamics).
    drag_n_s_m : float
        Linear drag coefficient k_d (N s/m) against the air velocity.
    """

    vehicle: VehicleConfig = VehicleConfig()
    gravity_m_s2: float = GRAVITY_M_S2
    drag_n_s_m: float = 0.0


def _flat_ground(x: float, y: float) -> float:
    return -math.inf


class Plant:
    """The rigid body, its four motors and the ground contact.

    Parameters
    ----------
    params : PlantParams
    ground_height : callable (x, y) -> z, optional
        Terrain height (m, ENU) under a point; default no ground at all.
    max_ground_m : float
        An upper bound of ``ground_height`` (m): above it the lookup is skipped.

    State (attributes, plain floats; read them through ``state_arrays``):
    ``p`` (3,) position ENU (m), ``v`` (3,) velocity ENU (m/s), ``R`` (9,)
    body FLU -> world ENU rotation, row-major, ``w`` (3,) body rate FLU
    (rad/s), ``f`` (4,) rotor thrusts (N), ``acc`` (3,) acceleration ENU at the
    end of the last step (m/s^2), ``landed`` (bool).
    """

    def __init__(self, params: PlantParams = PlantParams(),
                 ground_height: Callable[[float, float], float] | None = None,
                 max_ground_m: float = math.inf) -> None:
        self.params = params
        veh = params.vehicle
        self.ground_height = ground_height or _flat_ground
        self.max_ground_m = max_ground_m if ground_height is not None else -math.inf
        A = allocation_matrix(veh)
        self._A = tuple(tuple(float(a) for a in row) for row in A)
        self._m = float(veh.mass_kg)
        self._g = float(params.gravity_m_s2)
        self._J = tuple(float(j) for j in veh.inertia_kg_m2)
        self._fmax = float(veh.max_thrust_per_rotor_n)
        self._T = float(veh.motor_time_constant_s)
        self._kd = float(params.drag_n_s_m)
        self._lag_h = None
        self._lag_a = 0.0
        self._lag_b = 0.0
        self._count = 0
        self.impact_speed_m_s = 0.0
        self.impact_vel_enu_m_s = (0.0, 0.0, 0.0)
        self.touchdowns = 0
        self._terrain = self.ground_height
        self._terrain_max_m = self.max_ground_m
        # the compiled airborne kernel (``sitl.plant_kernel``, None: the Python loop), chosen
        # here so that numba's import and cache load (~0.3 s, once per process) precede the flight
        self._kernel = _plant_kernel.kernel()
        self._kstate = self._kinp = self._kprm = None
        self.set_state((0.0, 0.0, 0.0))

    # ------------------------------------------------------------------ state
    def set_state(self, p, v=(0.0, 0.0, 0.0), R=None, w=(0.0, 0.0, 0.0), f=None,
                  landed: bool = False) -> None:
        """Set the full state (arrays or sequences; R 3x3 body FLU -> world ENU).

        ``f`` None: rotors at zero thrust. Clears a crash.
        """
        self.crashed = False
        self.ground_height = self._terrain
        self.max_ground_m = self._terrain_max_m
        self.p = tuple(float(x) for x in p)
        self.v = tuple(float(x) for x in v)
        if R is None:
            self.R = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
        else:
            self.R = tuple(float(x) for x in np.asarray(R, dtype=float).reshape(9))
        self.w = tuple(float(x) for x in w)
        self.f = (0.0, 0.0, 0.0, 0.0) if f is None else tuple(float(x) for x in f)
        self.landed = bool(landed)
        self.acc = (0.0, 0.0, 0.0)

    def crash(self, p, rest_z_m: float) -> None:
        """Crash at ``p`` (ENU, m): rotors stopped for good, velocity and body
        rate zero; the body then falls straight down to ``rest_z_m`` (the
        support height under ``p``) and rests there."""
        self.p = tuple(float(x) for x in p)
        self.v = (0.0, 0.0, 0.0)
        self.w = (0.0, 0.0, 0.0)
        self.f = (0.0, 0.0, 0.0, 0.0)
        self.acc = (0.0, 0.0, 0.0)
        self.crashed = True
        rest = float(rest_z_m)
        self.ground_height = lambda x, y: rest
        self.max_ground_m = rest
        if self.p[2] <= rest:
            self.p = (self.p[0], self.p[1], rest)
            self.landed = True

    def state_arrays(self):
        """(p, v, R 3x3, w, acc, f) as numpy arrays (copies)."""
        return (np.array(self.p), np.array(self.v), np.array(self.R).reshape(3, 3),
                np.array(self.w), np.array(self.acc), np.array(self.f))

    # ------------------------------------------------------------------- step
    def step(self, cmd, h: float, wind_enu_m_s=(0.0, 0.0, 0.0)) -> None:
        """Advance the state by ``h`` seconds with the motor commands held.

        Parameters
        ----------
        cmd : sequence of 4 floats
            Normalised motor commands (PX4 order), clipped to [0, 1];
            commanded thrust ``cmd_i * max_thrust_per_rotor_n``.
        h : float
            Step (s).
        wind_enu_m_s : 3 floats
            Air velocity (ENU, m/s), used by the drag term only.
        """
        self.advance(cmd, h, 1, wind_enu_m_s)

    def advance(self, cmd, h: float, n: int, wind_enu_m_s=(0.0, 0.0, 0.0)) -> None:
        """``n`` physics steps of ``h`` seconds with the commands and wind held
        (zero-order hold over a sensor frame). Bit-for-bit the same as ``n``
        calls of ``step``; the state lives in local variables across the steps
        because attribute and tuple traffic costs as much as the arithmetic.
        """
        fmax = self._fmax
        # --- motors: exact first-order lag, exact mean thrust over the step
        if h != self._lag_h:
            self._lag_h = h
            if self._T > 0.0:
                self._lag_a = math.exp(-h / self._T)
                self._lag_b = self._T / h * (1.0 - self._lag_a)
            else:
                self._lag_a = self._lag_b = 0.0
        la, lb = self._lag_a, self._lag_b
        c0, c1, c2, c3 = cmd if not self.crashed else (0.0, 0.0, 0.0, 0.0)
        c0 = fmax * (0.0 if c0 < 0.0 else 1.0 if c0 > 1.0 else c0)
        c1 = fmax * (0.0 if c1 < 0.0 else 1.0 if c1 > 1.0 else c1)
        c2 = fmax * (0.0 if c2 < 0.0 else 1.0 if c2 > 1.0 else c2)
        c3 = fmax * (0.0 if c3 < 0.0 else 1.0 if c3 > 1.0 else c3)
        if not self.landed:
            kern = self._kernel
            if kern is not None:
                n -= self._advance_compiled(kern, c0, c1, c2, c3, h, n, wind_enu_m_s)
                if n == 0:
                    return
        (A00, A01, A02, A03), (A10, A11, A12, A13), (A20, A21, A22, A23), (A30, A31, A32, A33) = self._A
        m, g, kd = self._m, self._g, self._kd
        mg = m * g
        Jx, Jy, Jz = self._J
        # Euler's equation inlined (a nested function costs ~1 us per call here)
        ix, iy, iz = 1.0 / Jx, 1.0 / Jy, 1.0 / Jz
        cyz, czx, cxy = Jz - Jy, Jx - Jz, Jy - Jx          # (W x J W) = (cyz wy wz, czx wz wx, cxy wx wy)
        hh = 0.5 * h
        h6 = h / 6.0
        h12 = h * h / 12.0
        hs = h * h / 6.0
        c = kd / m
        gx, gy, gz = wind_enu_m_s
        max_ground = self.max_ground_m
        count = self._count
        landed = self.landed
        f0, f1, f2, f3 = self.f
        px, py, pz = self.p
        ux, uy, uz = self.v
        wx, wy, wz = self.w
        acc = self.acc
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = self.R
        for _ in range(n):
            m0 = c0 + (f0 - c0) * lb
            m1 = c1 + (f1 - c1) * lb
            m2 = c2 + (f2 - c2) * lb
            m3 = c3 + (f3 - c3) * lb
            f0 = c0 + (f0 - c0) * la
            f1 = c1 + (f1 - c1) * la
            f2 = c2 + (f2 - c2) * la
            f3 = c3 + (f3 - c3) * la
            F = A00 * m0 + A01 * m1 + A02 * m2 + A03 * m3
            tx = A10 * m0 + A11 * m1 + A12 * m2 + A13 * m3
            ty = A20 * m0 + A21 * m1 + A22 * m2 + A23 * m3
            tz = A30 * m0 + A31 * m1 + A32 * m2 + A33 * m3

            if landed:
                # Lift-off when the vertical thrust beats the weight (drag of a
                # vehicle at rest in the wind is not enough to lift or slide it).
                if F * r22 <= mg:
                    ux = uy = uz = wx = wy = wz = 0.0
                    acc = (0.0, 0.0, 0.0)
                    continue
                landed = False

            # --- rotation: RK4 on J W' = -W x J W + tau (tau constant)
            k1x = (tx - cyz * wy * wz) * ix
            k1y = (ty - czx * wz * wx) * iy
            k1z = (tz - cxy * wx * wy) * iz
            ax, ay, az = wx + hh * k1x, wy + hh * k1y, wz + hh * k1z
            k2x = (tx - cyz * ay * az) * ix
            k2y = (ty - czx * az * ax) * iy
            k2z = (tz - cxy * ax * ay) * iz
            ax, ay, az = wx + hh * k2x, wy + hh * k2y, wz + hh * k2z
            k3x = (tx - cyz * ay * az) * ix
            k3y = (ty - czx * az * ax) * iy
            k3z = (tz - cxy * ax * ay) * iz
            ax, ay, az = wx + h * k3x, wy + h * k3y, wz + h * k3z
            k4x = (tx - cyz * ay * az) * ix
            k4y = (ty - czx * az * ax) * iy
            k4z = (tz - cxy * ax * ay) * iz
            vx1 = wx + h6 * (k1x + 2.0 * (k2x + k3x) + k4x)
            vy1 = wy + h6 * (k1y + 2.0 * (k2y + k3y) + k4y)
            vz1 = wz + h6 * (k1z + 2.0 * (k2z + k3z) + k4z)
            e1x = (tx - cyz * vy1 * vz1) * ix
            e1y = (ty - czx * vz1 * vx1) * iy
            e1z = (tz - cxy * vx1 * vy1) * iz
            thx = hh * (wx + vx1) + h12 * (k1x - e1x + wy * vz1 - wz * vy1)
            thy = hh * (wy + vy1) + h12 * (k1y - e1y + wz * vx1 - wx * vz1)
            thz = hh * (wz + vz1) + h12 * (k1z - e1z + wx * vy1 - wy * vx1)
            wx, wy, wz = vx1, vy1, vz1

            # R <- R Exp(theta): ``rotate_right`` inlined (same expressions)
            t2 = thx * thx + thy * thy + thz * thz
            if t2 > 1e-12:
                ang = math.sqrt(t2)
                a = math.sin(ang) / ang
                s = math.sin(0.5 * ang)
                b = 2.0 * s * s / t2
            else:
                a = 1.0 - t2 / 6.0
                b = 0.5 - t2 / 24.0
            xx, yy, zz = thx * thx, thy * thy, thz * thz
            xy, xz, yz = thx * thy, thx * thz, thy * thz
            E00 = 1.0 - b * (yy + zz)
            E11 = 1.0 - b * (xx + zz)
            E22 = 1.0 - b * (xx + yy)
            E01 = b * xy - a * thz
            E10 = b * xy + a * thz
            E02 = b * xz + a * thy
            E20 = b * xz - a * thy
            E12 = b * yz - a * thx
            E21 = b * yz + a * thx
            n00 = r00 * E00 + r01 * E10 + r02 * E20
            n01 = r00 * E01 + r01 * E11 + r02 * E21
            n02 = r00 * E02 + r01 * E12 + r02 * E22
            n10 = r10 * E00 + r11 * E10 + r12 * E20
            n11 = r10 * E01 + r11 * E11 + r12 * E21
            n12 = r10 * E02 + r11 * E12 + r12 * E22
            n20 = r20 * E00 + r21 * E10 + r22 * E20
            n21 = r20 * E01 + r21 * E11 + r22 * E21
            n22 = r20 * E02 + r21 * E12 + r22 * E22
            count += 1
            if count >= _REORTHO_EVERY:
                count = 0
                n00, n01, n02, n10, n11, n12, n20, n21, n22 = polar_step(
                    (n00, n01, n02, n10, n11, n12, n20, n21, n22))

            # --- translation: Simpson/RK4 quadrature, exact for constant acceleration
            Fm = F / m
            ax0 = Fm * r02
            ay0 = Fm * r12
            az0 = Fm * r22 - g
            ax1 = Fm * n02
            ay1 = Fm * n12
            az1 = Fm * n22 - g
            axm = 0.5 * (ax0 + ax1)
            aym = 0.5 * (ay0 + ay1)
            azm = 0.5 * (az0 + az1)
            r00, r01, r02, r10, r11, r12, r20, r21, r22 = n00, n01, n02, n10, n11, n12, n20, n21, n22
            if kd != 0.0:
                # Linear drag on the relative air velocity, predicted explicitly
                # (k_d/m ~ 0.1/s: no stiffness at 1 kHz).
                rx, ry, rz = ux - gx, uy - gy, uz - gz
                ax0 -= c * rx
                ay0 -= c * ry
                az0 -= c * rz
                axm -= c * (rx + hh * ax0)
                aym -= c * (ry + hh * ay0)
                azm -= c * (rz + hh * az0)
                ax1 -= c * (rx + h * axm)
                ay1 -= c * (ry + h * aym)
                az1 -= c * (rz + h * azm)
            nvx = ux + h6 * (ax0 + 4.0 * axm + ax1)
            nvy = uy + h6 * (ay0 + 4.0 * aym + ay1)
            nvz = uz + h6 * (az0 + 4.0 * azm + az1)
            npx = px + h * ux + hs * (ax0 + 2.0 * axm)
            npy = py + h * uy + hs * (ay0 + 2.0 * aym)
            npz = pz + h * uz + hs * (az0 + 2.0 * azm)

            # Terrain lookup only when low enough to touch the highest ground.
            if npz <= max_ground and nvz <= 0.0:
                zg = self.ground_height(npx, npy)
                if npz <= zg:
                    # Touch-down: at rest, level, yaw kept.
                    self.impact_speed_m_s = math.sqrt(nvx * nvx + nvy * nvy + nvz * nvz)
                    self.impact_vel_enu_m_s = (nvx, nvy, nvz)
                    self.touchdowns += 1
                    px, py, pz = npx, npy, zg
                    ux = uy = uz = wx = wy = wz = 0.0
                    acc = (0.0, 0.0, 0.0)
                    yaw = math.atan2(r10, r00) if abs(r00) + abs(r10) > 1e-9 else 0.0
                    cy_, sy_ = math.cos(yaw), math.sin(yaw)
                    r00, r01, r02, r10, r11, r12, r20, r21, r22 = cy_, -sy_, 0.0, sy_, cy_, 0.0, 0.0, 0.0, 1.0
                    landed = True
                    continue
            px, py, pz = npx, npy, npz
            ux, uy, uz = nvx, nvy, nvz
            acc = (ax1, ay1, az1)
        self.f = (f0, f1, f2, f3)
        self.p = (px, py, pz)
        self.v = (ux, uy, uz)
        self.w = (wx, wy, wz)
        self.R = (r00, r01, r02, r10, r11, r12, r20, r21, r22)
        self.acc = acc
        self.landed = landed
        self._count = count

    def _advance_compiled(self, kern, c0: float, c1: float, c2: float, c3: float, h: float, n: int,
                          wind_enu_m_s) -> int:
        """The airborne steps of ``advance`` in the compiled kernel (``sitl.plant_kernel``);
        returns how many it did (it stops where the terrain is needed)."""
        st, inp = self._kstate, self._kinp
        if st is None:
            st, inp = self._kstate, self._kinp = np.zeros(_plant_kernel.STATE_LEN), np.zeros(_plant_kernel.INP_LEN)
            self._kprm = np.array([*(a for row in self._A for a in row), self._m, self._g, self._kd, *self._J,
                                   0.0, 0.0, 0.0])
        prm = self._kprm
        prm[22] = self._lag_a
        prm[23] = self._lag_b
        st[:] = (*self.f, *self.p, *self.v, *self.w, *self.R, *self.acc, float(self._count))
        gx, gy, gz = wind_enu_m_s
        inp[:] = (c0, c1, c2, c3, h, gx, gy, gz, self.max_ground_m)
        done = kern(st, prm, inp, n)
        if done:
            t = st.tolist()
            self.f = tuple(t[0:4])
            self.p = tuple(t[4:7])
            self.v = tuple(t[7:10])
            self.w = tuple(t[10:13])
            self.R = tuple(t[13:22])
            self.acc = tuple(t[22:25])
            self._count = int(t[25])
        return done


