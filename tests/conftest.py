"""Shared test set-up: the tests are grouped by kind.

- ``tests/unit/``: one law, kernel or data structure against a closed form or brute force.
- ``tests/verification/``: a whole scene against an analytical problem (docs/verification.md).
- ``tests/cases/``: smoke runs of the case scripts, the command line, pictures, reports, ensembles.

The folders have no ``__init__.py``: pytest's default ("prepend") import mode puts each test's own
folder on ``sys.path``, so a helper next to its tests imports by name (``contact_oracle``,
``test_cohesive``); every test file's basename is unique across the folders. This file puts
``tests/`` itself on ``sys.path`` so that the plain functions below import as
``from conftest import ...`` (worker processes of the parallel tests inherit the path), and
``cases/`` so that the case scripts import by name (``import planar_failure``).

What is here: the scenes that several test files built each for itself, moved here unchanged.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
"""The repository root (``cases/``, ``meshes/``, ``fdem/``)."""
CASES = ROOT / "cases"

for _path in (str(CASES), str(TESTS)):
    if _path not in sys.path:
        sys.path.insert(0, _path)

PLANAR_SIZE = 1.6
"""Mesh size [m] of the coarse planar-failure slope that the stage and report tests run."""


def load_case(stem: str, module_name: str | None = None, register: bool = False):
    """Import the case script ``cases/<stem>.py`` as a fresh module named ``module_name``
    (default ``stem``); ``register`` puts it in ``sys.modules`` before it runs, where a script's
    dataclasses look their module up."""
    spec = importlib.util.spec_from_file_location(module_name or stem, CASES / f"{stem}.py")
    module = importlib.util.module_from_spec(spec)
    if register:
        sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def planar_slope(geometry: str = "no_crack"):
    """The slope geometry of ``cases/planar_failure.py`` (``"no_crack"`` or ``"tension_crack"``)."""
    import planar_failure as pf

    from fdem.cases.planar_failure import planar_slope_geometry

    return planar_slope_geometry(pf.HEIGHT, **pf.GEOMETRIES[geometry])


def planar_slope_scene(geometry: str = "no_crack", size: float = PLANAR_SIZE, **kwargs):
    """The planar-failure slope (a block on a joint that daylights in the face, static geostatic
    start) built by ``cases/planar_failure.py`` at mesh size ``size``; ``kwargs`` go to
    ``planar_failure_simulation`` (``out_dir``, ``pictures``, ...)."""
    import planar_failure as pf

    return pf.planar_failure_simulation(planar_slope(geometry), size, **kwargs)
