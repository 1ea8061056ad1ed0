"""The companion speaks the vehicle's dialect, detected from its HEARTBEAT: a short
in-process flight of ``companion demo`` on the SITL's ArduCopter personality,
in all three control modes. Checked on the recording: the vehicle said
MAV_AUTOPILOT_ARDUPILOTMEGA and sent RAW_IMU, not HIGHRES_IMU, each frame; the companion set GUIDED with ArduCopter's number
(DO_SET_MODE(1, 4)), armed, and took off with MAV_CMD_NAV_TAKEOFF (param7 in
metres above home); the vehicle was in GUIDED (4) from arming to our landing
command and reached the height asked for before our setpoints took over. With
``--control companion`` and ``--control rates`` (body rates and thrust in GUIDED) the controller took over a vehicle at rest (ArduCopter
says "Takeoff complete" while still climbing at up to 2.7 m/s: taken over then,
the velocity error turned the thrust vector down, a demanded flip) and the
attitude stayed near level."""

from __future__ import annotations

import json

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from companion.cli import main
from companion.flight.core import TAKEOFF_REST_SPEED_M_S
from mavcore.autopilot import ARDUCOPTER

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("control", ["vehicle", "companion", "rates"])
def test_demo_flies_the_ardupilot_personality(tmp_path, caplog, control):
    out = tmp_path / control
    check = ["--check-params"] if control == "vehicle" else []
    rc = main(["demo", "--mission", "flat-rectangle", "--cut", "4", "--transport", "inproc", "--autopilot",
               "ardupilot", "--control", control, "--out", str(out), "--no-plots", "-v"] + check)
    rep = json.loads((out / "report.json").read_text())
    assert rc == 0 and rep["completed"]
    # -v: the detection and the vehicle's own account, through Python logging
    said = [(r.name, r.getMessage()) for r in caplog.records]
    assert ("companion", "vehicle: ardupilot (from its HEARTBEAT)") in said
    assert any(n == "sitl" and m.endswith("Armed in GUIDED") for n, m in said)
    # --check-params: ArduCopter's FS_GCS_ENABLE defaults to 0 (off), docs ask for 1 (RTL) or 5 (land)
    warned = [r.getMessage() for r in caplog.records if r.levelname == "WARNING" and r.name == "companion"]
    assert warned == (["parameter FS_GCS_ENABLE = 0: expected 1 or 5 (GCS failsafe: RTL or land)"] if check else [])
    reads = []
    log = mavutil.mavlink_connection(str(out / "flight.tlog"))
    set_modes, takeoffs, modes_armed, z0, z_done = [], [], set(), None, None
    counts = {"RAW_IMU": 0, "HIGHRES_IMU": 0, "SCALED_IMU2": 0}
    landing = False
    z = None
    v_handover, max_tilt, speed, controlling = None, 0.0, None, False
    n_rates = 0
    while (m := log.recv_match()) is not None:
        t = m.get_type()
        if m.get_srcSystem() == 1 and m.get_srcComponent() == 1:
            if t in counts:
                counts[t] += 1
            if t == "HEARTBEAT":
                assert m.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA and m.type == mavlink.MAV_TYPE_QUADROTOR
                if m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED and not landing:
                    modes_armed.add(m.custom_mode)
            elif t == "LOCAL_POSITION_NED":
                z = -m.z
                z0 = z if z0 is None else z0
                speed = (m.vx ** 2 + m.vy ** 2 + m.vz ** 2) ** 0.5
            elif t == "ATTITUDE" and controlling and not landing:
                max_tilt = max(max_tilt, abs(m.roll), abs(m.pitch))
            elif t == "STATUSTEXT" and m.text.startswith("Takeoff complete"):
                z_done = z
        elif t == "PARAM_REQUEST_READ":
            reads.append(m.param_id)
        elif t == "HIL_ACTUATOR_CONTROLS" and not controlling and m.controls[0] == m.controls[0]:
            controlling, v_handover = True, speed      # our first motor commands: the hand-over
        elif t == "SET_ATTITUDE_TARGET":
            n_rates += 1
            if not controlling:
                controlling, v_handover = True, speed  # our first body rates: the hand-over
        elif t == "COMMAND_LONG":
            if m.command == mavlink.MAV_CMD_DO_SET_MODE:
                set_modes.append((m.param1, m.param2, m.param3))
            elif m.command == mavlink.MAV_CMD_NAV_TAKEOFF:
                takeoffs.append(m.param7)
            elif m.command == mavlink.MAV_CMD_NAV_LAND:
                landing = True
    # ArduCopter's message set: RAW_IMU each sensor frame (the clock the companion flew by), no HIGHRES_IMU
    assert counts["HIGHRES_IMU"] == 0 and counts["SCALED_IMU2"] > 0
    assert counts["RAW_IMU"] == pytest.approx(rep["sim_time_s"] * 250, rel=0.02)
    # rates: the hover thrust under ArduCopter's name (MOT_THST_HOVER, PX4's MPC_THR_HOVER)
    assert reads == (["SIM_LOCKSTEP"] + (["MOT_THST_HOVER"] if control == "rates" else [])
                     + (["FS_GCS_ENABLE"] if check else []))
    assert set_modes and set(set_modes) == {(1.0, 4.0, 0.0)}
    assert modes_armed == {ARDUCOPTER.custom_mode("GUIDED")}
    assert len(set(takeoffs)) == 1 and takeoffs[0] > 0.5
    # reached within the take-off acceptance (NAV_MC_ALT_RAD, 0.8 m) of home + param7
    assert z_done is not None and abs(z_done - (z0 + takeoffs[0])) <= 0.8
    # --control rates: body rates and thrust (SET_ATTITUDE_TARGET) in GUIDED, ArduCopter's attitude mode
    assert (n_rates > 0) == (control == "rates") and ARDUCOPTER.attitude_mode == "GUIDED"
    if control in ("companion", "rates"):
        # the controller took over a vehicle at rest, and flew it level (the flip was > 1.6 rad)
        assert v_handover is not None and v_handover <= TAKEOFF_REST_SPEED_M_S
        assert max_tilt < 0.3
