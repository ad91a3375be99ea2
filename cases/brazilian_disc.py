"""Brazilian disc: the tensile strength from the peak platen load (verification.md).

A thin wrapper: the case lives in the package, :mod:`fdem.cases.brazilian_disc`, so that an installed
``fdem`` runs it too (``fdem run brazilian-disc --help`` lists the options).

    python cases/brazilian_disc.py --out runs/brazilian_disc
"""
from fdem.cases.brazilian_disc import *  # noqa: F401,F403  (constants and functions, for scripts that import this file)
from fdem.cases.brazilian_disc import main

if __name__ == "__main__":
    main()
