"""The scenes the ``fdem`` command runs: one module per case, each with ``main(argv) -> dict``.

The logic lives here, in the installed package, so ``fdem run NAME`` works after a plain
``pip install .``; the scripts in the repository's ``cases/`` folder are thin wrappers of these
modules (``python cases/four_slopes.py ...`` runs ``fdem.cases.four_slopes.main``). Every case
takes the shared options of :mod:`fdem.cases.common` (``--out``, ``--size``, ``--threads``,
``--max-time``, ``--no-pictures``).
"""
from __future__ import annotations

import importlib

CASES = {
    "quick-start": "fdem.cases.quick_start",
    "four-slopes": "fdem.cases.four_slopes",
    "block-on-incline": "fdem.cases.block_on_incline",
    "brazilian-disc": "fdem.cases.brazilian_disc",
    "muliashi": "fdem.cases.muliashi",
    "planar-failure": "fdem.cases.planar_failure",
    "newmark-block": "fdem.cases.newmark_block",
    "ensemble": "fdem.cases.ensemble",
    "rigid-blocks": "fdem.cases.rigid_blocks",
    "seismic-slope": "fdem.cases.seismic_slope",
    "compression-test": "fdem.cases.compression_test",
    "direct-shear": "fdem.cases.direct_shear",
    "scene": "fdem.cases.scene",
}
"""Case name (as ``fdem run`` takes it) -> module."""


def case_module(name: str):
    """The module of case ``name``; a ``KeyError`` naming the known cases otherwise."""
    key = name.replace("_", "-")
    if key not in CASES:
        raise KeyError(f"unknown case {name!r}; the cases are: {', '.join(CASES)}")
    return importlib.import_module(CASES[key])


def describe(name: str) -> str:
    """First line of the case's docstring."""
    try:
        doc = case_module(name).__doc__ or ""
    except Exception as err:  # a case being written may not import yet: say so, list the others
        return f"(does not import: {type(err).__name__}: {err})"
    return doc.strip().splitlines()[0] if doc.strip() else ""
