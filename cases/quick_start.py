"""Quick start: a small jointed slope that stands, fails under strength reduction and runs out.

A thin wrapper: the case lives in the package, :mod:`fdem.cases.quick_start`, so that an installed
``fdem`` runs it too (``fdem run quick-start --help`` lists the options).

    python cases/quick_start.py --out runs/quick_start
"""
from fdem.cases.quick_start import *  # noqa: F401,F403  (constants and functions, for scripts that import this file)
from fdem.cases.quick_start import main

if __name__ == "__main__":
    main()
