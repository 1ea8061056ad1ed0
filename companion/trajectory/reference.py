"""The reference the vehicle flies, phase by phase (pure: times in, samples out).

``RefSample`` is one reference sample (ENU, SI). ``TrajectoryWindow`` evaluates
the planned trajectory on the sensor-frame grid on demand, a short window at a
time (vectorised), so memory does not grow with the flight's length: the
trajectory is closed form (``companion.trajectory.Trajectory``), nothing is
cached beyond the window. ``smooth_segment`` gives the take-off's rest-to-rest
segments; ``setpoint_yaw_enu`` the heading that goes with a pointing direction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mavcore.vehicle import GRAVITY_M_S2


@dataclass(frozen=True, slots=True)
class RefSample:
    """A reference sample: position and its four derivatives (ENU) and the pointing direction.

    ``p`` m, ``v`` m/s, ``a`` m/s^2, ``jerk`` m/s^3, ``snap`` m/s^4, ``s``
    unit pointing vector (eq. 21); all float tuples (3,). ``target``: the
    pointing target S_p handed to the controller (None: the mission's).
    """

    p: tuple
    v: tuple
    a: tuple
    jerk: tuple
    snap: tuple
    s: tuple
    target: tuple | None = None


_Z3 = (0.0, 0.0, 0.0)


def at_rest(sample: RefSample) -> RefSample:
    """``sample``'s position and pointing with zero derivatives (a hover reference)."""
    return RefSample(sample.p, _Z3, _Z3, _Z3, _Z3, sample.s, sample.target)


def smooth_segment(p0, p1, duration_s: float, t_s: float):
    """Rest-to-rest segment from ``p0`` to ``p1`` (ENU, m) in ``duration_s``.

    The 7th-order smoothstep ``sigma(tau) = 35 tau^4 - 84 tau^5 + 70 tau^6 -
    20 tau^7`` has zero velocity, acceleration and jerk at both ends, so the
    controller's feed-forward (which uses jerk and snap, eq. 31) is
    continuous into and out of the segment. Peak speed ``35/16 |p1 - p0| /
    duration_s`` at mid-time.

    Returns
    -------
    (p, v, a, jerk, snap) : five float tuples (3,), ENU SI units, at ``t_s``
    (clamped to [0, duration_s]).
    """
    T = float(duration_s)
    tau = min(max(t_s / T, 0.0), 1.0)
    t2, t3 = tau * tau, tau * tau * tau
    t4 = t2 * t2
    s0 = t4 * (35.0 - 84.0 * tau + 70.0 * t2 - 20.0 * t3)
    s1 = t3 * (140.0 - 420.0 * tau + 420.0 * t2 - 140.0 * t3) / T
    s2 = t2 * (420.0 - 1680.0 * tau + 2100.0 * t2 - 840.0 * t3) / T ** 2
    s3 = tau * (840.0 - 5040.0 * tau + 8400.0 * t2 - 4200.0 * t3) / T ** 3
    s4 = (840.0 - 10080.0 * tau + 25200.0 * t2 - 16800.0 * t3) / T ** 4
    d = (p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2])
    return (
        (p0[0] + s0 * d[0], p0[1] + s0 * d[1], p0[2] + s0 * d[2]),
        (s1 * d[0], s1 * d[1], s1 * d[2]),
        (s2 * d[0], s2 * d[1], s2 * d[2]),
        (s3 * d[0], s3 * d[1], s3 * d[2]),
        (s4 * d[0], s4 * d[1], s4 * d[2]),
    )


def segments_sample(segments, t_s: float):
    """``smooth_segment`` of rest-to-rest segments ``[(p0, p1, duration_s), ...]`` flown
    back to back, ``t_s`` after the first one's start (past the last: its end, at rest)."""
    rest = t_s
    for p0, p1, T in segments:
        if rest < T:
            break
        rest -= T
    else:
        rest = T      # past the last segment: its end
    return smooth_segment(p0, p1, T, rest)


def pointing_at(p, target) -> tuple:
    """Unit vector from ``p`` toward ``target`` (eq. 21), ENU; +y if they coincide."""
    u = (target[0] - p[0], target[1] - p[1], target[2] - p[2])
    n = math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
    return (0.0, 1.0, 0.0) if n < 1e-9 else (u[0] / n, u[1] / n, u[2] / n)


