"""``companion demo`` on the SITL's PX4 personality in all three control modes (issue 17:
both personalities fly the demo in every mode; the ArduCopter half is
tests/test_autopilot_e2e.py). A short in-process flight of flat-rectangle, checked on
the recording against PX4's conventions, not the project's constants:

- the vehicle says MAV_AUTOPILOT_PX4 and sends HIGHRES_IMU (not ArduPilot's RAW_IMU);
- the companion enters OFFBOARD with MAV_CMD_DO_SET_MODE(MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
  main mode 6, sub mode 0), and the armed vehicle reports custom_mode 6 << 16
  (px4_custom_mode.h: the main mode in bits 16-23, the sub mode in bits 24-31);
- each mode sends its own control: position setpoints (``vehicle``: SET_POSITION_TARGET_LOCAL_NED,
  MAV_FRAME_LOCAL_NED, so the 1.5 m flight height is z = -1.5 m, down positive), body rates and
  thrust (``rates``: SET_ATTITUDE_TARGET), motor commands (``companion``:
  HIL_ACTUATOR_CONTROLS with finite controls; NaN ones are the lockstep's frame
  acknowledgements) and not the others'.
"""

from __future__ import annotations

import json
import math

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from companion.bundled import missions_dir
from companion.cli import main
from mavcore.mission import load_mission

pytestmark = pytest.mark.slow

PX4_MAIN_MODE_OFFBOARD = 6
OFFBOARD_CUSTOM_MODE = PX4_MAIN_MODE_OFFBOARD << 16


@pytest.mark.parametrize("control", ["vehicle", "companion", "rates"])
def test_demo_flies_the_px4_personality(tmp_path, caplog, control):
    out = tmp_path / control
    rc = main(["demo", "--mission", "flat-rectangle", "--cut", "4", "--transport", "inproc", "--autopilot", "px4",
               "--control", control, "--out", str(out), "--no-plots", "-v"])
    rep = json.loads((out / "report.json").read_text())
    assert rc == 0 and rep["completed"]
    assert ("companion", "vehicle: px4 (from its HEARTBEAT)") in [(r.name, r.getMessage()) for r in caplog.records]
    height = load_mission(missions_dir() / "flat-rectangle" / "mission.yaml").flight.height_agl_m
    log = mavutil.mavlink_connection(str(out / "flight.tlog"))
    imu = {"HIGHRES_IMU": 0, "RAW_IMU": 0}
    armed_modes, set_modes = set(), []
    sent = {"SET_POSITION_TARGET_LOCAL_NED": 0, "SET_ATTITUDE_TARGET": 0, "HIL_ACTUATOR_CONTROLS": 0}
    z_set = []
    while (m := log.recv_match()) is not None:
        t = m.get_type()
        if (m.get_srcSystem(), m.get_srcComponent()) == (1, 1):
            if t in imu:
                imu[t] += 1
            elif t == "HEARTBEAT":
                assert m.autopilot == mavlink.MAV_AUTOPILOT_PX4
                if m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED:
                    armed_modes.add(m.custom_mode)
        elif t == "COMMAND_LONG" and m.command == mavlink.MAV_CMD_DO_SET_MODE:
            set_modes.append((m.param1, m.param2, m.param3))
        elif t == "HIL_ACTUATOR_CONTROLS":
            sent[t] += not math.isnan(m.controls[0])
        elif t in sent:
            sent[t] += 1
            if t == "SET_POSITION_TARGET_LOCAL_NED":
                assert m.coordinate_frame == mavlink.MAV_FRAME_LOCAL_NED
                z_set.append(m.z)
    assert imu["HIGHRES_IMU"] > 0 and imu["RAW_IMU"] == 0
    assert (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PX4_MAIN_MODE_OFFBOARD, 0) in set_modes
    assert OFFBOARD_CUSTOM_MODE in armed_modes
    own = {"vehicle": "SET_POSITION_TARGET_LOCAL_NED", "rates": "SET_ATTITUDE_TARGET",
           "companion": "HIL_ACTUATOR_CONTROLS"}[control]
    assert sent[own] > 0
    others = {"SET_ATTITUDE_TARGET", "HIL_ACTUATOR_CONTROLS"} - {own}
    assert all(sent[k] == 0 for k in others), sent
    if control == "vehicle":
        # up is -z in NED: the flight height (flat terrain at home) is the lowest z asked for
        assert min(z_set) == pytest.approx(-height, abs=0.05) and max(z_set) <= 0.05
