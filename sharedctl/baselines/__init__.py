"""Alternatives to the shared controller on the same plant: operator alone, priority mux, CBF safety filter."""
