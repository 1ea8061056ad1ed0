"""Bundled MAVLink SITL: quadrotor plant, sensors, world, flight-stack shell.

``python -m sitl MISSION.yaml`` (or the ``sitl`` command) runs it; from
Python, ``SitlThread`` / ``SitlProcess`` start it for tests and the demo.
"""

from .api import SitlInProcess, SitlProcess, SitlThread, free_udp_port, peer_url

__all__ = ["SitlInProcess", "SitlProcess", "SitlThread", "free_udp_port", "peer_url"]
