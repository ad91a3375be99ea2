"""The Newmark sliding block under a base acceleration history.

A thin wrapper: the case lives in the package, :mod:`fdem.cases.newmark_block`, so that an installed
``fdem`` runs it too (``fdem run newmark-block --help`` lists the options).

    python cases/newmark_block.py --help
"""
from fdem.cases.newmark_block import *  # noqa: F401,F403  (constants and functions, for scripts that import this file)
from fdem.cases.newmark_block import main

if __name__ == "__main__":
    main()
