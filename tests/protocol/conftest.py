"""Make the shared hypothesis strategies (protocol_strategies.py) importable.

Tests run with ``--import-mode=importlib``, so sibling modules are not on
``sys.path`` by themselves.
"""
import sys
from pathlib import Path

_HERE = str(Path(__file__).resolve().parent)
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)
