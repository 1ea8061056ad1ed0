"""The SITL vehicle's MAVLink identity: system 1, component 1 (the autopilot)."""

SYSTEM_ID = 1
COMPONENT_ID = 1
