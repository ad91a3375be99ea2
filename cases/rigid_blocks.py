"""Rigid blocks: a slope's static factor of safety and mechanism by second-order cone programming.

A thin wrapper: the case lives in the package, :mod:`fdem.cases.rigid_blocks`, so that an installed
``fdem`` runs it too (``fdem run rigid-blocks --help`` lists the options).

    python cases/rigid_blocks.py --scene all --out runs/rigid_blocks
"""
from fdem.cases.rigid_blocks import *  # noqa: F401,F403  (constants and functions, for scripts that import this file)
from fdem.cases.rigid_blocks import main

if __name__ == "__main__":
    main()
