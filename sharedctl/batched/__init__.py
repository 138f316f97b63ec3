"""Many robots stepped together: the closed loop (plant, machine law, sharing) vectorised over a batch.

`simulate_batch(BatchProblem, duration, dt)` runs simulator.simulate's algorithm for N robots at
once and returns per-robot summaries (the fields of metrics.summarize) and, on request, traces.
"""
from .operators import OperatorBatch, operators_from_models
from .problem import BatchProblem
from .results import BatchResult
from .simulate import simulate_batch

__all__ = ["BatchProblem", "BatchResult", "OperatorBatch", "operators_from_models", "simulate_batch"]
