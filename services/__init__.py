"""Processes and command-line shells of sharedctl: I/O, timing, configuration."""
