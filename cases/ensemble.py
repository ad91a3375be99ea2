"""A stochastic ensemble of the planar-failure slope on Dask.

A thin wrapper: the case lives in the package, :mod:`fdem.cases.ensemble`, so that an installed
``fdem`` runs it too (``fdem run ensemble --help`` lists the options).

    python cases/ensemble.py --help
"""
from fdem.cases.ensemble import *  # noqa: F401,F403  (constants and functions, for scripts that import this file)
from fdem.cases.ensemble import main

if __name__ == "__main__":
    main()
