"""`python -m sharedctl …`: the `sharedctl` console script's twin (the command line lives in sharedctl.services.cli).

The one module of the control core that imports a service: it is an entry point, run by the interpreter
and imported by nothing (tests/test_layout.py checks both)."""
import sys

from sharedctl.services.cli import main

if __name__ == "__main__":
    sys.exit(main())
