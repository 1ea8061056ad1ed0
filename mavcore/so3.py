"""The one set of small SO(3) and vector helpers (the controller's and the SITL's), on float tuples.

World ENU / body FLU; a vector is a 3-tuple of floats, a rotation a row-major
9-tuple (``R[3 i + j]``), body to world. The hot paths (the controller, the
observer) avoid numpy: on 3-vectors its call overhead is larger than the
arithmetic. Everything here is pure.

- vectors: :func:`cross`, :func:`dot`, :func:`unit` / :func:`unit3` (ValueError
  on a zero or non-finite vector), :func:`reject`, :func:`unit_d2` (a unit
  vector and its first two time derivatives);
- rotations: :func:`so3_exp` (Rodrigues), :func:`mat_mul`, :func:`mat_apply`,
  :func:`mat_apply_t`, :func:`orthonormalise`, :func:`rotate_right` (``R Exp(theta)``,
  the plant's and estimator's attitude step) and :func:`polar_step` (one Newton step to
  the nearest rotation; ``sitl.plant_kernel`` compiles copies of both);
- two vector pairs ``b_i = R^T r_i`` (TRIAD): :func:`triad_rotation` (R),
  :func:`body_coordinates` (``R^T w``), :func:`thrust_axis_estimate` (``R e3``).
"""

from __future__ import annotations

import math

Vec3 = tuple[float, float, float]
Mat3 = tuple[float, float, float, float, float, float, float, float, float]   # row-major


# --- vectors ------------------------------------------------------------------


def cross(a, b) -> Vec3:
    """``a x b`` of two 3-sequences."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def dot(a, b) -> float:
    """``a . b`` of two 3-sequences."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def unit_d2(u, ud, udd):
    """Unit vector n = u/|u| and its first two time derivatives.

    Returns (n, n_dot, n_ddot), each (3,): ``n_dot = (I - n n^T) u_dot/|u|``, ``n_ddot =
    (u_ddot - 2 n_dot (n.u_dot) - n (n_dot.u_dot + n.u_ddot))/|u|`` (``companion.control.geometric``).
    """
    r = math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
    n = (u[0] / r, u[1] / r, u[2] / r)
    rd = n[0] * ud[0] + n[1] * ud[1] + n[2] * ud[2]
    nd = ((ud[0] - n[0] * rd) / r, (ud[1] - n[1] * rd) / r, (ud[2] - n[2] * rd) / r)
    rdd = nd[0] * ud[0] + nd[1] * ud[1] + nd[2] * ud[2] + n[0] * udd[0] + n[1] * udd[1] + n[2] * udd[2]
    ndd = ((udd[0] - 2.0 * nd[0] * rd - n[0] * rdd) / r,
           (udd[1] - 2.0 * nd[1] * rd - n[1] * rdd) / r,
           (udd[2] - 2.0 * nd[2] * rd - n[2] * rdd) / r)
    return n, nd, ndd


def unit(x: float, y: float, z: float) -> Vec3:
    """``(x, y, z) / |(x, y, z)|``. Raises ValueError on a zero or non-finite vector."""
    n = math.sqrt(x * x + y * y + z * z)
    if not n > 0.0:
        raise ValueError("cannot normalise a zero (or non-finite) vector")
    return (x / n, y / n, z / n)


def unit3(v) -> Vec3:
    """``v / |v|`` as a float tuple (3,). Raises ValueError on a zero vector."""
    x, y, z = float(v[0]), float(v[1]), float(v[2])
    n = math.sqrt(x * x + y * y + z * z)
    if not n > 0.0:
        raise ValueError("cannot normalise a zero (or non-finite) vector")
    return (x / n, y / n, z / n)


def reject(v: Vec3, n: Vec3) -> Vec3:
    """unit(v - (v.n) n): the direction of v normal to the unit vector n."""
    c = v[0] * n[0] + v[1] * n[1] + v[2] * n[2]
    return unit3((v[0] - c * n[0], v[1] - c * n[1], v[2] - c * n[2]))


# --- rotations ----------------------------------------------------------------


def so3_exp(wx: float, wy: float, wz: float) -> Mat3:
    """``exp(S(w))`` (Rodrigues), row-major 9-tuple, for a rotation vector w (rad)."""
    th2 = wx * wx + wy * wy + wz * wz
    if th2 < 1e-16:
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        th = math.sqrt(th2)
        a, b = math.sin(th) / th, (1.0 - math.cos(th)) / th2
    xx, yy, zz, xy, xz, yz = wx * wx, wy * wy, wz * wz, wx * wy, wx * wz, wy * wz
    return (1.0 - b * (yy + zz), -a * wz + b * xy, a * wy + b * xz,
            a * wz + b * xy, 1.0 - b * (xx + zz), -a * wx + b * yz,
            -a * wy + b * xz, a * wx + b * yz, 1.0 - b * (xx + yy))


