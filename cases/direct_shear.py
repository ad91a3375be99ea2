"""Direct shear test of a joint: peak and residual shear strength at several normal stresses, fitted c and phi.

A thin wrapper: the case lives in the package, :mod:`fdem.cases.direct_shear`, so that an installed
``fdem`` runs it too (``fdem run direct-shear --help`` lists the options).

    python cases/direct_shear.py --out runs/direct_shear
"""
from fdem.cases.direct_shear import *  # noqa: F401,F403  (constants and functions, for scripts that import this file)
from fdem.cases.direct_shear import main

if __name__ == "__main__":
    main()
