"""The alternatives the shared law is compared with, on the same sampled loop and operator link.

`human` (operator alone), `shared` (the paper's law) and `shared-nobackup` (the same without the
backup-safe sets): strategy.py; `mux` (twist_mux-style priority/timeout arbitration with a hold at
the border): mux.py; `cbf` (relative-degree-2 CBF QP safety filter): cbf.py. The loop: comparison.py;
the operator's link (rate, delay, loss, staleness): operator_link.py; the metrics:
comparison_metrics.py. `sharedctl compare` runs them.
"""
from .comparison import STRATEGIES, ComparisonTrace, build_strategy, run
from .operator_link import IDEAL, IMPAIRED, LinkConditions, OperatorLink
from .strategy import Command, Strategy

__all__ = ["STRATEGIES", "ComparisonTrace", "build_strategy", "run", "IDEAL", "IMPAIRED", "LinkConditions",
           "OperatorLink", "Command", "Strategy"]
