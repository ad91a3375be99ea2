"""The planar slope failure of verification.md against Hoek and Bray.

A thin wrapper: the case lives in the package, :mod:`fdem.cases.planar_failure`, so that an installed
``fdem`` runs it too (``fdem run planar-failure --help`` lists the options).

    python cases/planar_failure.py --help
"""
from fdem.cases.planar_failure import *  # noqa: F401,F403  (constants and functions, for scripts that import this file)
from fdem.cases.planar_failure import main

if __name__ == "__main__":
    main()
