"""sharedctl — adaptive shared control of output-constrained Euler–Lagrange robots.

This package is the pure control core (no sockets, clocks, threads or printing).
The wire protocol lives in ``sharedctl.protocol`` (folder ``protocol/``) and the
processes in ``sharedctl.services`` (folder ``services/``).
"""

__version__ = "0.1.0"
