"""The flight procedure: the flight core, its monitor, its log and its configuration."""
