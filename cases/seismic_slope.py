"""Seismic slope: the demo's jointed slope shaken through its base; critical amplitude against rigid blocks.

A thin wrapper: the case lives in the package, :mod:`fdem.cases.seismic_slope`, so that an installed
``fdem`` runs it too (``fdem run seismic-slope --help`` lists the options).

    python cases/seismic_slope.py --out runs/seismic_slope
"""
from fdem.cases.seismic_slope import *  # noqa: F401,F403  (constants and functions, for scripts that import this file)
from fdem.cases.seismic_slope import main

if __name__ == "__main__":
    main()
