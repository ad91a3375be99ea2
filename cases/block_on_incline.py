"""Block on an inclined plane (verification.md).

A thin wrapper: the case lives in the package, :mod:`fdem.cases.block_on_incline`, so that an installed
``fdem`` runs it too (``fdem run block-on-incline --help`` lists the options).

    python cases/block_on_incline.py --out runs/block_on_incline
"""
from fdem.cases.block_on_incline import *  # noqa: F401,F403  (constants and functions, for scripts that import this file)
from fdem.cases.block_on_incline import main

if __name__ == "__main__":
    main()
