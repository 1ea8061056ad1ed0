"""Optional compiled plant kernel (numba, the ``fast`` extra): the airborne
physics steps of ``sitl.plant.Plant.advance``.

``Plant.advance`` (plain Python floats) is the reference. This module holds
the same loop, the same expressions in the same order, for the steps of a
frame that neither start landed nor need the terrain (the body above the
highest ground, or climbing); at the first step that would need the terrain
lookup the kernel stops *before* committing it and the Python loop does the
rest of the frame. The kernel is compiled with ``cache=True`` (the machine
code is stored next to this file, or under ``NUMBA_CACHE_DIR``), so only the
first run on a machine pays the compilation. numba without ``fastmath``
keeps IEEE semantics (no reassociation, no contraction), and ``math.sin``
and ``math.sqrt`` resolve to the same libm / instruction as CPython's:
``tests/test_plant_kernel.py`` compares the two paths bit for bit over
seeded flights and random states (documented tolerance: none, exact).

Selection (``kernel()``): the compiled kernel when ``numba`` imports and the
environment variable ``VINEYARD_GNC_NUMBA`` is not ``0``; otherwise None
(the Python loop alone).

Arrays (float64), one per plant, reused every frame:

- ``state`` (26,): f (4, N), p (3, m ENU), v (3, m/s ENU), w (3, rad/s FLU),
  R (9, row-major, body FLU -> world ENU), acc (3, m/s^2 ENU), the polar
  step counter (1);
- ``prm`` (25,): allocation matrix A (16, row-major), m (kg), g (m/s^2),
  k_d (N s/m), J (3, kg m^2), the motor lag's a and b, unused;
- ``inp`` (9,): commanded thrusts c0..c3 (N, clipped), h (s), wind (3, m/s
  ENU), the highest ground (m).
"""

from __future__ import annotations

import math
import os

ENV = "VINEYARD_GNC_NUMBA"
STATE_LEN = 26
PRM_LEN = 25
INP_LEN = 9
#: polar (re-orthogonalisation) step every this many steps: ``sitl.plant._REORTHO_EVERY``
REORTHO_EVERY = 64


