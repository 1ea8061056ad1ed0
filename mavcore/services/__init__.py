"""The MAVLink services, one pure state machine per protocol (issue 17, deliverable 5).

Each module holds both sides of its protocol: the server side the vehicle
(``sitl.server``) answers with, the client side the companion
(``companion.flight.core``) drives. None does I/O: inputs are decoded
messages and the caller's clock (seconds passed in), outputs are messages
to send and events (docs/mavlink.md "Services").

- ``command``: COMMAND_LONG / COMMAND_INT and COMMAND_ACK;
- ``params``: PARAM_REQUEST_LIST / _READ, PARAM_SET, PARAM_VALUE;
- ``mission``: MISSION_COUNT / REQUEST_INT / ITEM_INT / ACK / CLEAR_ALL /
  SET_CURRENT for the mission, fence and rally lists;
- ``telemetry``: the stream schedule SET_MESSAGE_INTERVAL sets.
"""
