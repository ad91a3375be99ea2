"""The four jointed slopes of cases.md A (seed 002).

A thin wrapper: the case lives in the package, :mod:`fdem.cases.four_slopes`, so that an installed
``fdem`` runs it too (``fdem run four-slopes --help`` lists the options).

    python cases/four_slopes.py --out runs/four_slopes
"""
from fdem.cases.four_slopes import *  # noqa: F401,F403  (constants and functions, for scripts that import this file)
from fdem.cases.four_slopes import main

if __name__ == "__main__":
    main()
