"""Fault injection: seeded network/CAN impairments, process faults, and the fault campaign."""
