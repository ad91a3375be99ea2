"""Compression test: the uniaxial (or biaxial) strength and Young's modulus of an intact rock specimen.

A thin wrapper: the case lives in the package, :mod:`fdem.cases.compression_test`, so that an installed
``fdem`` runs it too (``fdem run compression-test --help`` lists the options).

    python cases/compression_test.py --out runs/compression_test
"""
from fdem.cases.compression_test import *  # noqa: F401,F403  (constants and functions, for scripts that import this file)
from fdem.cases.compression_test import main

if __name__ == "__main__":
    main()