def airborne_steps(s, prm, inp, n):  # noqa: C901 - one loop, kept in step with Plant.advance
    """Up to ``n`` airborne steps in place on ``state`` ``s``; returns the number done.

    Stops before a step whose end is at or below the highest ground while
    descending (``Plant.advance`` then looks the terrain up).
    """
    A00, A01, A02, A03 = prm[0], prm[1], prm[2], prm[3]
    A10, A11, A12, A13 = prm[4], prm[5], prm[6], prm[7]
    A20, A21, A22, A23 = prm[8], prm[9], prm[10], prm[11]
    A30, A31, A32, A33 = prm[12], prm[13], prm[14], prm[15]
    m, g, kd = prm[16], prm[17], prm[18]
    Jx, Jy, Jz = prm[19], prm[20], prm[21]
    la, lb = prm[22], prm[23]
    c0, c1, c2, c3 = inp[0], inp[1], inp[2], inp[3]
    h = inp[4]
    gx, gy, gz = inp[5], inp[6], inp[7]
    max_ground = inp[8]
    ix, iy, iz = 1.0 / Jx, 1.0 / Jy, 1.0 / Jz
    cyz, czx, cxy = Jz - Jy, Jx - Jz, Jy - Jx
    hh = 0.5 * h
    h6 = h / 6.0
    h12 = h * h / 12.0
    hs = h * h / 6.0
    c = kd / m
    f0, f1, f2, f3 = s[0], s[1], s[2], s[3]
    px, py, pz = s[4], s[5], s[6]
    ux, uy, uz = s[7], s[8], s[9]
    wx, wy, wz = s[10], s[11], s[12]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = s[13], s[14], s[15], s[16], s[17], s[18], s[19], s[20], s[21]
    ac0, ac1, ac2 = s[22], s[23], s[24]
    count = int(s[25])
    done = 0
    for _ in range(n):
        m0 = c0 + (f0 - c0) * lb
        m1 = c1 + (f1 - c1) * lb
        m2 = c2 + (f2 - c2) * lb
        m3 = c3 + (f3 - c3) * lb
        nf0 = c0 + (f0 - c0) * la
        nf1 = c1 + (f1 - c1) * la
        nf2 = c2 + (f2 - c2) * la
        nf3 = c3 + (f3 - c3) * la
        F = A00 * m0 + A01 * m1 + A02 * m2 + A03 * m3
        tx = A10 * m0 + A11 * m1 + A12 * m2 + A13 * m3
        ty = A20 * m0 + A21 * m1 + A22 * m2 + A23 * m3
        tz = A30 * m0 + A31 * m1 + A32 * m2 + A33 * m3

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

        t2 = thx * thx + thy * thy + thz * thz
        if t2 > 1e-12:
            ang = math.sqrt(t2)
            a = math.sin(ang) / ang
            sn = math.sin(0.5 * ang)
            b = 2.0 * sn * sn / t2
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
        ncount = count + 1
        if ncount >= REORTHO_EVERY:
            ncount = 0
            # sitl.plant.polar_step, inlined
            s00 = n00 * n00 + n10 * n10 + n20 * n20
            s11 = n01 * n01 + n11 * n11 + n21 * n21
            s22 = n02 * n02 + n12 * n12 + n22 * n22
            s01 = n00 * n01 + n10 * n11 + n20 * n21
            s02 = n00 * n02 + n10 * n12 + n20 * n22
            s12 = n01 * n02 + n11 * n12 + n21 * n22
            q00, q11, q22 = 1.5 - 0.5 * s00, 1.5 - 0.5 * s11, 1.5 - 0.5 * s22
            q01, q02, q12 = -0.5 * s01, -0.5 * s02, -0.5 * s12
            n00, n01, n02, n10, n11, n12, n20, n21, n22 = (
                n00 * q00 + n01 * q01 + n02 * q02, n00 * q01 + n01 * q11 + n02 * q12,
                n00 * q02 + n01 * q12 + n02 * q22,
                n10 * q00 + n11 * q01 + n12 * q02, n10 * q01 + n11 * q11 + n12 * q12,
                n10 * q02 + n11 * q12 + n12 * q22,
                n20 * q00 + n21 * q01 + n22 * q02, n20 * q01 + n21 * q11 + n22 * q12,
                n20 * q02 + n21 * q12 + n22 * q22)

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
        if kd != 0.0:
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
        if npz <= max_ground and nvz <= 0.0:
            break   # the terrain is needed: Plant.advance redoes this step
        f0, f1, f2, f3 = nf0, nf1, nf2, nf3
        wx, wy, wz = vx1, vy1, vz1
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = n00, n01, n02, n10, n11, n12, n20, n21, n22
        count = ncount
        px, py, pz = npx, npy, npz
        ux, uy, uz = nvx, nvy, nvz
        ac0, ac1, ac2 = ax1, ay1, az1
        done += 1
    s[0], s[1], s[2], s[3] = f0, f1, f2, f3
    s[4], s[5], s[6] = px, py, pz
    s[7], s[8], s[9] = ux, uy, uz
    s[10], s[11], s[12] = wx, wy, wz
    s[13], s[14], s[15], s[16], s[17], s[18], s[19], s[20], s[21] = r00, r01, r02, r10, r11, r12, r20, r21, r22
    s[22], s[23], s[24] = ac0, ac1, ac2
    s[25] = float(count)
    return done


_compiled = None
_tried = False


def kernel():
    """The compiled ``airborne_steps`` (numba, ``cache=True``), or None: numba not
    installed, or ``VINEYARD_GNC_NUMBA=0``. Compiled (or loaded from the cache) once."""
    global _compiled, _tried
    if os.environ.get(ENV, "1").strip() == "0":
        return None
    if not _tried:
        _tried = True
        try:
            import numba
        except ImportError:
            return None
        _compiled = numba.njit(cache=True, nogil=True)(airborne_steps)
    return _compiled
