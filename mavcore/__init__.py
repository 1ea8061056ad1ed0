"""The MAVLink core both sides share (issue 17, deliverable 4).

``companion`` and ``sitl`` import it; it imports neither. It starts with the
autopilot personalities (``mavcore.autopilot``): what differs between PX4
and ArduCopter on the wire.
"""