def setpoint_yaw_enu(s, a_enu_m_s2, gravity_m_s2: float = GRAVITY_M_S2) -> float:
    """Heading (ENU, rad from east, CCW) of the body x axis the controller would command.

    With ``b3d`` the feed-forward thrust direction ``unit(a + g e3)``,
    ``b2d = unit(s - (s.b3d) b3d)`` (eq. 22) and ``b1d = b2d x b3d``; the yaw
    is the heading of ``b1d``. Pointing straight along b3d falls back to
    the heading of +y (b1d = east).
    """
    b3 = (a_enu_m_s2[0], a_enu_m_s2[1], a_enu_m_s2[2] + gravity_m_s2)
    n = math.sqrt(b3[0] ** 2 + b3[1] ** 2 + b3[2] ** 2)
    b3 = (b3[0] / n, b3[1] / n, b3[2] / n)
    c = s[0] * b3[0] + s[1] * b3[1] + s[2] * b3[2]
    b2 = (s[0] - c * b3[0], s[1] - c * b3[1], s[2] - c * b3[2])
    if b2[0] ** 2 + b2[1] ** 2 + b2[2] ** 2 < 1e-12:
        return 0.0
    b1 = (b2[1] * b3[2] - b2[2] * b3[1], b2[2] * b3[0] - b2[0] * b3[2], b2[0] * b3[1] - b2[1] * b3[0])
    return math.atan2(b1[1], b1[0])


def climb_duration_s(distance_m: float, speed_m_s: float, min_s: float = 3.0) -> float:
    """Duration of a smooth segment whose peak speed (35/16 of the mean) is ``speed_m_s``."""
    return max(min_s, 35.0 / 16.0 * distance_m / speed_m_s)


class TrajectoryWindow:
    """The trajectory on the frame grid ``t0 + k dt``, evaluated a window at a time.

    Parameters
    ----------
    trajectory : companion.trajectory.Trajectory
        Closed-form reference (ENU).
    dt_s : float
        Sensor frame period (s).
    target_enu_m : (3,) sequence
        Pointing target S_p, used when the trajectory carries no pointing.
    window_frames : int
        Frames evaluated per window (vectorised); the only samples held.

    Notes
    -----
    ``sample(k)`` for frame k (k < 0 is frame 0, k beyond the end the last
    frame, whose time is ``tf``). Moving forward costs one vectorised
    evaluation per window; jumping back re-evaluates the window there.
    Memory is ``O(window_frames)`` whatever the trajectory's duration.
    """

    def __init__(self, trajectory, dt_s: float, target_enu_m, window_frames: int = 500) -> None:
        if not dt_s > 0.0:
            raise ValueError("dt_s must be > 0")
        self.traj = trajectory
        self.dt_s = float(dt_s)
        self.t0 = float(trajectory.t0)
        self.tf = float(trajectory.tf)
        self.n_frames = int(math.floor((self.tf - self.t0) / self.dt_s + 1e-9)) + 2
        self.target = tuple(float(x) for x in target_enu_m)
        self.window = max(1, int(window_frames))
        self._lo = 0
        self._buf: list[RefSample] = []

    @property
    def duration_s(self) -> float:
        return self.tf - self.t0

    def first(self) -> RefSample:
        return self.sample(0)

    def last(self) -> RefSample:
        return self.sample(self.n_frames - 1)

    def sample(self, k: int) -> RefSample:
        """Reference at frame ``k`` (clamped to the trajectory)."""
        k = min(max(int(k), 0), self.n_frames - 1)
        i = k - self._lo
        if not 0 <= i < len(self._buf):
            self._fill(k)
            i = 0
        return self._buf[i]

    def _fill(self, k: int) -> None:
        hi = min(k + self.window, self.n_frames)
        times = np.minimum(self.t0 + self.dt_s * np.arange(k, hi), self.tf)
        smp = self.traj.sample(times)
        if smp.pointing is not None:
            s = smp.pointing
        else:
            d = np.asarray(self.target) - smp.p
            s = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
        self._buf = [RefSample(*(tuple(r) for r in row)) for row in zip(
            smp.p.tolist(), smp.v.tolist(), smp.a.tolist(), smp.jerk.tolist(), smp.snap.tolist(), s.tolist())]
        self._lo = k
