"""The core both sides share (issue 17, deliverable 4).

``companion`` and ``sitl`` import it; it imports neither, and it is the only
part of the project ``sitl`` imports (tests/test_imports.py checks both, and
that no package-level import cycle exists). It holds:

- the MAVLink wire: ``codec`` (framing, CRC, fast pack/unpack, every message
  both ends encode or decode, the mission-item codec), ``link`` (datagram
  pipes, sockets, signing, the command/setpoint rules);
- the MAVLink services (``services``): the command, parameter, mission and
  telemetry-interval protocols as pure state machines, each with its
  vehicle (server) and companion (client) side;
- the autopilot personalities (``autopilot``: PX4, ArduCopter);
- the model of the vehicle and its world: ``vehicle``, ``energy``,
  ``geometry``, ``movers``, ``maps``, ``so3`` (the SO(3) helpers), ``frames``
  and ``geodesy`` (the one frame boundary);
- the mission file: ``mission`` (schema, incl. ``sim``, the controller's and
  the trajectory's sections, and the loader), with the bounded input layer
  (``inputs``, ``config``, ``errors``);
- ``logs`` (Python logging set-up of both command lines).
"""
