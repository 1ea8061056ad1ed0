"""Optional compiled plant kernel (numba, the ``fast`` extra): the airborne
physics steps of ``sitl.plant.Plant.advance``.

``Plant.advance`` (plain Python floats) is the reference. This module holds
the same loop, the same expressions in the same order, for the steps of a
frame that neither start landed nor need the terrain (the body above the
highest ground, or climbing); at the first step that would need the terrain
lookup the kernel stops *before* committing it and the Python loop does the
rest of the frame. The kernel is compiled with ``cache=True`` (the machine
code is stored next to this file, or under ``NUMBA_CACHE_DIR``), so only the
first run on a machine pays the compilation (~5 s); every process pays
numba's import and the cache load (~0.25 + 0.4 s of CPU, BENCHMARKS.md
"h16-speed"), in ``kernel()``, when the first plant is built. The step is
split into the parts ``_body_rates``, ``_rotate_right``, ``_polar_step`` and
``_translate`` (plain Python here; ``kernel()`` compiles them first, and the
compiled kernel calls the compiled parts). numba without ``fastmath``
keeps IEEE semantics (no reassociation, no contraction), and ``math.sin``
and ``math.sqrt`` resolve to the same libm / instruction as CPython's:
``tests/test_plant_kernel.py`` compares the two paths bit for bit over
seeded flights and random states (documented tolerance: none, exact).

Selection (``kernel()``): the compiled kernel when ``numba`` imports and the
environment variable ``VINEYARD_GNC_NUMBA`` is ``1``; otherwise None (the
Python loop alone). Opt-in: numba's import and cache load cost ~0.7 s per
process, repaid only after ~30,000 frames (a long-lived campaign worker, not
a short flight or a test); ``companion campaign`` turns it on in its workers.

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


def _body_rates(wx, wy, wz, tx, ty, tz, J, h):
    """RK4 on J W' = -W x J W + tau (tau constant) and the Magnus rotation vector
    of the step: ``Plant.advance``'s expressions. Returns (W1 (3), theta (3))."""
    Jx, Jy, Jz = J
    ix, iy, iz = 1.0 / Jx, 1.0 / Jy, 1.0 / Jz
    cyz, czx, cxy = Jz - Jy, Jx - Jz, Jy - Jx
    hh = 0.5 * h
    h6 = h / 6.0
    h12 = h * h / 12.0
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
    return (vx1, vy1, vz1), (thx, thy, thz)


def _rotate_right(R, thx, thy, thz):
    """``mavcore.so3.rotate_right``: R Exp(theta), Rodrigues, row-major 9-tuples."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
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
    return (r00 * E00 + r01 * E10 + r02 * E20, r00 * E01 + r01 * E11 + r02 * E21,
            r00 * E02 + r01 * E12 + r02 * E22,
            r10 * E00 + r11 * E10 + r12 * E20, r10 * E01 + r11 * E11 + r12 * E21,
            r10 * E02 + r11 * E12 + r12 * E22,
            r20 * E00 + r21 * E10 + r22 * E20, r20 * E01 + r21 * E11 + r22 * E21,
            r20 * E02 + r21 * E12 + r22 * E22)


def _polar_step(R):
    """``mavcore.so3.polar_step``: one Newton step toward the nearest rotation."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
    s00 = r00 * r00 + r10 * r10 + r20 * r20
    s11 = r01 * r01 + r11 * r11 + r21 * r21
    s22 = r02 * r02 + r12 * r12 + r22 * r22
    s01 = r00 * r01 + r10 * r11 + r20 * r21
    s02 = r00 * r02 + r10 * r12 + r20 * r22
    s12 = r01 * r02 + r11 * r12 + r21 * r22
    m00, m11, m22 = 1.5 - 0.5 * s00, 1.5 - 0.5 * s11, 1.5 - 0.5 * s22
    m01, m02, m12 = -0.5 * s01, -0.5 * s02, -0.5 * s12
    return (r00 * m00 + r01 * m01 + r02 * m02, r00 * m01 + r01 * m11 + r02 * m12,
            r00 * m02 + r01 * m12 + r02 * m22,
            r10 * m00 + r11 * m01 + r12 * m02, r10 * m01 + r11 * m11 + r12 * m12,
            r10 * m02 + r11 * m12 + r12 * m22,
            r20 * m00 + r21 * m01 + r22 * m02, r20 * m01 + r21 * m11 + r22 * m12,
            r20 * m02 + r21 * m12 + r22 * m22)


