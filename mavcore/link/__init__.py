"""The link pieces both ends share: datagram pipes and sockets, MAVLink 2
signing and the command/setpoint sanity rules (``command_rules``)."""
