"""The controller process (see docs/services.md)."""
