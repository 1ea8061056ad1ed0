"""MAVLink link of the companion: codec (the only NED/FRD module), connection,
.tlog recorder/reader and the mission upload protocol."""

from .connection import Connection, check_connection_string
from .mission_upload import MissionRejected, upload_mission
from .tlog import TlogRecord, TlogWriter, read_tlog

__all__ = ["Connection", "check_connection_string", "MissionRejected", "upload_mission",
           "TlogRecord", "TlogWriter", "read_tlog"]
