"""Fault injection: seeded network/CAN impairments and process faults (the campaign that drives them is a
study: services/studies/campaign/)."""
