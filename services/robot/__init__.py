"""The robot process (see docs/services.md)."""