def _translate(p, u, Fm, r_start, r_end, wind, m_g_c, h):
    """Simpson/RK4 quadrature of p, v with the thrust axis at the start and end of
    the step, ``m_g_c`` = (g, k_d / m, k_d): linear drag on the air velocity.
    Returns (p1, v1, acc1)."""
    px, py, pz = p
    ux, uy, uz = u
    g, c, kd = m_g_c
    gx, gy, gz = wind
    hh = 0.5 * h
    h6 = h / 6.0
    hs = h * h / 6.0
    ax0 = Fm * r_start[0]
    ay0 = Fm * r_start[1]
    az0 = Fm * r_start[2] - g
    ax1 = Fm * r_end[0]
    ay1 = Fm * r_end[1]
    az1 = Fm * r_end[2] - g
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
    v1 = (ux + h6 * (ax0 + 4.0 * axm + ax1), uy + h6 * (ay0 + 4.0 * aym + ay1), uz + h6 * (az0 + 4.0 * azm + az1))
    p1 = (px + h * ux + hs * (ax0 + 2.0 * axm), py + h * uy + hs * (ay0 + 2.0 * aym),
          pz + h * uz + hs * (az0 + 2.0 * azm))
    return p1, v1, (ax1, ay1, az1)


def airborne_steps(s, prm, inp, n):
    """Up to ``n`` airborne steps in place on ``state`` ``s``; returns the number done.

    Stops before a step whose end is at or below the highest ground while
    descending (``Plant.advance`` then looks the terrain up).
    """
    A = (prm[0], prm[1], prm[2], prm[3], prm[4], prm[5], prm[6], prm[7],
         prm[8], prm[9], prm[10], prm[11], prm[12], prm[13], prm[14], prm[15])
    m = prm[16]
    m_g_c = (prm[17], prm[18] / m, prm[18])
    J = (prm[19], prm[20], prm[21])
    la, lb = prm[22], prm[23]
    c0, c1, c2, c3 = inp[0], inp[1], inp[2], inp[3]
    h = inp[4]
    wind = (inp[5], inp[6], inp[7])
    max_ground = inp[8]
    f0, f1, f2, f3 = s[0], s[1], s[2], s[3]
    p = (s[4], s[5], s[6])
    u = (s[7], s[8], s[9])
    w = (s[10], s[11], s[12])
    R = (s[13], s[14], s[15], s[16], s[17], s[18], s[19], s[20], s[21])
    acc = (s[22], s[23], s[24])
    count = int(s[25])
    done = 0
    for _ in range(n):
        # motors: exact first-order lag, exact mean thrust over the step
        m0 = c0 + (f0 - c0) * lb
        m1 = c1 + (f1 - c1) * lb
        m2 = c2 + (f2 - c2) * lb
        m3 = c3 + (f3 - c3) * lb
        F = A[0] * m0 + A[1] * m1 + A[2] * m2 + A[3] * m3
        tx = A[4] * m0 + A[5] * m1 + A[6] * m2 + A[7] * m3
        ty = A[8] * m0 + A[9] * m1 + A[10] * m2 + A[11] * m3
        tz = A[12] * m0 + A[13] * m1 + A[14] * m2 + A[15] * m3
        w1, th = _body_rates(w[0], w[1], w[2], tx, ty, tz, J, h)
        R1 = _rotate_right(R, th[0], th[1], th[2])
        count1 = count + 1
        if count1 >= REORTHO_EVERY:
            count1 = 0
            R1 = _polar_step(R1)
        p1, u1, acc1 = _translate(p, u, F / m, (R[2], R[5], R[8]), (R1[2], R1[5], R1[8]), wind, m_g_c, h)
        if p1[2] <= max_ground and u1[2] <= 0.0:
            break   # the terrain is needed: Plant.advance redoes this step
        f0, f1, f2, f3 = c0 + (f0 - c0) * la, c1 + (f1 - c1) * la, c2 + (f2 - c2) * la, c3 + (f3 - c3) * la
        p, u, w, R, acc, count = p1, u1, w1, R1, acc1, count1
        done += 1
    s[0], s[1], s[2], s[3] = f0, f1, f2, f3
    s[4], s[5], s[6] = p
    s[7], s[8], s[9] = u
    s[10], s[11], s[12] = w
    s[13], s[14], s[15], s[16], s[17], s[18], s[19], s[20], s[21] = R
    s[22], s[23], s[24] = acc
    s[25] = float(count)
    return done


#: the step's parts, compiled before ``airborne_steps`` (numba resolves them as globals)
_PARTS = ("_body_rates", "_rotate_right", "_polar_step", "_translate")


_compiled = None
_tried = False


def kernel():
    """The compiled ``airborne_steps`` (numba, ``cache=True``), or None: numba not
    installed, or ``VINEYARD_GNC_NUMBA`` not ``1``. Compiled (or loaded from the cache) once."""
    global _compiled, _tried
    if os.environ.get(ENV, "0").strip() != "1":
        return None
    if not _tried:
        _tried = True
        try:
            import numba
        except ImportError:
            return None
        jit = numba.njit(cache=True, nogil=True)
        g = globals()
        for name in _PARTS:    # the kernel calls the compiled parts (same expressions, same order)
            g[name] = jit(g[name])
        compiled = jit(airborne_steps)
        # The first call loads the machine code from the cache (compiles it on a new
        # machine) and initialises numba's CPU target: ~0.4 s of CPU, paid here, at
        # start-up, rather than in a flight's first frame. Zero steps: nothing moves.
        import numpy as np

        compiled(np.zeros(STATE_LEN), np.ones(PRM_LEN), np.zeros(INP_LEN), 0)
        _compiled = compiled
    return _compiled
