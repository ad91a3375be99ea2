"""The Muliashi slope (cases.md B): gravity increase to failure; see :mod:`fdem.cases.muliashi`.

    python cases/muliashi.py --out runs/muliashi
"""
from fdem.cases.muliashi import main

if __name__ == "__main__":
    main()
