"""The console process (see docs/services.md)."""
