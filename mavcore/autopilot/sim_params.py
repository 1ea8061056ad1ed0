"""The simulator's own parameters (SIM_*), the same under every personality:
noise and lockstep, applied by ``sitl.server``."""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

from .base import ParamSpec

R, I = mavlink.MAV_PARAM_TYPE_REAL32, mavlink.MAV_PARAM_TYPE_INT32

SIM_PARAM_SPECS: tuple[ParamSpec, ...] = (
    ParamSpec("SIM_LOCKSTEP", I, 0, 0, 1,
              "1: lockstep with the actuator peer (the --lockstep option; read-only): the vehicle waits for "
              "every answer, so link delay costs wall time, not control"),
    ParamSpec("SIM_LS_TMO", R, 2.0, 0.05, 60.0, "lockstep: wall-clock wait for the answer (s)"),
    ParamSpec("SIM_LS_SPIN", R, 300.0, 0.0, 5000.0,
              "lockstep: busy-poll for the answer this long before sleeping (us; 0 off)"),
    ParamSpec("SIM_VEC_VAR", R, 5.0e-4, 0.0, 1.0, "accel/mag direction noise variance (-)"),
    ParamSpec("SIM_GYRO_VAR", R, 5.0e-4, 0.0, 1.0, "gyro noise variance ((rad/s)^2)"),
    ParamSpec("SIM_POS_STD", R, 0.0, 0.0, 100.0, "horizontal position measurement noise std (m)"),
    ParamSpec("SIM_POSZ_STD", R, 0.0, 0.0, 100.0, "vertical position measurement noise std (m)"),
    ParamSpec("SIM_VEL_STD", R, 0.0, 0.0, 100.0, "velocity measurement noise std (m/s)"),
    ParamSpec("SIM_RNG_STD", R, 0.0, 0.0, 100.0, "rangefinder noise std (m)"),
    ParamSpec("SIM_RNG_HZ", R, 0.0, 0.0, 1000.0,
              "rangefinder sample and DISTANCE_SENSOR rate (Hz; 0: leave each sensor's rate as it is)"),
)

#: Parameters a PARAM_SET cannot change (they describe how the simulator was started).
READ_ONLY_PARAMS = frozenset({"SIM_LOCKSTEP"})
