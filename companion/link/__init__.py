"""MAVLink link of the companion: connection and .tlog recorder/reader (the
protocols it speaks are ``mavcore.services``)."""

from .connection import Connection, check_connection_string
from .tlog import TlogRecord, TlogWriter, read_tlog

__all__ = ["Connection", "check_connection_string", "TlogRecord", "TlogWriter", "read_tlog"]
