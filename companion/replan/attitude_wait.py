"""A reading waits for the attitude of its own time.

Over a lossy link the vehicle's ATTITUDE arrives late or not at all (20 %
loss leaves gaps of 200 ms in a 50 Hz stream). A DISTANCE_SENSOR reading
placed with an attitude carried that far with the last body rates was off
by up to 4.5 deg of tilt; a beam looking 10 deg down then puts the ground
5 m ahead 0.4 m above it: a phantom obstacle on a clear field.

The rule: a reading is placed with an attitude measured no more than
``MAX_EXTRAPOLATION_S`` before its time (the bound the position's
extrapolation already has), else it waits until the vehicle reports an
attitude at or after its time and is placed with the rotation interpolated
between the two measurements around it (``interpolated_rotation``). A
reading waits at most ``MAX_PROPAGATION_S``: then it is placed as before, the
attitude carried with the body rates (a reading is late, never lost). With
the companion's own observer (an attitude every frame) nothing waits, and on a
link that loses nothing a 50 Hz stream is never 50 ms old.
"""

from __future__ import annotations

import math
from collections import deque

from .perception import HISTORY_S, MAX_EXTRAPOLATION_S, MAX_PROPAGATION_S, Pose, propagated_pose, rotated


def interpolated_rotation(R0: tuple, R1: tuple, s: float) -> tuple:
    """``R0 exp(s log(R0^T R1))``: the rotation a fraction ``s`` of the way from
    ``R0`` to ``R1`` along the shortest arc (row-major 9-tuples)."""
    # D = R0^T R1
    D = [sum(R0[3 * k + i] * R1[3 * k + j] for k in range(3)) for i in range(3) for j in range(3)]
    c = max(-1.0, min(1.0, 0.5 * (D[0] + D[4] + D[8] - 1.0)))
    th = math.acos(c)
    sn = math.sin(th)
    if th < 1e-12 or sn < 1e-9:      # the same rotation, or a half turn (no unique arc): the nearer end
        return tuple(R0) if s < 0.5 else tuple(R1)
    a = s * th / (2 * sn)
    return rotated(tuple(R0), (D[7] - D[5]) * a, (D[2] - D[6]) * a, (D[3] - D[1]) * a)


class AttitudeWait:
    """The vehicle's attitude measurements and the readings waiting for one (module doc).

    ``measured`` each new ATTITUDE (vehicle time s, row-major R body FLU -> ENU, body
    rates FLU rad/s); ``live`` tells whether the poses come from them (False: the
    companion's observer). ``stale(t)`` says whether a reading of vehicle time ``t``
    must wait; ``hold`` keeps it; ``ready`` hands back those that can be placed now,
    each with its pose; ``pose_at`` is the pose of a reading that need not wait.

    The attitude of a reading comes from the measurements, not from the frames'
    poses: a frame's pose carries the attitude known at that frame, which may be
    older than one that came since.
    """

    def __init__(self) -> None:
        self._meas: deque = deque()          # (t_s, R 9-tuple), oldest first
        self._waiting: deque = deque()       # (arrival t_s, reading)
        self.live = False
        self.n_waited = 0

    def measured(self, t_s: float, R: tuple, w=(0.0, 0.0, 0.0)) -> None:
        q = self._meas
        if q and t_s <= q[-1][0]:
            return
        q.append((float(t_s), tuple(R), tuple(w)))
        while q[0][0] < t_s - HISTORY_S:
            q.popleft()

    def stale(self, t_s: float) -> bool:
        """A reading of vehicle time ``t_s`` would be placed with an attitude carried
        more than ``MAX_EXTRAPOLATION_S`` past the last measurement."""
        return self.live and bool(self._meas) and t_s - self._meas[-1][0] > MAX_EXTRAPOLATION_S + 1e-9

    def hold(self, arrival_s: float, reading) -> None:
        self._waiting.append((float(arrival_s), reading))
        self.n_waited += 1

    def __len__(self) -> int:
        return len(self._waiting)

    def _rotation_at(self, t_s: float):
        """The measured attitude interpolated at ``t_s``; None when no measurement
        follows it."""
        q = self._meas
        if not q or q[-1][0] < t_s:
            return None
        i = len(q) - 1
        while i > 0 and q[i - 1][0] >= t_s:
            i -= 1
        t1, R1 = q[i][0], q[i][1]
        if i == 0 or t1 == t_s:
            return R1
        t0, R0 = q[i - 1][0], q[i - 1][1]
        return interpolated_rotation(R0, R1, (t_s - t0) / (t1 - t0))

    def pose_at(self, t_s: float, pose):
        """``pose`` (the frames' pose at ``t_s``, a ``Pose`` or None) with the attitude
        of the measurements: interpolated between the two around ``t_s``, or the last
        carried with its body rates (at most ``MAX_EXTRAPOLATION_S``: else the reading
        is ``stale``). Unchanged when no measurement is live or ``t_s`` is older than
        the measurements kept."""
        q = self._meas
        if pose is None or not self.live or not q or t_s < q[0][0]:
            return pose
        R = self._rotation_at(t_s)
        if R is None:
            t_l, R_l, w_l = q[-1]
            R = propagated_pose(0.0, pose.p, (0.0, 0.0, 0.0), t_s - t_l, R_l, w_l)[1]
        return Pose(pose.t_s, pose.p, R)

    def ready(self, now_s: float, poses) -> list:
        """[(arrival s, reading, Pose or None)] of the waiting readings that can be
        placed at ``now_s``: an attitude measured at or after the reading's time has
        come (position from ``poses``, a ``PoseHistory``), or it has waited
        ``MAX_PROPAGATION_S`` (the pose ``poses`` gives, as without waiting)."""
        out = []
        keep: deque = deque()
        for arrival, reading in self._waiting:
            tb = reading.time_boot_ms * 1e-3
            R = self._rotation_at(tb)
            if R is not None:
                pose = poses.at(tb)
                out.append((arrival, reading, None if pose is None else Pose(pose.t_s, pose.p, R)))
            elif now_s - arrival >= MAX_PROPAGATION_S or not math.isfinite(tb):
                out.append((arrival, reading, poses.at(tb) or poses.at(now_s)))
            else:
                keep.append((arrival, reading))
        self._waiting = keep
        return out
