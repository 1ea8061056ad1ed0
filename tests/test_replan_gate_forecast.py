"""The gate flies what the avoiding modes commit (``companion.safety.gate_forecast``,
``Replanner._shape``; docs/replan.md "The stopping point").

Scene tests/test_safety_guard.py's (flat ground, one row at x in [5.0, 5.2], y in [0, 5]),
with a thin post: a vertical cylinder of radius 0.05 m at (2.0, 8.0), 3 m tall. R = 0.4 m,
clearance 0.5 m, so the vehicle's centre keeps 0.9 m from the post's surface; braking at
1 m/s^2 after the guard's default delay of 0.5 s.

The premise, worked by hand: a reference flown straight along +y at 0.9 m/s, 1.0 m from the
post's surface (x = 3.05), never comes within 1.0 m of it, so its brake (straight on along
the line) keeps clear. The stopping law does not pass it: at 1.0 m before the post (along y)
the centre is sqrt(1 + 1.05^2) = 1.45 m from the axis, d = 1.40 m, room 0.50 m,
v_max = sqrt(2 * 0.50 + 0.25) - 0.5 = 0.618 m/s, while the approach is
0.9 * 1.0 / 1.45 = 0.621 m/s; at 0.7 m before, d = 1.212 m, v_max = 0.435 m/s against
0.499 m/s, 0.064 m/s over the law (more than its 0.05 m/s tolerance). A reference that
neither passes nor brakes for longer than GRACE_S is refused.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.safety import gate_forecast
from companion.safety import Guard, GuardConfig
from companion.safety.gate import GuardGate
from companion.safety.guard import DELAY_S, GRACE_S, grace_accepts
from companion.safety.stopping import stopping_speed_m_s
from companion.trajectory.reference import RefSample
from test_replan_stopping import _shaping
from test_safety_guard import _scene

R, C = 0.4, 0.5
REQ = R + C
POST = (2.0, 8.0)
POST_R, POST_TOP = 0.05, 3.0
DT = 0.004
SPEED = 0.9
X_PASS = POST[0] + POST_R + 1.0          # 1.0 m from the post's surface
Z = (0.0, 0.0, 0.0)


def _post(points):
    p = np.asarray(points, float).reshape(-1, 3)
    radial = np.maximum(np.hypot(p[:, 0] - POST[0], p[:, 1] - POST[1]) - POST_R, 0.0)
    above = np.maximum(p[:, 2] - POST_TOP, 0.0)
    return np.hypot(radial, above)


def _guard() -> Guard:
    cfg = GuardConfig(airframe_radius_m=R, terrain_clearance_m=C, row_clearance_m=C, obstacle_clearance_m=C,
                      accel_m_s2=1.0, delay_s=DELAY_S)
    return Guard(cfg, _scene(), _post)


def _ref(st) -> RefSample:
    return RefSample(tuple(st.p), tuple(st.v), tuple(st.a), tuple(st.jerk), tuple(st.snap), (0.0, 1.0, 0.0))


def test_grace_rule_hand_cases():
    # a pass ends the run; a failure starts one, or goes on with it
    assert grace_accepts(True, False, 5.0, 4.0) == (True, None)
    assert grace_accepts(False, False, 5.0, None) == (True, 5.0)
    assert grace_accepts(False, False, 5.0 + GRACE_S, 5.0) == (True, 5.0)
    assert grace_accepts(False, False, 5.0 + GRACE_S + 0.01, 5.0) == (False, 5.0)
    assert grace_accepts(False, True, 9.0, 5.0) == (True, 5.0)      # braking: flown however long


def test_the_array_flags_are_check_samples_verdicts():
    g = _guard()
    rng = np.random.default_rng(11)
    p = np.column_stack([rng.uniform(0.0, 4.5, 500), rng.uniform(5.5, 10.5, 500), rng.uniform(0.3, 3.5, 500)])
    v = rng.uniform(-1.5, 1.5, (500, 3))
    a = rng.uniform(-1.0, 1.0, (500, 3))
    ok, braking, surface = g.sample_flags(p, v, a)
    assert (~ok).sum() > 50 and braking[~ok].any() and not braking[~ok].all()
    for k in range(len(p)):
        one = g.check_sample(p[k], v[k], True, a[k])
        assert (one.ok, one.braking, one.surface) == (bool(ok[k]), bool(braking[k]), surface[k])


def test_the_premise_a_straight_pass_keeps_clear_yet_breaks_the_law():
    g = _guard()
    ys = np.arange(5.0, 11.0, 0.01)
    p = np.column_stack([np.full_like(ys, X_PASS), ys, np.full_like(ys, 1.5)])
    assert _post(p).min() == pytest.approx(1.0, abs=1e-9)
    assert g.check_path(p, 0.05).ok                         # the margin rule passes it
    # the hand-worked point 0.7 m before the post breaks the law by more than its tolerance
    d = math.hypot(0.7, X_PASS - POST[0]) - POST_R
    approach = SPEED * 0.7 / (d + POST_R)
    assert approach - stopping_speed_m_s(d - REQ, 1.0, DELAY_S) > 0.05
    # flown at 0.9 m/s, one sample a frame: refused
    gate = GuardGate(g, 2.0)
    refused = [gate.dispose(DT * k, RefSample((X_PASS, 5.0 + SPEED * DT * k, 1.5), (0.0, SPEED, 0.0), Z, Z, Z,
                                              (0.0, 1.0, 0.0)))[1] for k in range(int(5.0 / DT))]
    assert any(v is not None for v in refused) and gate.refusals[0]["rule"] == "speed"


def _pass_the_post(seconds=9.0):
    """A mode asking for 0.9 m/s along +y past the post, the reference from (X_PASS, 5.0)
    at that speed; every committed state offered to a gate. (gate, positions)."""
    g = _guard()
    rp = _shaping(g)
    rp.shaper.reset((X_PASS, 5.0, 1.5), (0.0, SPEED, 0.0), Z, Z)
    gate = GuardGate(g, 2.0)
    out = []
    for k in range(int(seconds / DT)):
        rp._t_s = DT * (k + 1)
        st = rp._shape(DT, (0.0, SPEED, 0.0))
        gate.dispose(rp._t_s, _ref(st))
        out.append(st.p)
        if gate.engaged:
            break
    return gate, np.array(out)


def test_the_gate_flies_every_state_the_shaper_commits_past_the_post():
    gate, p = _pass_the_post()
    assert gate.n_refusals == 0 and not gate.engaged
    assert _post(p).min() >= REQ                             # never inside the clearance
    assert p[-1, 1] > POST[1] + 2.0                          # and it went on past the post


def test_without_the_forecast_the_gate_refuses_the_pass(monkeypatch):
    # the mutation: the brake judged by the margin rule alone (the code before the forecast)
    monkeypatch.setattr(gate_forecast, "brake_verdict", lambda *a, **k: None)
    gate, _ = _pass_the_post()
    assert gate.n_refusals >= 1 and gate.refusals[0]["rule"] == "speed"
