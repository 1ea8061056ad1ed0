"""The one MAVLink codec of both ends: the only place that speaks NED/FRD,
wire units and MAVLink's [w, x, y, z] quaternions (docs/frames.md).

One concept per module, each name defined once:

- ``wire``: MAVLink 2 framing, the X.25 CRC, the fast packer (vehicle end) and
  the fast datagram splitter/decoder (companion end) of the per-frame
  messages, PX4's ``custom_mode`` word;
- ``actuators``: HIL_ACTUATOR_CONTROLS, encoded by the companion and decoded by
  the vehicle (with the one-datagram fast path);
- ``mission_items``: MISSION_ITEM(_INT) <-> ``MissionItem``, item positions
  <-> world ENU;
- ``vehicle_end``: what the vehicle (the SITL) sends (telemetry) and decodes
  (setpoints, commands);
- ``companion_end``: what the companion decodes (telemetry) and sends
  (setpoints).

This face only re-exports (``from mavcore import codec``; ``codec.X``).
"""

from .actuators import *  # noqa: F401,F403
from .companion_end import *  # noqa: F401,F403
from .mission_items import *  # noqa: F401,F403
from .vehicle_end import *  # noqa: F401,F403
from .wire import *  # noqa: F401,F403
from . import actuators, companion_end, mission_items, vehicle_end, wire

__all__ = sorted(set(actuators.__all__) | set(companion_end.__all__) | set(mission_items.__all__)
                 | set(vehicle_end.__all__) | set(wire.__all__))
