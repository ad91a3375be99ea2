"""``python -m fdem``: the ``fdem`` command (:mod:`fdem.cli`), for environments without the script on PATH."""
import sys

from fdem.cli import main

__all__: list[str] = []

sys.exit(main())