def mat_mul(A: Mat3, B: Mat3) -> Mat3:
    """``A B`` of two row-major 9-tuples."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = A
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = B
    return (a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
            a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
            a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8)


def mat_apply(A: Mat3, x: float, y: float, z: float) -> Vec3:
    """``A (x, y, z)``."""
    return (A[0] * x + A[1] * y + A[2] * z, A[3] * x + A[4] * y + A[5] * z, A[6] * x + A[7] * y + A[8] * z)


def mat_apply_t(A: Mat3, x: float, y: float, z: float) -> Vec3:
    """``A^T (x, y, z)``."""
    return (A[0] * x + A[3] * y + A[6] * z, A[1] * x + A[4] * y + A[7] * z, A[2] * x + A[5] * y + A[8] * z)


def orthonormalise(R: Mat3) -> Mat3:
    """The nearest-by-construction rotation: Gram-Schmidt on the columns x, y; z = x cross y."""
    x = unit(R[0], R[3], R[6])
    c = x[0] * R[1] + x[1] * R[4] + x[2] * R[7]
    y = unit(R[1] - c * x[0], R[4] - c * x[1], R[7] - c * x[2])
    z = (x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0])
    return (x[0], y[0], z[0], x[1], y[1], z[1], x[2], y[2], z[2])


def triad_rotation(b1, b2, r1, r2) -> Mat3:
    """``R`` (body -> world, row-major 9-tuple) from two vector pairs ``b_i = R^T r_i`` (TRIAD).

    Pair 1 is matched exactly, pair 2 only fixes the rotation about it.

    Parameters
    ----------
    b1, b2 : sequence (3,)
        Body-frame directions (any length > 0, not collinear).
    r1, r2 : sequence (3,)
        Their world directions.

    Returns
    -------
    tuple (9,)
        ``R = [r1 m_r n_r] [b1 m_b n_b]^T`` with ``m = unit(1 x 2)``, ``n = 1 x m``.
    """
    def frame(u, w):
        u = unit(float(u[0]), float(u[1]), float(u[2]))
        m = unit(u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0])
        n = (u[1] * m[2] - u[2] * m[1], u[2] * m[0] - u[0] * m[2], u[0] * m[1] - u[1] * m[0])
        return u, m, n

    bu, bm, bn = frame(b1, b2)
    ru, rm, rn = frame(r1, r2)
    return tuple(ru[i] * bu[j] + rm[i] * bm[j] + rn[i] * bn[j] for i in range(3) for j in range(3))


def triad_frames(b1, b2, r1, r2) -> tuple:
    """The TRIAD frames of two vector pairs: ``(m_b, n_b, m_r, n_r)`` with ``m = unit(1 x 2)``, ``n = 1 x m``.

    ``b1``, ``r1`` must be unit vectors (pair 1 is matched exactly); then
    ``R = [r1 m_r n_r] [b1 m_b n_b]^T``. Raises ValueError when a pair's
    vectors are collinear (or not finite).
    """
    b1x, b1y, b1z = b1
    b2x, b2y, b2z = b2
    r1x, r1y, r1z = r1
    r2x, r2y, r2z = r2
    x, y, z = b1y * b2z - b1z * b2y, b1z * b2x - b1x * b2z, b1x * b2y - b1y * b2x
    n = math.sqrt(x * x + y * y + z * z)
    if not n > 0.0:
        raise ValueError("cannot normalise a zero (or non-finite) vector")
    mbx, mby, mbz = x / n, y / n, z / n
    x, y, z = r1y * r2z - r1z * r2y, r1z * r2x - r1x * r2z, r1x * r2y - r1y * r2x
    n = math.sqrt(x * x + y * y + z * z)
    if not n > 0.0:
        raise ValueError("cannot normalise a zero (or non-finite) vector")
    mrx, mry, mrz = x / n, y / n, z / n
    return ((mbx, mby, mbz), (b1y * mbz - b1z * mby, b1z * mbx - b1x * mbz, b1x * mby - b1y * mbx),
            (mrx, mry, mrz), (r1y * mrz - r1z * mry, r1z * mrx - r1x * mrz, r1x * mry - r1y * mrx))


def triad_to_body(w, b1, r1, frames) -> Vec3:
    """``R^T w`` from pair 1 and its :func:`triad_frames`."""
    mb, nb, mr, nr = frames
    w0, w1, w2 = w
    c1 = w0 * r1[0] + w1 * r1[1] + w2 * r1[2]
    c2 = w0 * mr[0] + w1 * mr[1] + w2 * mr[2]
    c3 = w0 * nr[0] + w1 * nr[1] + w2 * nr[2]
    return (c1 * b1[0] + c2 * mb[0] + c3 * nb[0], c1 * b1[1] + c2 * mb[1] + c3 * nb[1],
            c1 * b1[2] + c2 * mb[2] + c3 * nb[2])


def triad_to_body3(w1, w2, w3, b1, r1, frames) -> tuple:
    """:func:`triad_to_body` of three world vectors at once: ``(R^T w1, R^T w2, R^T w3)``."""
    mb, nb, mr, nr = frames
    b10, b11, b12 = b1
    r10, r11, r12 = r1
    mb0, mb1, mb2 = mb
    nb0, nb1, nb2 = nb
    mr0, mr1, mr2 = mr
    nr0, nr1, nr2 = nr
    out = []
    for w0, w1_, w2_ in (w1, w2, w3):
        c1 = w0 * r10 + w1_ * r11 + w2_ * r12
        c2 = w0 * mr0 + w1_ * mr1 + w2_ * mr2
        c3 = w0 * nr0 + w1_ * nr1 + w2_ * nr2
        out.append((c1 * b10 + c2 * mb0 + c3 * nb0, c1 * b11 + c2 * mb1 + c3 * nb1, c1 * b12 + c2 * mb2 + c3 * nb2))
    return tuple(out)


def triad_body_z(b1, r1, frames) -> Vec3:
    """``R e3`` (the body z axis in the world) from pair 1 and its :func:`triad_frames`."""
    mb, nb, mr, nr = frames
    return (r1[0] * b1[2] + mr[0] * mb[2] + nr[0] * nb[2], r1[1] * b1[2] + mr[1] * mb[2] + nr[1] * nb[2],
            r1[2] * b1[2] + mr[2] * mb[2] + nr[2] * nb[2])


def body_coordinates(w, b1, b2, r1, r2) -> Vec3:
    """``R^T w``: a world vector's body coordinates from two vector pairs (TRIAD).

    Parameters
    ----------
    w : sequence (3,)
        World vector (ENU).
    b1, b2 : sequence (3,)
        Body unit vectors ``b_i = R^T r_i``; r1, r2 : their world directions.
        Pair 1 is matched exactly, pair 2 completes the frame.

    Returns
    -------
    tuple (3,)
        ``R^T w`` (body FLU), exact when the pairs are.
    """
    return triad_to_body(w, b1, r1, triad_frames(b1, b2, r1, r2))


def thrust_axis_estimate(b1, b2, r1, r2) -> Vec3:
    """``R e3`` (world) from two vector pairs by TRIAD (pair 1 exact, pair 2 completes).

    Parameters
    ----------
    b1, b2 : sequence (3,)
        Body unit vectors; r1, r2 : sequence (3,) their world directions.

    Returns
    -------
    tuple (3,)
        Estimate of the body z axis in the world frame (unit).
    """
    return triad_body_z(b1, r1, triad_frames(b1, b2, r1, r2))


def rotate_right(R, thx: float, thy: float, thz: float):
    """``R Exp(theta)`` for a row-major 9-tuple R and a rotation vector theta
    (rad, body frame): Rodrigues' formula, plain floats.

    ``Exp(theta) = I + a [theta]x + b [theta]x^2`` with ``a = sin|t|/|t|``
    and ``b = (1 - cos|t|)/|t|^2`` written as ``2 sin^2(|t|/2)/|t|^2`` (no
    cancellation for small angles).
    """
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
    t2 = thx * thx + thy * thy + thz * thz
    if t2 > 1e-12:
        ang = math.sqrt(t2)
        a = math.sin(ang) / ang
        s = math.sin(0.5 * ang)
        b = 2.0 * s * s / t2
    else:  # Taylor series, exact to rounding for |theta| < 1e-6
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


def polar_step(R):
    """One Newton step toward the nearest rotation, ``R (3 I - R^T R) / 2``
    (row-major 9-tuples); quadratic convergence, so one step per 64 physics
    steps removes the rounding drift of ``rotate_right``."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
    # S = R^T R (symmetric)
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
